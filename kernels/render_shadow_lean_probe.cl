/* A diagnosis, not a render stage (bench/shadow_lean_probe.py; tests/raytrace/
 * test_shadow_lean_probe.py): one level's shadow rays as two launches instead of render_shadow's
 * one, to measure what a shadow stage that traces a list of rays the shading wrote would cost.
 *
 * render_shadow_emit runs render_shadow's per-hit work (shadow_site, light_term, the cut-off;
 * render_shadow.h) and adds the light that needs no shadow ray to radiance[i]; where
 * render_shadow would trace, it appends the shadow ray to a list instead, as a Ray record:
 * origin, the hit's index i as ``pixel``, direction, medium, the weight w E brdf, and tmax's bits
 * as ``sample``. Rays that start inside a dielectric (they cross its surface: the pool's floor
 * under the water) fill the list from the front, the others from the back (list_counts[0] and
 * [1]), so whole warps take alike rays. render_shadow_lean traces the list alone: the same
 * shadow_transmittance, then radiance[i] += T w E brdf. With one light per scene the two give
 * render_shadow's radiance up to rounding (w E brdf T summed in another order); with several, two
 * entries of one hit could add to radiance[i] at once, so the probe takes one light.
 * Built with LEAN_FULL_FIRST=1, the rays whose origin lies in a full light-buffer cell (more
 * than LB_SLOTS triangles: a fine grid's cells or a BVH walk answer them) go first, in a list of
 * their own (list_counts[2], from list[capacity]), so that the costliest start first. */
#include "common.h"
#include "render_bins.h"
#include "render_shadow.h"

#ifndef LEAN_FULL_FIRST
#define LEAN_FULL_FIRST 0
#endif

__kernel void render_shadow_emit(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                                 __global const Light* restrict lights,
                                 __global const Ray* restrict rays,
                                 __global const Hit* restrict hits, __global const uint* counts,
                                 const uint depth, __global float4* restrict radiance,
                                 __global const float4* restrict caustic_map,
                                 const CausticParams cprm, __global Ray* restrict list,
                                 __global uint* restrict list_counts, const uint capacity,
                                 LIGHT_BUFFER_PARAMS)
{
    /* a work-group's entries of one light take consecutive slots: one global atomic per list
       and work-group (a scan's cost), not one per ray */
    __local uint group_count[3], group_base[3];
    const uint n = counts[depth], lid = get_local_id(0);
    for (uint base = get_group_id(0) * get_local_size(0); base < n;
         base += get_num_groups(0) * get_local_size(0)) {   /* uniform over the work-group */
        const uint i = base + lid;
        ShadowSite o;
        const bool site = i < n && shadow_site(RENDER_GEOM_ARGS, prm, rays, hits, i, &cprm, &o);
        float3 sum = (float3)(0.0f);
        if (site && o.caustic) sum = caustic_lookup(caustic_map, &cprm, o.s.p, o.nf_g) * o.s.kd;
        for (uint l = 0; l < prm->n_lights; l++) {   /* uniform */
            if (lid < 3) group_count[lid] = 0;
            barrier(CLK_LOCAL_MEM_FENCE);
            float3 ldir, E, brdf;
            float dist;
            bool traced = false;
            if (site && !(o.caustic && ((cprm.light_mask >> l) & 1u))
                && light_term(&o, lights[l], &ldir, &dist, &E, &brdf)) {
                if (light_below_cut(prm, &o, E, brdf)) sum += E * brdf;
                else traced = true;
            }
            const bool crossing = site && o.medium >= 0;
            const bool full = LEAN_FULL_FIRST && traced
                              && light_buffer_full(LIGHT_BUFFER_ARGS, l, o.org);
            const uint cls = full ? 2u : crossing ? 0u : 1u;
            const uint k = traced ? atomic_inc(&group_count[cls]) : 0u;
            barrier(CLK_LOCAL_MEM_FENCE);
            if (lid < 3) group_base[lid] = atomic_add(&list_counts[lid], group_count[lid]);
            barrier(CLK_LOCAL_MEM_FENCE);
            if (traced) {
                const uint slot = group_base[cls] + k;
                const float3 c = o.w * E * brdf;
                Ray s;
                s.ox = o.org.x;
                s.oy = o.org.y;
                s.oz = o.org.z;
                s.pixel = i;
                s.dx = ldir.x;
                s.dy = ldir.y;
                s.dz = ldir.z;
                s.medium = o.medium;
                s.wr = c.x;
                s.wg = c.y;
                s.wb = c.z;
                s.sample = as_uint(dist);
                list[full ? capacity + slot : crossing ? slot : capacity - 1u - slot] = s;
            }
        }
        if (site) radiance[i] += (float4)(o.w * sum, 0.0f);
    }
}

__kernel void render_shadow_lean(SCENE_PARAMS, RENDER_GEOM_PARAMS, LIGHT_BUFFER_PARAMS,
                                 __constant const RenderParams* prm,
                                 __global const Ray* restrict list,
                                 __global const uint* restrict list_counts, const uint capacity,
                                 __global float4* restrict radiance)
{
    const uint first = list_counts[2], front = first + list_counts[0];
    const uint n = front + list_counts[1];
    for (uint j = get_global_id(0); j < n; j += get_global_size(0)) {
        const Ray s = list[j < first ? capacity + j
                           : j < front ? j - first : capacity - 1u - (j - front)];
        const float3 T = shadow_transmittance(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS,
                                              LIGHT_BUFFER_ARGS, prm, 0u, ray_org(&s),
                                              ray_dir(&s), as_float(s.sample), s.medium);
        if (max3(T) > 0.0f) radiance[s.pixel] += (float4)(T * ray_weight(&s), 0.0f);
    }
}

/* The same question for the renderer's own shadow kernels: would they gain from taking the hits
 * whose shadow rays start in a full light-buffer cell first? render_shadow_classify flags them
 * (first_flags[i], and their indices in first_list); render_shadow_ordered and
 * render_shadow_ordered_binned are render_shadow and render_shadow_binned over the list first,
 * then the other hits in order. Which work-item takes a hit never changes its radiance. */
__kernel void render_shadow_classify(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                                     __global const Ray* restrict rays,
                                     __global const Hit* restrict hits,
                                     __global const uint* counts, const uint depth,
                                     const CausticParams cprm, LIGHT_BUFFER_PARAMS,
                                     __global uchar* restrict first_flags,
                                     __global uint* restrict first_list,
                                     __global uint* restrict first_count)
{
    const uint n = counts[depth];
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) {
        ShadowSite o;
        bool full = false;
        if (shadow_site(RENDER_GEOM_ARGS, prm, rays, hits, i, &cprm, &o))
            for (uint l = 0; l < prm->n_lights; l++)
                full |= light_buffer_full(LIGHT_BUFFER_ARGS, l, o.org);
        first_flags[i] = full ? 1 : 0;
        if (full) first_list[atomic_inc(first_count)] = i;
    }
}

/* Entry j of the ordered launch: first_list's hits, then the others (n: none, a flagged one) */
inline uint ordered_hit(const uint j, const uint n, const uint n_first,
                        __global const uchar* restrict first_flags,
                        __global const uint* restrict first_list)
{
    if (j < n_first) return first_list[j];
    if (j >= n_first + n || first_flags[j - n_first]) return n;
    return j - n_first;
}

/* The parameters of both ordered kernels: render_shadow's, then the classification's. */
#define ORDERED_SHADOW_PARAMS                                                                  \
    SCENE_PARAMS, RENDER_GEOM_PARAMS, __constant const RenderParams* prm,                      \
        __global const Light* restrict lights, __global const Ray* restrict rays,             \
        __global const Hit* restrict hits, __global const uint* counts, const uint depth,     \
        __global float4* restrict radiance, __global const float4* restrict caustic_map,      \
        const CausticParams cprm, LIGHT_BUFFER_PARAMS,                                         \
        __global const uchar* restrict first_flags, __global const uint* restrict first_list, \
        __global const uint* restrict first_count

__kernel void render_shadow_ordered(ORDERED_SHADOW_PARAMS)
{
    const uint n = counts[depth], n_first = *first_count;
    for (uint j = get_global_id(0); j < n_first + n; j += get_global_size(0)) {
        const uint i = ordered_hit(j, n, n_first, first_flags, first_list);
        if (i < n)
            shadow_ray(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights, rays,
                       hits, i, radiance, caustic_map, &cprm);
    }
}

__kernel __attribute__((reqd_work_group_size(RENDER_BIN_WG, 1, 1))) void
render_shadow_ordered_binned(ORDERED_SHADOW_PARAMS)
{
    __local RenderBins bins;
    const uint n = counts[depth], n_first = *first_count;
    for (uint base = get_group_id(0) * RENDER_BIN_WG; base < n_first + n;
         base += get_num_groups(0) * RENDER_BIN_WG) {   /* uniform over the work-group */
        const uint e = ordered_hit(base + get_local_id(0), n, n_first, first_flags, first_list);
        const uint cls = e < n ? shadow_cost_class(prm, rays, hits, e, &cprm) : RENDER_BIN_IDLE;
        const uint i = bin_round(&bins, e, cls);
        if (i < n)
            shadow_ray(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights, rays,
                       hits, i, radiance, caustic_map, &cprm);
    }
}
