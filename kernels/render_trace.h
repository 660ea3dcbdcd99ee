/* Renderer: the per-ray body of the trace stage (closest hit of one wavefront ray), shared by
 * render_trace / render_trace_shade (render_trace.cl) and render_shadow_trace
 * (render_shadow_trace.cl), so all run the same code. */
#ifndef LBWATER_RENDER_TRACE_H
#define LBWATER_RENDER_TRACE_H

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

#endif
