/* Renderer framebuffer stage, one launch per depth level: the next wavefront's rays (scatter of
 * the compacted children, render_secondary.cl), race-free accumulation (one work-item per pixel
 * gathers the pixel's rays, which stay sorted by pixel through every compaction) and, after the
 * last level of a chunk, tonemap of the chunk's pixels to RGBA8. */
#include "common.h"
#include "render_surface.h"

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

inline uchar4 tonemap_rgba8(float3 radiance, __constant const RenderParams* prm)
{
    const float3 c = tonemap(radiance * prm->exposure.x, prm->tonemap);
    return (uchar4)(to_u8(srgb_encode(c.x)), to_u8(srgb_encode(c.y)), to_u8(srgb_encode(c.z)),
                    (uchar)255);
}

/* Pixel q0 + k: adds this wavefront's radiance to the framebuffer (depth 0 overwrites: it starts
 * the frame) and, when `finish` is set (the chunk's last level), writes the pixel's RGBA8. */
inline void accumulate_pixel(__constant const RenderParams* prm, __constant const Camera* cam,
                             __global const Ray* rays, uint n, uint depth, uint q,
                             __global const float4* radiance, __global float4* fb, uint finish,
                             __global uchar4* rgba)
{
    uint x, y;
    if (!pixel_of(cam, q, &x, &y)) return;
    float3 sum = (float3)(0.0f);
    for (uint i = lower_bound_pixel(rays, n, q); i < n && rays[i].pixel == q; i++)
        sum += radiance[i].xyz;
    const uint p = y * cam->width + x;
    float4 c;
    if (depth == 0) c = (float4)(sum, 1.0f);
    else c = fb[p] + (float4)(sum, 0.0f);
    fb[p] = c;
    if (finish) rgba[p] = tonemap_rgba8(c.xyz, prm);
}

/* Grid-stride over k: (gp.scatter) ray k's children go into `out`; k < n_q: pixel q0 + k. */
__kernel void render_gather(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                            __constant const Camera* cam, __global const Ray* rays,
                            __global const Hit* hits, __global const uint* counts,
                            const uint depth, __global const uint* child_offsets,
                            __global const uint* block_sums, __global Ray* out,
                            const GatherParams gp, __global const float4* radiance,
                            __global float4* fb, __global uchar4* rgba)
{
    const uint scatter = gp.scatter, q0 = gp.q0, n_q = gp.n_q, finish = gp.finish;
    const uint n = counts[depth];
    const uint end = scatter ? max(n, n_q) : n_q;
    for (uint k = get_global_id(0); k < end; k += get_global_size(0)) {
        if (scatter && k < n)
            scatter_children(RENDER_GEOM_ARGS, prm, rays, hits, k, depth, child_offsets,
                             block_sums, out);
        if (k < n_q)
            accumulate_pixel(prm, cam, rays, n, depth, q0 + k, radiance, fb, finish, rgba);
    }
}
