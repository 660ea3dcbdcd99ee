/* Renderer stage: closest hit of every ray in the wavefront (primary or secondary), and the
 * same fused with the shading of the hit (render_trace_shade, RenderSettings.fuse_trace_shade:
 * one launch fewer per depth level, the ray and hit stay in registers). Built with
 * TRACE_COOP=1, also the *_coop kernels: one ray per work-group of TRACE_COOP_WIDTH traversed
 * together (traverse_coop.h), for the latency-bound tail levels (RenderSettings.coop_from). */
#include "common.h"
#include "render_surface.h"
#include "render_trace.h"

/* Grid-stride loops: launched with any number of work-items, the device-side count decides. */
__kernel void render_trace(SCENE_PARAMS, __global const Ray* restrict rays,
                           __global const uint* restrict counts, const uint depth,
                           __global Hit* restrict hits)
{
    const uint n = counts[depth];
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) {
        const Ray r = rays[i];
        hits[i] = trace_ray(TRACE_SERIAL_ARGS, &r, depth);
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
        const Hit h = trace_ray(TRACE_SERIAL_ARGS, &r, depth);
        hits[i] = h;
        shade_hit(RENDER_GEOM_ARGS, prm, cam, r, h, i, depth, radiance, child_counts, aov,
                  write_aov);
    }
}

#if TRACE_COOP
/* A work-group per ray while the level has few, else a work-item per ray (render_trace.h
 * trace_rays_coop, trace_shade_rays_coop). */
__kernel __attribute__((reqd_work_group_size(TRACE_COOP_WIDTH, 1, 1))) void render_trace_coop(
    SCENE_PARAMS, __global const Ray* restrict rays, __global const uint* restrict counts,
    const uint depth, __global Hit* restrict hits)
{
    __local TraceCoop coop;
    trace_rays_coop(SCENE_ARGS, rays, counts[depth], depth, hits, &coop);
}

__kernel __attribute__((reqd_work_group_size(TRACE_COOP_WIDTH, 1, 1))) void
render_trace_shade_coop(SCENE_PARAMS, RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                        __constant const Camera* cam, __global const Ray* restrict rays,
                        __global const uint* restrict counts, const uint depth,
                        __global Hit* restrict hits, __global float4* restrict radiance,
                        __global uint* restrict child_counts, __global Aov* restrict aov,
                        const uint write_aov)
{
    __local TraceCoop coop;
    trace_shade_rays_coop(SCENE_ARGS, RENDER_GEOM_ARGS, prm, cam, rays, counts[depth], depth,
                          hits, radiance, child_counts, aov, write_aov, &coop);
}
#endif
