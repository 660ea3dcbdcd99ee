/* Renderer: what a hit looks like (position, normals, uv, material, colour) and the Whitted
 * rules shared by the shade, shadow and secondary stages, so each stage derives the same
 * answer from (ray, hit) without storing a surface record per ray. */
#ifndef LBWATER_RENDER_SURFACE_H
#define LBWATER_RENDER_SURFACE_H

#include "render_optics.h"
#include "scene.h"
#include "transform.h"

/* The renderer's shading data (raytrace.render_scene.RenderScene.shade_bindings()): instances,
 * their world_from_object rows (the scene's transform buffer) and normal transforms (written
 * by tlas_prep), meshes, positions (float4, input order), normals (float4), uvs (float2),
 * triangles (uint x3, input order), per-triangle material ids, materials, textures, texels,
 * and the dynamic meshes' positions and normals (MESH_DYNAMIC: the buffers their writer, e.g.
 * the water surface kernel, fills and the BVH reads; vert_offset indexes these). */
#define RENDER_GEOM_PARAMS                                                                     \
    __global const InstanceInfo* restrict g_inst, __global const Transform* restrict g_xform, \
    __global const Transform* restrict g_nxform, __global const MeshInfo* restrict g_mesh,    \
    __global const float4* restrict g_pos, __global const float4* restrict g_nrm,             \
    __global const float2* restrict g_uv, __global const uint* restrict g_tri,                \
    __global const ushort* restrict g_tri_mat, __global const Material* restrict g_mat,       \
    __global const TexInfo* restrict g_tex, __global const float4* restrict g_texels,         \
    __global const float4* restrict g_dpos, __global const float4* restrict g_dnrm

#define RENDER_GEOM_ARGS g_inst, g_xform, g_nxform, g_mesh, g_pos, g_nrm, g_uv, g_tri, g_tri_mat, \
    g_mat, g_tex, g_texels, g_dpos, g_dnrm

typedef struct {
    float3 p;       /* world position from the barycentrics */
    float3 ng;      /* unit geometric normal (winding side) */
    float3 ns;      /* unit shading normal, on the side of ng */
    float3 kd;      /* diffuse colour, texture applied */
    int material;
} Surface;


inline Surface surface_at(RENDER_GEOM_PARAMS, int inst, int prim, float u, float v)
{
    Surface s;
    const InstanceInfo in = g_inst[inst];
    const MeshInfo m = g_mesh[in.mesh];
    const uint t = m.tri_offset + (uint)prim;
    const uint i0 = m.vert_offset + g_tri[3 * t];
    const uint i1 = m.vert_offset + g_tri[3 * t + 1];
    const uint i2 = m.vert_offset + g_tri[3 * t + 2];
    const bool dyn = (m.flags & MESH_DYNAMIC) != 0u;
    __global const float4* pos = dyn ? g_dpos : g_pos;
    __global const float4* nrm = dyn ? g_dnrm : g_nrm;
    const float3 p0 = pos[i0].xyz, p1 = pos[i1].xyz, p2 = pos[i2].xyz;
    const float w = 1.0f - u - v;
    const Transform nx = g_nxform[inst];
    s.p = xform_point(g_xform[inst], w * p0 + u * p1 + v * p2);
    s.ng = normalize(xform_vector(nx, cross(p1 - p0, p2 - p0)));
    s.ns = s.ng;
    if (m.flags & MESH_HAS_NORMALS) {
        const float3 n = w * nrm[i0].xyz + u * nrm[i1].xyz + v * nrm[i2].xyz;
        const float len2 = dot(n, n);
        if (len2 > 1e-20f) {
            const float3 ns = normalize(xform_vector(nx, n));
            s.ns = dot(ns, s.ng) >= 0.0f ? ns : -ns;
        }
    }
    s.material = in.material >= 0 ? in.material
               : ((m.flags & MESH_TRI_MATERIALS) ? (int)g_tri_mat[t] : m.material);
    const Material mat = g_mat[s.material];
    s.kd = mat.diffuse.xyz;
    if (mat.texture >= 0 && (m.flags & MESH_HAS_UVS)) {
        const float2 uv = w * g_uv[i0] + u * g_uv[i1] + v * g_uv[i2];
        const float2 scaled = uv * (float2)(mat.uv_scale_u, mat.uv_scale_v);
        s.kd *= tex_bilinear(g_texels, g_tex[mat.texture], scaled, true).xyz;
    }
    return s;
}

inline bool is_dielectric(const Material* m) { return m->absorption.w > 0.0f; }

inline float max3(float3 a) { return fmax(a.x, fmax(a.y, a.z)); }

inline float3 ray_weight(const Ray* r) { return (float3)(r->wr, r->wg, r->wb); }
inline float3 ray_dir(const Ray* r) { return (float3)(r->dx, r->dy, r->dz); }
inline float3 ray_org(const Ray* r) { return (float3)(r->ox, r->oy, r->oz); }

/* The ray's weight at its hit, after Beer-Lambert absorption along a path inside a medium. */
inline float3 attenuated_weight(const Ray* r, float t, __global const Material* g_mat)
{
    float3 w = ray_weight(r);
    if (r->medium >= 0) w *= beer(g_mat[r->medium].absorption.xyz, t);
    return w;
}

/* Normals facing the side the ray came from; the shading normal falls back to the geometric one
 * when it faces away from the ray (interpolated normals on a silhouette). */
inline void facing_normals(const Surface* s, float3 d, float3* nf_g, float3* nf_s)
{
    const bool front = dot(d, s->ng) < 0.0f;
    *nf_g = front ? s->ng : -s->ng;
    *nf_s = front ? s->ns : -s->ns;
    if (dot(*nf_s, d) >= 0.0f) *nf_s = *nf_g;
}

/* Fraction of the (attenuated) weight lit directly: 1 for dielectrics, 1 - reflectivity else. */
inline float direct_fraction(const Material* m)
{
    return is_dielectric(m) ? 1.0f : 1.0f - m->reflectivity;
}

/* Whitted children of a hit: reflection (mirror or Fresnel) and refraction; at most two.
 * Returns the number written to out[0..]; children below min_weight or past max_depth are cut. */
inline int spawn_children(const Ray* r, const Surface* s, float3 w, uint depth,
                          __constant const RenderParams* prm, __global const Material* g_mat,
                          Ray* out)
{
    if (depth >= prm->max_depth) return 0;
    const Material m = g_mat[s->material];
    const float3 d = ray_dir(r);
    float3 nf_g, nf_s;
    facing_normals(s, d, &nf_g, &nf_s);
    float3 w_refl = (float3)(0.0f), w_refr = (float3)(0.0f);
    float3 t_dir = (float3)(0.0f);
    int refr_medium = RENDER_NO_MEDIUM;
    if (is_dielectric(&m)) {
        const bool entering = dot(d, s->ng) < 0.0f;
        const float eta = entering ? 1.0f / m.absorption.w : m.absorption.w;
        float3 n_use = nf_s;
        bool ok = refract_dir(d, n_use, eta, &t_dir);
        if (ok && dot(t_dir, nf_g) >= 0.0f) {   /* bent to the wrong side: use the true face */
            n_use = nf_g;
            ok = refract_dir(d, n_use, eta, &t_dir);
        }
        const float F = ok ? fresnel(prm->fresnel, -dot(d, n_use), eta) : 1.0f;
        w_refl = w * F;
        w_refr = ok ? w * (1.0f - F) : (float3)(0.0f);
        refr_medium = entering ? s->material : RENDER_NO_MEDIUM;
    } else {
        w_refl = w * m.reflectivity;
    }
    int n = 0;
    if (max3(w_refl) > 0.0f && max3(w_refl) >= prm->min_weight) {
        float3 rd = reflect_dir(d, nf_s);
        if (dot(rd, nf_g) <= 0.0f) rd = reflect_dir(d, nf_g);
        const float3 o = offset_ray(s->p, nf_g);
        Ray c = {o.x, o.y, o.z, r->pixel, rd.x, rd.y, rd.z, r->medium,
                 w_refl.x, w_refl.y, w_refl.z, r->sample};
        out[n++] = c;
    }
    if (max3(w_refr) > 0.0f && max3(w_refr) >= prm->min_weight) {
        const float3 o = offset_ray(s->p, -nf_g);
        Ray c = {o.x, o.y, o.z, r->pixel, t_dir.x, t_dir.y, t_dir.z, refr_medium,
                 w_refr.x, w_refr.y, w_refr.z, r->sample};
        out[n++] = c;
    }
    return n;
}

/* Shading of ray i of the wavefront with its closest hit h (no shadow rays: render_shadow):
 * ambient, sky on a miss, Beer-Lambert, the child count for the compaction, the primary AOV.
 * The hit's surface in *hit_surface (render_shadow_list.cl shades and lists at once). */
inline void shade_hit_at(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                         __constant const Camera* cam, const Ray r, const Hit h, uint i,
                         const uint depth, __global float4* restrict radiance,
                         __global uint* restrict child_counts, __global Aov* restrict aov,
                         const uint write_aov, Surface* hit_surface)
{
    float3 L;
    uint n_children = 0;
    Aov a = {(float4)(0.0f), INFINITY, -1, -1, -1};
    if (h.prim < 0) {
        const float3 w = attenuated_weight(&r, INFINITY, g_mat);
        const float3 d = ray_dir(&r);
        L = max3(w) > 0.0f ? w * (prm->sky == SKY_CUBEMAP ? sky_cubemap(d, prm, g_tex, g_texels)
                                                          : sky_procedural(d, prm))
                           : (float3)(0.0f);
    } else {
        const Surface s = surface_at(RENDER_GEOM_ARGS, h.inst, h.prim, h.u, h.v);
        *hit_surface = s;
        const Material m = g_mat[s.material];
        const float3 w = attenuated_weight(&r, h.t, g_mat);
        L = w * direct_fraction(&m) * prm->ambient.xyz * s.kd;
        Ray kids[2];
        n_children = (uint)spawn_children(&r, &s, w, depth, prm, g_mat, kids);
        float3 nf_g, nf_s;
        facing_normals(&s, ray_dir(&r), &nf_g, &nf_s);
        a.normal = (float4)(nf_s, 0.0f);
        a.depth = h.t;
        a.prim = h.prim;
        a.inst = h.inst;
        a.material = s.material;
    }
    radiance[i] = (float4)(L, 0.0f);
    child_counts[i] = n_children;
    if (write_aov && depth == 0 && r.sample == 0) {
        uint x, y;
        if (pixel_of(cam, r.pixel, &x, &y)) aov[y * cam->width + x] = a;
    }
}

inline void shade_hit(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                      __constant const Camera* cam, const Ray r, const Hit h, uint i,
                      const uint depth, __global float4* restrict radiance,
                      __global uint* restrict child_counts, __global Aov* restrict aov,
                      const uint write_aov)
{
    Surface s;
    shade_hit_at(RENDER_GEOM_ARGS, prm, cam, r, h, i, depth, radiance, child_counts, aov,
                 write_aov, &s);
}

/* Writes ray i's children into the next wavefront at its compacted offset: the exclusive offset
 * within its scan block (child_offsets[i]) plus the block's offset (block_sums, render_scan). */
inline void scatter_children(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                             __global const Ray* rays, __global const Hit* hits, uint i,
                             uint depth, __global const uint* child_offsets,
                             __global const uint* block_sums, __global Ray* out)
{
    const Hit h = hits[i];
    if (h.prim < 0) return;
    const Ray r = rays[i];
    const Surface s = surface_at(RENDER_GEOM_ARGS, h.inst, h.prim, h.u, h.v);
    const float3 w = attenuated_weight(&r, h.t, g_mat);
    Ray kids[2];
    const int n = spawn_children(&r, &s, w, depth, prm, g_mat, kids);
    const uint dst = child_offsets[i] + block_sums[i / RENDER_SCAN_BLOCK];
    for (int k = 0; k < n; k++)
        if (dst + (uint)k < prm->capacity) out[dst + (uint)k] = kids[k];
}

#endif
