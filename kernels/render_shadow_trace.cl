/* Renderer stage: the shadow rays of depth level depth - 1 and the closest hits of level depth in
 * one launch (RenderSettings.overlap_levels). The two are independent once the children of
 * level depth - 1 are scattered, and NVIDIA's OpenCL runs no two kernels of one in-order queue at
 * once: in one launch, the tail levels' few shadow rays no longer cost a traversal chain of
 * latency of their own. Work-item j of a grid-stride loop over counts[depth - 1] +
 * counts[depth] does shadow ray j of level depth - 1 (j < counts[depth - 1]), else traces ray
 * j - counts[depth - 1] of level depth: the same per-ray bodies as render_shadow
 * (render_shadow.h) and render_trace / render_trace_shade (render_trace.h, shade_hit), so the
 * image is the same byte for byte. The levels' hits (and, shaded here, their radiance) live in
 * buffers of their own parity.
 * Built with TRACE_COOP=1, the *_coop kernels trace level depth's rays one per work-group
 * (traverse_coop.h; RenderSettings.coop_from), and level depth - 1's shadow rays too when
 * coop_shadow, else one per work-item first (level coop_from - 1 is not a tail level). */
#include "common.h"
#include "render_bins.h"
#include "render_shadow.h"
#include "render_surface.h"
#include "render_trace.h"

__kernel void render_shadow_trace(SCENE_PARAMS, RENDER_GEOM_PARAMS,
                                  __constant const RenderParams* prm,
                                  __global const Light* restrict lights,
                                  __global const uint* restrict counts, const uint depth,
                                  __global const Ray* restrict shadow_rays,
                                  __global const Hit* restrict shadow_hits,
                                  __global float4* restrict shadow_radiance,
                                  __global const float4* restrict caustic_map,
                                  const CausticParams cprm, LIGHT_BUFFER_PARAMS,
                                  __global const Ray* restrict rays,
                                  __global Hit* restrict hits)
{
    const uint n_shadow = counts[depth - 1u], n = n_shadow + counts[depth];
    for (uint j = get_global_id(0); j < n; j += get_global_size(0)) {
        if (j < n_shadow) {
            shadow_ray(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights,
                       shadow_rays, shadow_hits, j, shadow_radiance, caustic_map, &cprm);
        } else {
            const uint i = j - n_shadow;
            const Ray r = rays[i];
            hits[i] = trace_ray(TRACE_SERIAL_ARGS, &r, depth);
        }
    }
}

/* The same with level depth's hits shaded at once (RenderSettings.fuse_trace_shade). */
__kernel void render_shadow_trace_shade(SCENE_PARAMS, RENDER_GEOM_PARAMS,
                                        __constant const RenderParams* prm,
                                        __global const Light* restrict lights,
                                        __global const uint* restrict counts, const uint depth,
                                        __global const Ray* restrict shadow_rays,
                                        __global const Hit* restrict shadow_hits,
                                        __global float4* restrict shadow_radiance,
                                        __global const float4* restrict caustic_map,
                                        const CausticParams cprm, LIGHT_BUFFER_PARAMS,
                                        __constant const Camera* cam,
                                        __global const Ray* restrict rays,
                                        __global Hit* restrict hits,
                                        __global float4* restrict radiance,
                                        __global uint* restrict child_counts,
                                        __global Aov* restrict aov, const uint write_aov)
{
    const uint n_shadow = counts[depth - 1u], n = n_shadow + counts[depth];
    for (uint j = get_global_id(0); j < n; j += get_global_size(0)) {
        if (j < n_shadow) {
            shadow_ray(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights,
                       shadow_rays, shadow_hits, j, shadow_radiance, caustic_map, &cprm);
        } else {
            const uint i = j - n_shadow;
            const Ray r = rays[i];
            const Hit h = trace_ray(TRACE_SERIAL_ARGS, &r, depth);
            hits[i] = h;
            shade_hit(RENDER_GEOM_ARGS, prm, cam, r, h, i, depth, radiance, child_counts, aov,
                      write_aov);
        }
    }
}

/* The two above with each round's entries taken in the order of their cost class (render_bins.h;
 * RenderSettings.cost_bins: level depth - 1's crossing shadow rays, its other shadow rays, level
 * depth's traces, none): the same bytes. */
__kernel __attribute__((reqd_work_group_size(RENDER_BIN_WG, 1, 1))) void
render_shadow_trace_binned(SCENE_PARAMS, RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                           __global const Light* restrict lights,
                           __global const uint* restrict counts, const uint depth,
                           __global const Ray* restrict shadow_rays,
                           __global const Hit* restrict shadow_hits,
                           __global float4* restrict shadow_radiance,
                           __global const float4* restrict caustic_map, const CausticParams cprm,
                           LIGHT_BUFFER_PARAMS,
                           __global const Ray* restrict rays, __global Hit* restrict hits)
{
    __local RenderBins bins;
    const uint n_shadow = counts[depth - 1u], n = n_shadow + counts[depth];
    for (uint base = get_group_id(0) * RENDER_BIN_WG; base < n;
         base += get_num_groups(0) * RENDER_BIN_WG) {   /* uniform over the work-group */
        const uint j = base + get_local_id(0);
        const uint i = bin_round(&bins, j, shadow_trace_cost_class(prm, shadow_rays, shadow_hits,
                                                                    j, n_shadow, n, &cprm));
        if (i >= n) continue;
        if (i < n_shadow) {
            shadow_ray(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights,
                       shadow_rays, shadow_hits, i, shadow_radiance, caustic_map, &cprm);
        } else {
            const Ray r = rays[i - n_shadow];
            hits[i - n_shadow] = trace_ray(TRACE_SERIAL_ARGS, &r, depth);
        }
    }
}

__kernel __attribute__((reqd_work_group_size(RENDER_BIN_WG, 1, 1))) void
render_shadow_trace_shade_binned(SCENE_PARAMS, RENDER_GEOM_PARAMS,
                                 __constant const RenderParams* prm,
                                 __global const Light* restrict lights,
                                 __global const uint* restrict counts, const uint depth,
                                 __global const Ray* restrict shadow_rays,
                                 __global const Hit* restrict shadow_hits,
                                 __global float4* restrict shadow_radiance,
                                 __global const float4* restrict caustic_map,
                                 const CausticParams cprm, LIGHT_BUFFER_PARAMS,
                                 __constant const Camera* cam,
                                 __global const Ray* restrict rays, __global Hit* restrict hits,
                                 __global float4* restrict radiance,
                                 __global uint* restrict child_counts,
                                 __global Aov* restrict aov, const uint write_aov)
{
    __local RenderBins bins;
    const uint n_shadow = counts[depth - 1u], n = n_shadow + counts[depth];
    for (uint base = get_group_id(0) * RENDER_BIN_WG; base < n;
         base += get_num_groups(0) * RENDER_BIN_WG) {   /* uniform over the work-group */
        const uint j = base + get_local_id(0);
        const uint i = bin_round(&bins, j, shadow_trace_cost_class(prm, shadow_rays, shadow_hits,
                                                                    j, n_shadow, n, &cprm));
        if (i >= n) continue;
        if (i < n_shadow) {
            shadow_ray(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights,
                       shadow_rays, shadow_hits, i, shadow_radiance, caustic_map, &cprm);
        } else {
            const uint t = i - n_shadow;
            const Ray r = rays[t];
            const Hit h = trace_ray(TRACE_SERIAL_ARGS, &r, depth);
            hits[t] = h;
            shade_hit(RENDER_GEOM_ARGS, prm, cam, r, h, t, depth, radiance, child_counts, aov,
                      write_aov);
        }
    }
}

#if TRACE_COOP
__kernel __attribute__((reqd_work_group_size(TRACE_COOP_WIDTH, 1, 1))) void
render_shadow_trace_coop(SCENE_PARAMS, RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                         __global const Light* restrict lights,
                         __global const uint* restrict counts, const uint depth,
                         __global const Ray* restrict shadow_rays,
                         __global const Hit* restrict shadow_hits,
                         __global float4* restrict shadow_radiance,
                         __global const float4* restrict caustic_map, const CausticParams cprm,
                         LIGHT_BUFFER_PARAMS,
                         __global const Ray* restrict rays, __global Hit* restrict hits,
                         const uint coop_shadow)
{
    __local TraceCoop coop;
    /* level depth - 1's shadow rays a group each only from coop_from on (coop_shadow) */
    shadow_rays_coop(SCENE_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights, shadow_rays,
                     shadow_hits, counts[depth - 1u], coop_shadow, shadow_radiance, caustic_map,
                     &cprm, &coop);
    trace_rays_coop(SCENE_ARGS, rays, counts[depth], depth, hits, &coop);
}

__kernel __attribute__((reqd_work_group_size(TRACE_COOP_WIDTH, 1, 1))) void
render_shadow_trace_shade_coop(SCENE_PARAMS, RENDER_GEOM_PARAMS,
                               __constant const RenderParams* prm,
                               __global const Light* restrict lights,
                               __global const uint* restrict counts, const uint depth,
                               __global const Ray* restrict shadow_rays,
                               __global const Hit* restrict shadow_hits,
                               __global float4* restrict shadow_radiance,
                               __global const float4* restrict caustic_map,
                               const CausticParams cprm, LIGHT_BUFFER_PARAMS,
                               __constant const Camera* cam,
                               __global const Ray* restrict rays, __global Hit* restrict hits,
                               __global float4* restrict radiance,
                               __global uint* restrict child_counts, __global Aov* restrict aov,
                               const uint write_aov, const uint coop_shadow)
{
    __local TraceCoop coop;
    /* level depth - 1's shadow rays a group each only from coop_from on (coop_shadow) */
    shadow_rays_coop(SCENE_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights, shadow_rays,
                     shadow_hits, counts[depth - 1u], coop_shadow, shadow_radiance, caustic_map,
                     &cprm, &coop);
    trace_shade_rays_coop(SCENE_ARGS, RENDER_GEOM_ARGS, prm, cam, rays, counts[depth], depth,
                          hits, radiance, child_counts, aov, write_aov, &coop);
}
#endif
