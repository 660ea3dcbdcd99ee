/* Thin entry points over traverse.h for raytrace.intersect and the benchmark: one ray per
   work-item, ray i = (org[i].xyz, dir[i].xyz) over [org[i].w, dir[i].w) (tmin, tmax), seeing
   the instances whose visibility mask shares a bit with `mask`; with `only` >= 0, that
   instance alone (trace_scene's `only`: its BLAS or height-field walk, no TLAS walk). With
   TRACE_COOP=1, also the cooperative walk (traverse_coop.h): one ray per work-group of
   TRACE_COOP_WIDTH. */
#include "traverse.h"
#include "traverse_coop.h"

__kernel void trace_closest(SCENE_PARAMS, int n, __global const float4* restrict org,
                            __global const float4* restrict dir, __global Hit* restrict hits,
                            uint mask, int only) {
    int i = get_global_id(0);
    if (i >= n) return;
    float4 o = org[i], d = dir[i];
    Hit h;
    trace_scene(SCENE_ARGS, o.xyz, d.xyz, o.w, d.w, false, mask, only, &h, TRACE_KIND_QUERY);
    hits[i] = h;
}

__kernel void trace_any(SCENE_PARAMS, int n, __global const float4* restrict org,
                        __global const float4* restrict dir, __global Hit* restrict hits,
                        uint mask, int only) {
    int i = get_global_id(0);
    if (i >= n) return;
    float4 o = org[i], d = dir[i];
    Hit h;
    trace_scene(SCENE_ARGS, o.xyz, d.xyz, o.w, d.w, true, mask, only, &h, TRACE_KIND_QUERY);
    hits[i] = h;
}

#if TRACE_COOP
/* One ray per work-group (a grid stride over the groups), every work-item tracing it. */
__kernel __attribute__((reqd_work_group_size(TRACE_COOP_WIDTH, 1, 1))) void trace_closest_coop(
    SCENE_PARAMS, int n, __global const float4* restrict org, __global const float4* restrict dir,
    __global Hit* restrict hits, uint mask, int only) {
    __local TraceCoop coop;
    for (int i = get_group_id(0); i < n; i += get_num_groups(0)) {
        float4 o = org[i], d = dir[i];
        Hit h = trace_closest_only(TRACE_COOP_ARGS(&coop), o.xyz, d.xyz, o.w, d.w, mask, only,
                                   TRACE_KIND_QUERY);
        if (get_local_id(0) == 0) hits[i] = h;
    }
}

__kernel __attribute__((reqd_work_group_size(TRACE_COOP_WIDTH, 1, 1))) void trace_any_coop(
    SCENE_PARAMS, int n, __global const float4* restrict org, __global const float4* restrict dir,
    __global Hit* restrict hits, uint mask, int only) {
    __local TraceCoop coop;
    for (int i = get_group_id(0); i < n; i += get_num_groups(0)) {
        float4 o = org[i], d = dir[i];
        Hit h;
        trace_scene_coop(SCENE_ARGS, &coop, o.xyz, d.xyz, o.w, d.w, true, mask, only, &h,
                         TRACE_KIND_QUERY);
        if (get_local_id(0) == 0) hits[i] = h;
    }
}
#endif
