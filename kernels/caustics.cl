/* Caustics stage: sunlight traced through the live water surface onto the pool's floor and walls.
 * Launch order per frame (raytrace/caustics.py, Caustics.enqueue), no host sync:
 *   caustics_clear    zero the fixed-point accumulator (3 uint per texel)
 *   caustics_photons  once per light (directional, or a spot above the water): a jittered
 *                     grid_x * grid_z photon grid over the water at its rest level (from a
 *                     spot: photons aimed at the grid's points); each photon is traced (scene_closest_hit),
 *                     refracted into the water (Snell with the shading normal, 1 - Fresnel),
 *                     attenuated (Beer-Lambert) to its first opaque hit, and splatted there when
 *                     that is the pool instance: atomic_add of its flux in fixed point
 *                     (deterministic: integer sums do not depend on the order)
 *   caustics_filter   per texel: tent filter of filter_radius texels inside its face
 *                     (weights renormalised at the face's edges), flux / texel area =
 *                     irradiance (W/m^2), blended with last frame's map (exponential)
 * Bytes: 12 B accumulator + 16 B map per texel; a photon reads the BVH like a shadow ray. */
#include "common.h"
#include "render_surface.h"
#include "traverse.h"
#include "caustics.h"

__kernel void caustics_clear(__global uint* restrict accum, const CausticParams cp)
{
    const uint n = 3u * cp.n_texels;
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) accum[i] = 0u;
}

inline float cone01(float e0, float e1, float x)   /* render_shadow.h's smooth01 */
{
    const float t = clamp((x - e0) / fmax(e1 - e0, 1e-7f), 0.0f, 1.0f);
    return t * t * (3.0f - 2.0f * t);
}

/* Photon i: a jittered point of its grid cell at the water's rest level; a directional light's
 * photon starts there moved back along the light to emit_y, a spot's at the spot, with the flux
 * of the solid angle the cell subtends, I cone(d) |d.y| cell / dist^2. */
inline float3 photon_start(const CausticParams* cp, uint i, float3* dir, float3* phi)
{
    const uint ix = i % cp->grid_x, iz = i / cp->grid_x;
    const uint key = hash_u32(i * 0x9e3779b9u ^ hash_u32(cp->seed));
    const float jx = hash_unit(key), jz = hash_unit(key ^ 0x68e31da4u);
    const float cw = (cp->emit.z - cp->emit.x) / (float)cp->grid_x;
    const float ch = (cp->emit.w - cp->emit.y) / (float)cp->grid_z;
    const float3 p = (float3)(cp->emit.x + ((float)ix + jx) * cw, cp->light_dir.w,
                              cp->emit.y + ((float)iz + jz) * ch);
    if (cp->light_pos.w > 0.0f) {
        const float3 to = p - cp->light_pos.xyz;
        const float dist2 = dot(to, to);
        *dir = to * rsqrt(dist2);
        *phi = cp->flux.xyz * (cone01(cp->cos_outer, cp->cos_inner,
                                      dot(*dir, cp->light_dir.xyz))
                               * -dir->y / dist2);
        return cp->light_pos.xyz;
    }
    const float3 d = cp->light_dir.xyz;
    *dir = d;
    *phi = cp->flux.xyz;
    return p - d * ((cp->emit_y - cp->light_dir.w) / -d.y);
}

inline void splat(__global uint* restrict accum, const CausticParams* cp, uint t, float3 phi)
{
    const float3 q = phi * cp->flux.w + 0.5f;
    if (q.x >= 1.0f) atomic_add(&accum[3u * t], (uint)q.x);
    if (q.y >= 1.0f) atomic_add(&accum[3u * t + 1u], (uint)q.y);
    if (q.z >= 1.0f) atomic_add(&accum[3u * t + 2u], (uint)q.z);
}

__kernel void caustics_photons(SCENE_PARAMS, RENDER_GEOM_PARAMS, const CausticParams cp,
                               __global uint* restrict accum)
{
    const uint n = cp.grid_x * cp.grid_z;
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) {
        float3 d, phi;
        float3 org = photon_start(&cp, i, &d, &phi);
        int medium = RENDER_NO_MEDIUM;
        for (int k = 0; k < CAUSTIC_MAX_HITS; k++) {
            const Hit h = scene_closest_hit_masked(SCENE_ARGS, org, d, 0.0f, INFINITY, ~0u,
                                                   TRACE_KIND_PHOTON | (k ? TRACE_CONTINUE : 0));
            if (h.prim < 0) break;
            const Surface s = surface_at(RENDER_GEOM_ARGS, h.inst, h.prim, h.u, h.v);
            const Material m = g_mat[s.material];
            if (medium >= 0) phi *= beer(g_mat[medium].absorption.xyz, h.t);
            float3 nf_g, nf_s;
            facing_normals(&s, d, &nf_g, &nf_s);
            if (!is_dielectric(&m)) {
                /* lit through the water, on the pool: splat; anything else shadows */
                if (medium >= 0 && h.inst == cp.pool_instance) {
                    const int f = caustic_face(nf_g);
                    if (f >= 0) splat(accum, &cp, caustic_texel(&cp, f, s.p), phi);
                }
                break;
            }
            /* only the way into the water is followed: light leaving it lights what lies above,
             * which shadow rays handle */
            if (medium >= 0 || dot(d, s.ng) >= 0.0f) break;
            const float eta = 1.0f / m.absorption.w;
            float3 n_use = nf_s, t;
            bool ok = refract_dir(d, n_use, eta, &t);
            if (ok && dot(t, nf_g) >= 0.0f) {   /* bent to the wrong side: use the true face */
                n_use = nf_g;
                ok = refract_dir(d, n_use, eta, &t);
            }
            if (!ok) break;
            phi *= 1.0f - fresnel(cp.fresnel, -dot(d, n_use), eta);
            medium = s.material;
            org = offset_ray(s.p, -nf_g);
            d = t;
        }
    }
}

/* Texel t -> its face, (iu, iv) and the face's dims and first texel. */
inline int texel_face(const CausticParams* cp, uint t, uint* iu, uint* iv, uint* nu, uint* nv,
                      uint* off)
{
    for (int f = CAUSTIC_FACES - 1; f >= 0; f--) {
        *off = caustic_face_dims(cp, f, nu, nv);
        if (t >= *off) {
            *iu = (t - *off) % *nu;
            *iv = (t - *off) / *nu;
            return f;
        }
    }
    return -1;
}

__kernel void caustics_filter(__global const uint* restrict accum, __global float4* restrict map,
                              const CausticParams cp)
{
    const uint t = get_global_id(0);
    if (t >= cp.n_texels) return;
    uint iu, iv, nu, nv, off;
    const int f = texel_face(&cp, t, &iu, &iv, &nu, &nv, &off);
    const int r = (int)cp.filter_radius;
    float3 sum = (float3)(0.0f);
    float wsum = 0.0f;
    for (int dv = -r; dv <= r; dv++) {
        const int y = (int)iv + dv;
        if (y < 0 || y >= (int)nv) continue;
        for (int du = -r; du <= r; du++) {
            const int x = (int)iu + du;
            if (x < 0 || x >= (int)nu) continue;
            const float w = (float)(r + 1 - abs(du)) * (float)(r + 1 - abs(dv));
            const uint s = 3u * (off + (uint)y * nu + (uint)x);
            sum += w * (float3)((float)accum[s], (float)accum[s + 1u], (float)accum[s + 2u]);
            wsum += w;
        }
    }
    const float3 E = sum * (cp.texel.w / (wsum * caustic_texel_area(&cp, f)));
    const float3 prev = cp.blend > 0.0f ? map[t].xyz : (float3)(0.0f);
    map[t] = (float4)(cp.blend * prev + (1.0f - cp.blend) * E, 0.0f);
}
