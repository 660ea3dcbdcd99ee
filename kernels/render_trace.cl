/* Renderer stage: closest hit of every ray in the wavefront (primary or secondary), and the
 * same fused with the shading of the hit (render_trace_shade, RenderSettings.fuse_trace_shade:
 * one launch fewer per depth level, the ray and hit stay in registers). */
#include "common.h"
#include "render_surface.h"
#include "traverse.h"

inline Hit trace_ray(SCENE_PARAMS, const Ray* r, uint depth)
{
    Hit h = {INFINITY, 0.0f, 0.0f, -1, -1};
    if (r->wr + r->wg + r->wb > 0.0f)   /* dead padding rays have zero weight */
        h = scene_closest_hit_masked(SCENE_ARGS, (float3)(r->ox, r->oy, r->oz),
                                     (float3)(r->dx, r->dy, r->dz), 0.0f, INFINITY, ~0u,
                                     depth ? TRACE_KIND_SECONDARY : TRACE_KIND_PRIMARY);
    return h;
}

/* Grid-stride loops: launched with any number of work-items, the device-side count decides. */
__kernel void render_trace(SCENE_PARAMS, __global const Ray* restrict rays,
                           __global const uint* restrict counts, const uint depth,
                           __global Hit* restrict hits)
{
    const uint n = counts[depth];
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) {
        const Ray r = rays[i];
        hits[i] = trace_ray(SCENE_ARGS, &r, depth);
    }
}

__kernel void render_trace_shade(SCENE_PARAMS, RENDER_GEOM_PARAMS,
                                 __constant const RenderParams* prm, __constant const Camera* cam,
                                 __global const Ray* restrict rays,
                                 __global const uint* restrict counts, const uint depth,
                                 __global Hit* restrict hits, __global float4* restrict radiance,
                                 __global uint* restrict child_counts, __global Aov* restrict aov,
                                 const uint write_aov)
{
    const uint n = counts[depth];
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) {
        const Ray r = rays[i];
        const Hit h = trace_ray(SCENE_ARGS, &r, depth);
        hits[i] = h;
        shade_hit(RENDER_GEOM_ARGS, prm, cam, r, h, i, depth, radiance, child_counts, aov,
                  write_aov);
    }
}
