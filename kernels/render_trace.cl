/* Renderer stage: closest hit of every ray in the wavefront (primary or secondary). */
#include "common.h"
#include "render_types.h"
#include "traverse.h"

__kernel void render_trace(SCENE_PARAMS, __global const Ray* restrict rays,
                           __global const uint* restrict counts, const uint depth,
                           __global Hit* restrict hits)
{
    /* a grid-stride loop: launched with at most a few waves of work-items whatever the count */
    const uint n = counts[depth];
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) {
        const Ray r = rays[i];
        Hit h = {INFINITY, 0.0f, 0.0f, -1, -1};
        if (r.wr + r.wg + r.wb > 0.0f)   /* dead padding rays have zero weight */
            h = scene_closest_hit(SCENE_ARGS, (float3)(r.ox, r.oy, r.oz),
                                  (float3)(r.dx, r.dy, r.dz), 0.0f, INFINITY);
        hits[i] = h;
    }
}
