/* Renderer stage: closest hit of every ray in the wavefront (primary or secondary). */
#include "common.h"
#include "render_types.h"
#include "traverse.h"

__kernel void render_trace(SCENE_PARAMS, __global const Ray* restrict rays,
                           __global const uint* restrict counts, const uint depth,
                           __global Hit* restrict hits)
{
    const uint i = get_global_id(0);
    GUARD_COUNT(i, counts + depth);
    const Ray r = rays[i];
    Hit h = {INFINITY, 0.0f, 0.0f, -1, -1};
    if (r.wr + r.wg + r.wb > 0.0f)   /* dead padding rays have zero weight */
        h = scene_closest_hit(SCENE_ARGS, (float3)(r.ox, r.oy, r.oz), (float3)(r.dx, r.dy, r.dz),
                              0.0f, INFINITY);
    hits[i] = h;
}
