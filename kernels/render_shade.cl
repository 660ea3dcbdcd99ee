/* Renderer stages: shading of each hit (ambient, sky on a miss, child counts for the compaction,
 * primary AOVs) and direct light through shadow rays (Phong per light when unoccluded). Two
 * kernels: fused into one, the shading state kept live across the shadow traversal cost 15-50%
 * on the H100 (measured 2026-11-23). Both loop with a grid stride (see render_trace.cl); built
 * with TRACE_COOP=1, render_shadow_coop traces each hit's shadow rays with a whole work-group
 * (traverse_coop.h; RenderSettings.coop_from). */
#include "common.h"
#include "render_surface.h"
#include "render_bins.h"
#include "render_shadow.h"

__kernel void render_shade(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                           __constant const Camera* cam, __global const Ray* restrict rays,
                           __global const Hit* restrict hits, __global const uint* counts,
                           const uint depth, __global float4* restrict radiance,
                           __global uint* restrict child_counts, __global Aov* restrict aov,
                           const uint write_aov)
{
    const uint n = counts[depth];
    for (uint i = get_global_id(0); i < n; i += get_global_size(0))
        shade_hit(RENDER_GEOM_ARGS, prm, cam, rays[i], hits[i], i, depth, radiance, child_counts,
                  aov, write_aov);
}

__kernel void render_shadow(SCENE_PARAMS, RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                            __global const Light* restrict lights,
                            __global const Ray* restrict rays, __global const Hit* restrict hits,
                            __global const uint* counts, const uint depth,
                            __global float4* restrict radiance,
                            __global const float4* restrict caustic_map, const CausticParams cprm,
                            LIGHT_BUFFER_PARAMS)
{
    const uint n = counts[depth];
    for (uint i = get_global_id(0); i < n; i += get_global_size(0))
        shadow_ray(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights, rays,
                   hits, i, radiance, caustic_map, &cprm);
}

/* The same, each round's entries taken by the work-items in the order of their cost class
 * (render_bins.h; RenderSettings.cost_bins): the same bytes. */
__kernel __attribute__((reqd_work_group_size(RENDER_BIN_WG, 1, 1))) void render_shadow_binned(
    SCENE_PARAMS, RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
    __global const Light* restrict lights, __global const Ray* restrict rays,
    __global const Hit* restrict hits, __global const uint* counts, const uint depth,
    __global float4* restrict radiance, __global const float4* restrict caustic_map,
    const CausticParams cprm, LIGHT_BUFFER_PARAMS)
{
    __local RenderBins bins;
    const uint n = counts[depth];
    for (uint base = get_group_id(0) * RENDER_BIN_WG; base < n;
         base += get_num_groups(0) * RENDER_BIN_WG) {   /* uniform over the work-group */
        const uint j = base + get_local_id(0);
        const uint cls = j < n ? shadow_cost_class(prm, rays, hits, j, &cprm) : RENDER_BIN_IDLE;
        const uint i = bin_round(&bins, j, cls);
        if (i < n)
            shadow_ray(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights, rays,
                       hits, i, radiance, caustic_map, &cprm);
    }
}

#if TRACE_COOP
__kernel __attribute__((reqd_work_group_size(TRACE_COOP_WIDTH, 1, 1))) void render_shadow_coop(
    SCENE_PARAMS, RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
    __global const Light* restrict lights, __global const Ray* restrict rays,
    __global const Hit* restrict hits, __global const uint* counts, const uint depth,
    __global float4* restrict radiance, __global const float4* restrict caustic_map,
    const CausticParams cprm, LIGHT_BUFFER_PARAMS)
{
    __local TraceCoop coop;
    shadow_rays_coop(SCENE_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights, rays, hits,
                     counts[depth], true, radiance, caustic_map, &cprm, &coop);
}
#endif
