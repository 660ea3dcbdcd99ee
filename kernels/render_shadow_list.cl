/* Renderer stage with RenderSettings.shadow_list: the shadow rays of every depth level as one
 * list, traced in one launch after the last level's trace, instead of a launch per level
 * (render_shade.cl's render_shadow and its flavours).
 *
 * render_shade_list shades each hit as render_shade does (shade_hit) and does render_shadow's
 * per-hit work (shadow_site, light_term, the cut-off; render_shadow.h) in the same pass: the
 * light that needs no shadow ray joins the hit's radiance, and each shadow ray to trace becomes
 * a ShadowRay entry of the list. A work-group's entries of one light take consecutive slots (one
 * global atomic per part of the list and work-group): in the main part each group's rays that
 * start inside a dielectric (they cross its surface: the pool floor under the water) come
 * first, so that whole warps take alike rays; rays that start in a full light-buffer cell (a
 * fine grid or a BVH walk answers them) go to a part of their own, traced first (past its room,
 * last in the main part). A hit whose shadow ray finds no room says so in its radiance's w (a
 * mask of the lights: as_float), and render_shadow_spill traces those rays before the level's
 * buffers are reused (the same answer, the same sum; the shading holds no walk: on the H200 one
 * out of line took the baseline scene's level-0 shading from 0.147 to 0.255 ms). Those launches
 * cost 0.005 ms each; folded into the levels' scans and the list's launch they cost more (the
 * list's launch 0.344 against 0.244 ms: BENCHMARKS.md, fourteenth session).
 *
 * render_shadow_list traces the list: the same shadow_transmittance as render_shadow, then adds
 * T w E brdf to the pixel's shadow light (render_shadow_list.h: fixed-point sums, the same in any
 * order), which the tonemap pass adds to the framebuffer. The image is the same whatever the
 * order of the atomics and the room of the list; against the per-level stage it differs only by
 * float rounding (a pixel's shadowed light is summed apart from the rest of its radiance). */
#include "common.h"
#include "render_surface.h"
#include "render_shadow.h"
#include "render_shadow_list.h"

/* Classes of a shadow-list entry within a work-group: the full part, then the main part's
   crossing and other rays. */
#define LIST_FULL 0u
#define LIST_CROSSING 1u
#define LIST_OTHER 2u

inline ShadowRay shadow_entry(const ShadowSite* o, uint q, uint light, float3 c)
{
    ShadowRay s;
    s.ox = o->org.x;
    s.oy = o->org.y;
    s.oz = o->org.z;
    s.pixel_light = q | (light << SHADOW_RAY_LIGHT_SHIFT);
    s.cr = c.x;
    s.cg = c.y;
    s.cb = c.z;
    s.medium = o->medium;
    return s;
}

__kernel void render_shade_list(SCENE_PARAMS, RENDER_GEOM_PARAMS,
                                __constant const RenderParams* prm, __constant const Camera* cam,
                                __global const Ray* restrict rays,
                                __global const Hit* restrict hits, __global const uint* counts,
                                const uint depth, __global float4* restrict radiance,
                                __global uint* restrict child_counts, __global Aov* restrict aov,
                                const uint write_aov, __global const Light* restrict lights,
                                __global const float4* restrict caustic_map,
                                const CausticParams cprm, LIGHT_BUFFER_PARAMS,
                                __global ShadowRay* restrict shadow_list,
                                __global uint* restrict list_counts, const ShadowListParams lp,
                                __global ulong* restrict shadow_light)
{
    __local uint group_count[3], group_base[2], group_full;
    const uint n = counts[depth], lid = get_local_id(0);
    for (uint base = get_group_id(0) * get_local_size(0); base < n;
         base += get_num_groups(0) * get_local_size(0)) {   /* uniform over the work-group */
        const uint i = base + lid;
        ShadowSite o;
        bool site = false;
        uint q = 0, spilled = 0;   /* spilled: lights whose shadow ray found no room */
        if (i < n) {   /* one surface_at for the shading and the shadow rays */
            const Ray r = rays[i];
            const Hit h = hits[i];
            Surface surf;
            shade_hit_at(RENDER_GEOM_ARGS, prm, cam, r, h, i, depth, radiance, child_counts,
                         aov, write_aov, &surf);
            site = h.prim >= 0 && shadow_site_of(g_mat, prm, &r, &h, &surf, &cprm, &o);
            q = r.pixel;
        }
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
            const uint cls = !traced ? LIST_OTHER
                             : light_buffer_full(LIGHT_BUFFER_ARGS, l, o.org) ? LIST_FULL
                             : o.medium >= 0 ? LIST_CROSSING : LIST_OTHER;
            const uint k = traced ? atomic_inc(&group_count[cls]) : 0u;
            barrier(CLK_LOCAL_MEM_FENCE);
            if (lid == 0) {   /* full rays past the full part's room go last in the main part */
                const uint nf = group_count[LIST_FULL];
                group_base[0] = atomic_add(&list_counts[0], nf);
                group_full = min(nf, lp.full_room - min(group_base[0], lp.full_room));
                group_base[1] = atomic_add(&list_counts[1], group_count[LIST_CROSSING]
                                           + group_count[LIST_OTHER] + nf - group_full);
            }
            barrier(CLK_LOCAL_MEM_FENCE);
            if (traced) {
                const float3 c = o.w * E * brdf;
                const bool in_full = cls == LIST_FULL && k < group_full;
                const uint slot = in_full ? lp.main_room + group_base[0] + k
                                  : group_base[1] + k
                                    + (cls == LIST_OTHER ? group_count[LIST_CROSSING]
                                       : cls == LIST_FULL ? group_count[LIST_CROSSING]
                                                            + group_count[LIST_OTHER]
                                                            - group_full
                                       : 0u);
                if (in_full || slot < lp.main_room) {
                    shadow_list[slot] = shadow_entry(&o, q, l, c);
                } else {
                    spilled |= 1u << l;
                    atomic_inc(&list_counts[2]);
                }
            }
        }
        if (site && (max3(sum) > 0.0f || spilled)) {
            const float4 L = radiance[i];
            radiance[i] = (float4)(L.xyz + o.w * sum, as_float(spilled));
        }
    }
}

/* Level depth's shadow rays that found no room in the list (render_shade_list marks their
 * lights in radiance[i].w), traced as render_shadow_list would; at once back when no ray of the
 * frame's chunk spilled (list_counts[2]). */
__kernel void render_shadow_spill(SCENE_PARAMS, RENDER_GEOM_PARAMS,
                                  __constant const RenderParams* prm,
                                  __global const Light* restrict lights,
                                  __global const Ray* restrict rays,
                                  __global const Hit* restrict hits, __global const uint* counts,
                                  const uint depth, __global const float4* restrict radiance,
                                  const CausticParams cprm, LIGHT_BUFFER_PARAMS,
                                  __global const uint* restrict list_counts,
                                  __global ulong* restrict shadow_light)
{
    if (list_counts[2] == 0u) return;
    const uint n = counts[depth];
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) {
        const uint spilled = as_uint(radiance[i].w);
        ShadowSite o;
        if (!spilled || !shadow_site(RENDER_GEOM_ARGS, prm, rays, hits, i, &cprm, &o)) continue;
        for (uint l = 0; l < prm->n_lights; l++) {
            const Light li = lights[l];
            float3 ldir, E, brdf;
            float dist;
            if (!((spilled >> l) & 1u) || !light_term(&o, li, &ldir, &dist, &E, &brdf))
                continue;
            shadow_ray_toward(li, o.org, &ldir, &dist);
            const float3 T = shadow_transmittance(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS,
                                                  LIGHT_BUFFER_ARGS, prm, l, o.org, ldir, dist,
                                                  o.medium);
            if (max3(T) > 0.0f)
                shadow_light_add(shadow_light, rays[i].pixel, T * (o.w * E * brdf));
        }
    }
}

/* The list's rays, the full part first; adds the frame's count of listed rays and of those
 * spilled to the stats. The list's counts are zeroed by render_raygen. */
__kernel void render_shadow_list(SCENE_PARAMS, RENDER_GEOM_PARAMS, LIGHT_BUFFER_PARAMS,
                                 __constant const RenderParams* prm,
                                 __global const Light* restrict lights,
                                 __global const ShadowRay* restrict shadow_list,
                                 __global const uint* restrict list_counts,
                                 const ShadowListParams lp, __global ulong* restrict shadow_light,
                                 __global uint* restrict stats)
{
    const uint n_full = min(list_counts[0], lp.full_room);
    const uint n = n_full + min(list_counts[1], lp.main_room);
    if (get_global_id(0) == 0) {
        stats[RENDER_STAT_SHADOW_LISTED] += n;
        stats[RENDER_STAT_SHADOW_SPILLED] += list_counts[2];
    }
    for (uint j = get_global_id(0); j < n; j += get_global_size(0)) {
        const ShadowRay s = shadow_list[j < n_full ? lp.main_room + j : j - n_full];
        const uint l = s.pixel_light >> SHADOW_RAY_LIGHT_SHIFT;
        const float3 org = (float3)(s.ox, s.oy, s.oz);
        float3 dir;
        float tmax;
        shadow_ray_toward(lights[l], org, &dir, &tmax);
        const float3 T = shadow_transmittance(TRACE_SERIAL_ARGS, RENDER_GEOM_ARGS,
                                              LIGHT_BUFFER_ARGS, prm, l, org, dir, tmax,
                                              s.medium);
        if (max3(T) > 0.0f)
            shadow_light_add(shadow_light, s.pixel_light & SHADOW_RAY_PIXEL_MASK,
                             T * (float3)(s.cr, s.cg, s.cb));
    }
}
