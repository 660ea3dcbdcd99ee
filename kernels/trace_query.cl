/* Thin entry points over traverse.h for raytrace.intersect and the benchmark: one ray per
   work-item, ray i = (org[i].xyz, dir[i].xyz) over [org[i].w, dir[i].w) (tmin, tmax). */
#include "traverse.h"

__kernel void trace_closest(SCENE_PARAMS, int n, __global const float4* restrict org,
                            __global const float4* restrict dir, __global Hit* restrict hits) {
    int i = get_global_id(0);
    if (i >= n) return;
    float4 o = org[i], d = dir[i];
    hits[i] = scene_closest_hit(SCENE_ARGS, o.xyz, d.xyz, o.w, d.w);
}

__kernel void trace_any(SCENE_PARAMS, int n, __global const float4* restrict org,
                        __global const float4* restrict dir, __global Hit* restrict hits) {
    int i = get_global_id(0);
    if (i >= n) return;
    float4 o = org[i], d = dir[i];
    Hit h;
    scene_any_hit_record(SCENE_ARGS, o.xyz, d.xyz, o.w, d.w, &h);
    hits[i] = h;
}
