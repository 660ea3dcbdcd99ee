/* Renderer: the per-ray body of the shadow stage (direct light of one hit through shadow rays),
 * shared by render_shadow (render_shade.cl) and render_shadow_trace (render_shadow_trace.cl), so
 * both run the same code. */
#ifndef LBWATER_RENDER_SHADOW_H
#define LBWATER_RENDER_SHADOW_H

#include "caustics.h"
#include "render_surface.h"
#include "traverse_coop.h"
#include "light_buffer.h"

inline float smooth01(float e0, float e1, float x)
{
    const float t = clamp((x - e0) / fmax(e1 - e0, 1e-7f), 0.0f, 1.0f);
    return t * t * (3.0f - 2.0f * t);
}

/* The shadow stage's two walks, each a function of its own that the compiler keeps out of line:
 * the any-hit walk of a ray the light buffer leaves unknown and a crossing's closest hit.
 * Inlined, their code and traversal stacks sat in every shadow kernel beside its shading; out
 * of line, the baseline scene's shadow rays took 0.528 against 0.558 ms on the H200, with the
 * same registers (BENCHMARKS.md, twelfth session; bench/patches/shadow_walks_noinline.patch).
 * On a CPU (TRACE_CPU: PoCL) they stay inline, as every traversal helper there (traverse.h):
 * out of line, PoCL's level-0 shadow launch took 3% longer. */
#if TRACE_CPU
#define SHADOW_WALK TRACE_INLINE
#else
#define SHADOW_WALK __attribute__((noinline))
#endif

SHADOW_WALK bool shadow_any_walk(TRACE_PARAMS, float3 org, float3 dir, float tmax, uint mask)
{
    return trace_any_masked(TRACE_ARGS, org, dir, 0.0f, tmax, mask, TRACE_KIND_SHADOW);
}

SHADOW_WALK Hit shadow_crossing_walk(TRACE_PARAMS, float3 org, float3 dir, float tmax, int ci,
                                     int kind)
{
    return trace_closest_only(TRACE_ARGS, org, dir, 0.0f, tmax, RENDER_MASK_TRANSMISSIVE, ci,
                              kind);
}

/* Fraction of light `light` reaching org along dir within tmax. Opaque scenes: one any-hit
 * query, answered from the light's map where it has one (light_buffer.h: the same answer).
 * With dielectrics (transmissive_shadows), the ray goes straight through up to
 * RENDER_MAX_SHADOW_CROSSINGS dielectric surfaces, times (1 - Fresnel) at each and Beer-Lambert
 * inside (no refraction bending: no caustics). There, first an any-hit query of the opaque-only
 * instances (RENDER_MASK_OPAQUE: it ends at the first blocker and never enters the water's
 * tree), then the crossings, closest hit by closest hit, of the instances that hold a
 * dielectric (RENDER_MASK_TRANSMISSIVE; an opaque triangle there still blocks): where one
 * instance holds them all (RenderParams.crossing_instance: the water, as a rule), its own
 * BLAS or height-field walk alone, with no TLAS walk, which half the crossings of the water's
 * sunlit hits spent proving the ray misses the water's box. Where that instance is the height
 * field and the ray climbs faster than its slopes (RenderParams.one_crossing, hf_climbs), the
 * walks that can find nothing are left out: the one from a point over the surface
 * (hf_unreachable: the water's own sunlit points) and the one after the ray leaves the water
 * (the floor's). */
inline float3 shadow_transmittance(TRACE_PARAMS, RENDER_GEOM_PARAMS, LIGHT_BUFFER_PARAMS,
                                   __constant const RenderParams* prm, uint light, float3 org,
                                   float3 dir, float tmax, int medium)
{
    /* one any-hit call site for both cases (one walk's code in the kernel) */
    const uint opaque = prm->transmissive_shadows ? RENDER_MASK_OPAQUE : ~0u;
    const int mapped = light_buffer_blocked(LIGHT_BUFFER_ARGS, instances, light, org, dir, tmax,
                                            trace_stats);
    if (mapped == LB_BLOCKED
        || (mapped == LB_UNKNOWN
            && shadow_any_walk(TRACE_ARGS, org, dir, tmax, opaque)))
        return (float3)(0.0f);
    if (!prm->transmissive_shadows) return (float3)(1.0f);
    /* a ray that climbs faster than the water's slopes (hf_climbs) crosses it at most once,
       upward: from over the surface it crosses nothing, and after an exit nothing more */
    const int ci = prm->crossing_instance;
    bool climbs = false, over = false;
    if (prm->one_crossing && ci >= 0 && instances[ci].mesh == hf_info->mesh) {
        float3 oo, od;
        trace_object_ray_od(instances + ci, org, dir, &oo, &od);
        climbs = hf_climbs(hf_info, od);
        over = climbs && hf_unreachable(hf_info, hf_vertices, oo, od);
    }
    float3 T = (float3)(1.0f);
    for (int k = 0; k < RENDER_MAX_SHADOW_CROSSINGS; k++) {
        Hit h = {INFINITY, 0.0f, 0.0f, -1, -1};
        if (!(climbs && medium < 0 && (k || over)))
            h = shadow_crossing_walk(TRACE_ARGS, org, dir, tmax, ci,
                                     TRACE_KIND_CROSSING | (k ? TRACE_CONTINUE : 0));
        if (h.prim < 0) {
            if (medium >= 0) T *= beer(g_mat[medium].absorption.xyz, tmax);
            return T;
        }
        const Surface s = surface_at(RENDER_GEOM_ARGS, h.inst, h.prim, h.u, h.v);
        const Material m = g_mat[s.material];
        if (!is_dielectric(&m)) return (float3)(0.0f);
        if (medium >= 0) T *= beer(g_mat[medium].absorption.xyz, h.t);
        float3 nf_g, nf_s;
        facing_normals(&s, dir, &nf_g, &nf_s);
        const bool entering = dot(dir, s.ng) < 0.0f;
        const float eta = entering ? 1.0f / m.absorption.w : m.absorption.w;
        T *= 1.0f - fresnel(prm->fresnel, -dot(dir, nf_g), eta);
        medium = entering ? s.material : RENDER_NO_MEDIUM;
        org = offset_ray(s.p, -nf_g);
        tmax -= h.t;
    }
    return (float3)(0.0f);
}

/* What the shadow rays of one hit share: its surface, the weight its direct light adds to the
 * pixel with (the ray's attenuated weight times the material's direct fraction), the view
 * direction, the facing normals, the shadow rays' origin and medium, and whether the caustic map
 * carries its lights (a pool surface seen through the water: caustics.cl). */
typedef struct {
    Surface s;
    float4 specular;   /* the material's specular rgb, w: shininess */
    float3 w, d, nf_g, nf_s, org;
    int medium;
    bool caustic;
} ShadowSite;

/* The ShadowSite in *o of a hit h of ray r at surface s (surface_at); false when it adds no
 * direct light (no lights, no weight). */
inline bool shadow_site_of(__global const Material* restrict g_mat,
                           __constant const RenderParams* prm, const Ray* r, const Hit* h,
                           const Surface* s, const CausticParams* cp, ShadowSite* o)
{
    if (prm->n_lights == 0) return false;
    o->s = *s;
    const Material m = g_mat[s->material];
    o->w = attenuated_weight(r, h->t, g_mat) * direct_fraction(&m);
    if (max3(o->w) <= 0.0f) return false;
    o->specular = m.specular;
    o->d = ray_dir(r);
    facing_normals(&o->s, o->d, &o->nf_g, &o->nf_s);
    o->org = offset_ray(o->s.p, o->nf_g);
    o->medium = r->medium;
    o->caustic = cp->enabled && h->inst == cp->pool_instance && r->medium >= 0;
    return true;
}

/* Hit i's ShadowSite in *o; false when it adds no direct light (a miss, no lights, no weight). */
inline bool shadow_site(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                        __global const Ray* restrict rays, __global const Hit* restrict hits,
                        uint i, const CausticParams* cp, ShadowSite* o)
{
    const Hit h = hits[i];
    if (h.prim < 0 || prm->n_lights == 0) return false;
    const Ray r = rays[i];
    const Surface s = surface_at(RENDER_GEOM_ARGS, h.inst, h.prim, h.u, h.v);
    return shadow_site_of(g_mat, prm, &r, &h, &s, cp, o);
}

/* The ray from org towards light li: its unit direction and length (INFINITY: directional).
 * light_term takes it from the surface point; every shadow stage traces it from the offset
 * origin, so that a list entry (ShadowRay) need not carry it: the list's kernel derives the
 * same ray from the origin and the light. */
inline void shadow_ray_toward(const Light li, float3 org, float3* dir, float* tmax)
{
    if (li.kind == LIGHT_SPOT) {
        const float3 to = li.position.xyz - org;
        *tmax = length(to);
        *dir = to / *tmax;
    } else {
        *dir = -li.direction.xyz;
        *tmax = INFINITY;
    }
}

/* Light li at site o unshadowed: the direction to it and its distance (INFINITY: directional),
 * its irradiance E and the Phong BRDF times the cosine; false when it adds nothing (behind the
 * surface, outside a spot's cone). */
inline bool light_term(const ShadowSite* o, const Light li, float3* ldir, float* dist, float3* E,
                       float3* brdf)
{
    shadow_ray_toward(li, o->s.p, ldir, dist);
    *E = li.kind == LIGHT_SPOT
             ? li.color.xyz * (smooth01(li.cos_outer, li.cos_inner, dot(-*ldir, li.direction.xyz))
                               / (*dist * *dist))
             : li.color.xyz;
    const float ndl = dot(o->nf_s, *ldir);
    if (ndl <= 0.0f || dot(o->nf_g, *ldir) <= 0.0f || max3(*E) <= 0.0f) return false;
    const float rv = fmax(dot(reflect_dir(-*ldir, o->nf_s), -o->d), 0.0f);
    const float spec = o->specular.w > 0.0f ? pow(rv, o->specular.w) : 1.0f;
    *brdf = o->s.kd * ndl + o->specular.xyz * spec;
    return true;
}

/* Whether light that adds E brdf at site o goes unshadowed, with no shadow ray: it adds less than
 * min_weight to the pixel (the cut-off of children), e.g. the water's sharp highlight away from
 * the sun's mirror direction, a third of the pool's shadow rays. Unoccluded, the same sum. */
inline bool light_below_cut(__constant const RenderParams* prm, const ShadowSite* o, float3 E,
                            float3 brdf)
{
    return max3(o->w * E * brdf) < prm->min_weight;
}

/* With coop_on, the whole work-group runs it for ray i alike; one work-item adds the light. */
inline void shadow_ray(TRACE_PARAMS, RENDER_GEOM_PARAMS, LIGHT_BUFFER_PARAMS,
                       __constant const RenderParams* prm,
                       __global const Light* restrict lights, __global const Ray* restrict rays,
                       __global const Hit* restrict hits, uint i,
                       __global float4* restrict radiance,
                       __global const float4* restrict caustic_map, const CausticParams* cp)
{
    ShadowSite o;
    if (!shadow_site(RENDER_GEOM_ARGS, prm, rays, hits, i, cp, &o)) return;
    float3 sum = (float3)(0.0f);
    if (o.caustic) sum = caustic_lookup(caustic_map, cp, o.s.p, o.nf_g) * o.s.kd;
    for (uint l = 0; l < prm->n_lights; l++) {
        if (o.caustic && ((cp->light_mask >> l) & 1u)) continue;
        const Light li = lights[l];
        float3 ldir, E, brdf;
        float dist;
        if (!light_term(&o, li, &ldir, &dist, &E, &brdf)) continue;
        if (light_below_cut(prm, &o, E, brdf)) {
            sum += E * brdf;
            continue;
        }
        shadow_ray_toward(li, o.org, &ldir, &dist);
        const float3 T = shadow_transmittance(TRACE_ARGS, RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm,
                                              l, o.org, ldir, dist, o.medium);
        if (max3(T) <= 0.0f) continue;
        sum += T * E * brdf;
    }
    if (TRACE_LEADER) radiance[i] += (float4)(o.w * sum, 0.0f);
}

#if TRACE_COOP
/* The shadow rays of the n hits of a level: a work-group per ray while few (and ``allowed``),
 * else a work-item per ray; ``allowed`` uniform over the work-group. */
inline void shadow_rays_coop(SCENE_PARAMS, RENDER_GEOM_PARAMS, LIGHT_BUFFER_PARAMS,
                             __constant const RenderParams* prm,
                             __global const Light* restrict lights,
                             __global const Ray* restrict rays,
                             __global const Hit* restrict hits, const uint n, const bool allowed,
                             __global float4* restrict radiance,
                             __global const float4* restrict caustic_map,
                             const CausticParams* cp, __local TraceCoop* coop)
{
    const bool on = allowed && n <= TRACE_COOP_MAX_RAYS;
    TRACE_COOP_FOR(i, n, on)
        shadow_ray(TRACE_COOP_IF_ARGS(coop, on), RENDER_GEOM_ARGS, LIGHT_BUFFER_ARGS, prm, lights,
                   rays, hits, i,
                   radiance, caustic_map, cp);
}
#endif

#endif
