/* Renderer: the per-ray body of the trace stage (closest hit of one wavefront ray), shared by
 * render_trace / render_trace_shade (render_trace.cl) and render_shadow_trace
 * (render_shadow_trace.cl), so all run the same code. */
#ifndef LBWATER_RENDER_TRACE_H
#define LBWATER_RENDER_TRACE_H

#include "render_surface.h"
#include "render_types.h"
#include "traverse_coop.h"

/* TRACE_PARAMS: per work-item, or per work-group with coop_on (traverse_coop.h) */
inline Hit trace_ray(TRACE_PARAMS, const Ray* r, uint depth)
{
    Hit h = {INFINITY, 0.0f, 0.0f, -1, -1};
    if (r->wr + r->wg + r->wb > 0.0f)   /* dead padding rays have zero weight */
        h = trace_closest_masked(TRACE_ARGS, (float3)(r->ox, r->oy, r->oz),
                                 (float3)(r->dx, r->dy, r->dz), 0.0f, INFINITY, ~0u,
                                 depth ? TRACE_KIND_SECONDARY : TRACE_KIND_PRIMARY);
    return h;
}

#if TRACE_COOP
/* Level depth's n rays traced: a work-group per ray while few, else a work-item per ray; the
 * work-item holding a ray's hit writes it. */
inline void trace_rays_coop(SCENE_PARAMS, __global const Ray* restrict rays, const uint n,
                            const uint depth, __global Hit* restrict hits,
                            __local TraceCoop* coop)
{
    const bool on = n <= TRACE_COOP_MAX_RAYS;   /* uniform over the work-group */
    TRACE_COOP_FOR(i, n, on) {
        const Ray r = rays[i];
        const Hit h = trace_ray(TRACE_COOP_IF_ARGS(coop, on), &r, depth);
        if (!on || get_local_id(0) == 0) hits[i] = h;
    }
}

/* The same, each hit shaded at once (shade_hit) by the work-item that writes it. */
inline void trace_shade_rays_coop(SCENE_PARAMS, RENDER_GEOM_PARAMS,
                                  __constant const RenderParams* prm,
                                  __constant const Camera* cam, __global const Ray* restrict rays,
                                  const uint n, const uint depth, __global Hit* restrict hits,
                                  __global float4* restrict radiance,
                                  __global uint* restrict child_counts,
                                  __global Aov* restrict aov, const uint write_aov,
                                  __local TraceCoop* coop)
{
    const bool on = n <= TRACE_COOP_MAX_RAYS;   /* uniform over the work-group */
    TRACE_COOP_FOR(i, n, on) {
        const Ray r = rays[i];
        const Hit h = trace_ray(TRACE_COOP_IF_ARGS(coop, on), &r, depth);
        if (!on || get_local_id(0) == 0) {
            hits[i] = h;
            shade_hit(RENDER_GEOM_ARGS, prm, cam, r, h, i, depth, radiance, child_counts, aov,
                      write_aov);
        }
    }
}
#endif

#endif
