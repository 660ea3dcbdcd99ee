/* Renderer framebuffer stage, one or two launches per depth level: the next wavefront's rays
 * (scatter of the compacted children, render_secondary.cl) and race-free accumulation (the first
 * ray of each pixel's run sums the run: rays stay sorted by pixel through every compaction);
 * after the last level of a chunk, a second launch tonemaps the chunk's pixels to RGBA8. */
#include "common.h"
#include "render_surface.h"
#include "render_shadow_list.h"

inline uchar4 tonemap_rgba8(float3 radiance, __constant const RenderParams* prm)
{
    const float3 c = tonemap(radiance * prm->exposure.x, prm->tonemap);
    return (uchar4)(to_u8(srgb_encode(c.x)), to_u8(srgb_encode(c.y)), to_u8(srgb_encode(c.z)),
                    (uchar)255);
}

/* Ray k starts its pixel's run (rays stay sorted by pixel): adds the run's radiance, summed in
 * ray order, to the framebuffer (depth 0 overwrites: it starts the frame, and every pixel of a
 * chunk has depth-0 rays). One work-item per run: race-free, O(rays) per level. */
inline void accumulate_run(__constant const Camera* cam, __global const Ray* rays, uint n,
                           uint depth, uint k, __global const float4* radiance,
                           __global float4* fb)
{
    const uint q = rays[k].pixel;
    if (k > 0 && rays[k - 1].pixel == q) return;
    uint x, y;
    if (!pixel_of(cam, q, &x, &y)) return;
    float3 sum = (float3)(0.0f);
    for (uint i = k; i < n && rays[i].pixel == q; i++) sum += radiance[i].xyz;
    const uint p = y * cam->width + x;
    fb[p] = depth == 0 ? (float4)(sum, 1.0f) : fb[p] + (float4)(sum, 0.0f);
}

/* Grid-stride over k. gp.finish: pixel q0 + k (k < n_q) is tonemapped to RGBA8 (after the
 * chunk's last level was accumulated), GATHER_FINISH_SHADOW_LIST: with the shadow list's light
 * of the pixel added to the framebuffer first (render_shadow_list.h). Otherwise ray k (k < n): its children go into `out`
 * (gp.scatter) and, if it starts its pixel's run, the run is accumulated (gp.accumulate). The
 * scatter reads no radiance: with RenderSettings.overlap_levels it runs before the level's shadow
 * rays (render_shadow_trace.cl), the accumulation after them. */
__kernel void render_gather(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                            __constant const Camera* cam, __global const Ray* rays,
                            __global const Hit* hits, __global const uint* counts,
                            const uint depth, __global const uint* child_offsets,
                            __global const uint* block_sums, __global Ray* out,
                            const GatherParams gp, __global const float4* radiance,
                            __global float4* fb, __global uchar4* rgba,
                            __global const ulong* restrict shadow_light)
{
    const uint n = counts[depth];
    if (gp.finish) {
        for (uint k = get_global_id(0); k < gp.n_q; k += get_global_size(0)) {
            uint x, y;
            const uint q = gp.q0 + k;
            const bool listed = gp.finish == GATHER_FINISH_SHADOW_LIST;
            const float3 light = listed ? shadow_light_of(shadow_light, q) : (float3)(0.0f);
            if (!pixel_of(cam, q, &x, &y)) continue;
            const uint p = y * cam->width + x;
            float4 c = fb[p];
            if (listed) {
                c.xyz += light;
                fb[p] = c;
            }
            rgba[p] = tonemap_rgba8(c.xyz, prm);
        }
        return;
    }
    for (uint k = get_global_id(0); k < n; k += get_global_size(0)) {
        if (gp.scatter)
            scatter_children(RENDER_GEOM_ARGS, prm, rays, hits, k, depth, child_offsets,
                             block_sums, out);
        if (gp.accumulate) accumulate_run(cam, rays, n, depth, k, radiance, fb);
    }
}
