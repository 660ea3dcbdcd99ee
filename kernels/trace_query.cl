/* Thin entry points over traverse.h for raytrace.intersect and the benchmark: one ray per
   work-item, ray i = (org[i].xyz, dir[i].xyz) over [org[i].w, dir[i].w) (tmin, tmax), seeing
   the instances whose visibility mask shares a bit with `mask`. */
#include "traverse.h"

__kernel void trace_closest(SCENE_PARAMS, int n, __global const float4* restrict org,
                            __global const float4* restrict dir, __global Hit* restrict hits,
                            uint mask) {
    int i = get_global_id(0);
    if (i >= n) return;
    float4 o = org[i], d = dir[i];
    hits[i] = scene_closest_hit_masked(SCENE_ARGS, o.xyz, d.xyz, o.w, d.w, mask,
                                       TRACE_KIND_QUERY);
}

__kernel void trace_any(SCENE_PARAMS, int n, __global const float4* restrict org,
                        __global const float4* restrict dir, __global Hit* restrict hits,
                        uint mask) {
    int i = get_global_id(0);
    if (i >= n) return;
    float4 o = org[i], d = dir[i];
    Hit h;
    trace_scene(SCENE_ARGS, o.xyz, d.xyz, o.w, d.w, true, mask, &h, TRACE_KIND_QUERY);
    hits[i] = h;
}
