/* Renderer framebuffer stages: race-free accumulation (one work-item per pixel gathers the
 * pixel's rays, which stay sorted by pixel through every compaction) and tonemap to RGBA8. */
#include "common.h"
#include "render_optics.h"

/* Index of the first ray with pixel >= q among rays[0..n). */
inline uint lower_bound_pixel(__global const Ray* rays, uint n, uint q)
{
    uint lo = 0, hi = n;
    while (lo < hi) {
        const uint mid = (lo + hi) >> 1;
        if (rays[mid].pixel < q) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* Adds this wavefront's radiance to the framebuffer (depth 0 overwrites: it starts the frame). */
__kernel void render_accumulate(__constant const Camera* cam, const uint q0, const uint n_q,
                                __global const Ray* rays, __global const float4* radiance,
                                __global const uint* counts, const uint depth,
                                __global float4* fb)
{
    const uint k = get_global_id(0);
    if (k >= n_q) return;
    const uint q = q0 + k;
    uint x, y;
    if (!pixel_of(cam, q, &x, &y)) return;
    const uint n = counts[depth];
    float3 sum = (float3)(0.0f);
    for (uint i = lower_bound_pixel(rays, n, q); i < n && rays[i].pixel == q; i++)
        sum += radiance[i].xyz;
    const uint p = y * cam->width + x;
    if (depth == 0) fb[p] = (float4)(sum, 1.0f);
    else fb[p] += (float4)(sum, 0.0f);
}

__kernel void render_tonemap(__global const float4* fb, const uint n_pixels,
                             __constant const RenderParams* prm, __global uchar4* rgba)
{
    const uint p = get_global_id(0);
    if (p >= n_pixels) return;
    const float3 c = tonemap(fb[p].xyz * prm->exposure.x, prm->tonemap);
    rgba[p] = (uchar4)(to_u8(srgb_encode(c.x)), to_u8(srgb_encode(c.y)), to_u8(srgb_encode(c.z)),
                       (uchar)255);
}
