/* LBVH over a triangle mesh on the device (raytrace.bvh.Blas). Launch order of a build:
     bvh_reset_info -> bvh_tri_bounds -> bvh_tri_morton -> sort (sort_*.cl) ->
     bvh_gather_hierarchy
   A refit (same topology, moved vertices) is bvh_gather_hierarchy alone, on the stored sorted keys
   and order (the header's counts are handed over at the root, see BvhInfo.n_bad_pending).
   Inputs: vertices as float4 (w ignored), triangles as 3 x uint32 (packed, 12 bytes). */
#include "bvh_hierarchy.h"

inline void load_triangle(__global const float4* restrict verts, __global const uint* restrict tris,
                          uint nv, uint t, float4* a, float4* b, float4* c) {
    /* Indices are clamped so a bad index buffer cannot read outside the vertex buffer. */
    uint i0 = min(tris[3 * t], nv - 1), i1 = min(tris[3 * t + 1], nv - 1),
         i2 = min(tris[3 * t + 2], nv - 1);
    *a = verts[i0];
    *b = verts[i1];
    *c = verts[i2];
}

inline bool finite3(float3 v) {
    return isfinite(v.x) && isfinite(v.y) && isfinite(v.z);
}

/* Start a build: root unknown, counts zero, empty centroid bounds. */
__kernel void bvh_reset_info(__global BvhInfo* infos, int info_index, int n_prims) {
    if (get_global_id(0) != 0) return;
    bvh_info_reset(infos + info_index, n_prims);
}

/* Centroid bounds of all triangles (grid-stride loop, then one reduction per work-group). */
__kernel __attribute__((reqd_work_group_size(BOUNDS_WG, 1, 1)))
void bvh_tri_bounds(__global const float4* restrict verts, __global const uint* restrict tris,
                    uint n_tris, uint nv, __global BvhInfo* infos, int info_index) {
    __local float lmin[3 * BOUNDS_WG], lmax[3 * BOUNDS_WG];
    float3 cmin = (float3)(INFINITY), cmax = (float3)(-INFINITY);
    for (uint t = get_global_id(0); t < n_tris; t += get_global_size(0)) {
        float4 a, b, c;
        load_triangle(verts, tris, nv, t, &a, &b, &c);
        float3 m = (a.xyz + b.xyz + c.xyz) * (1.0f / 3.0f);
        if (finite3(m)) {
            cmin = fmin(cmin, m);
            cmax = fmax(cmax, m);
        }
    }
    reduce_centroid_bounds(cmin, cmax, lmin, lmax, infos + info_index);
}

/* Morton key of every triangle's centroid; vals = triangle index (the sort's payload). */
__kernel void bvh_tri_morton(__global const float4* restrict verts,
                             __global const uint* restrict tris, uint n_tris, uint nv,
                             __global const BvhInfo* restrict infos, int info_index, int key_bits,
                             __global uint* restrict keys, __global uint* restrict vals) {
    uint t = get_global_id(0);
    if (t >= n_tris) return;
    float3 lo, ext;
    morton_frame(infos + info_index, &lo, &ext);
    uint4 masks = morton_masks(ext, key_bits);
    float4 a, b, c;
    load_triangle(verts, tris, nv, t, &a, &b, &c);
    float3 m = (a.xyz + b.xyz + c.xyz) * (1.0f / 3.0f);
    keys[t] = morton_isotropic(m, lo, ext, masks);
    vals[t] = t;
}

/* Triangle i of the sorted order gathered into out[tri_base + i] (leaf order, its original index
   in p0.w); returns its box. Counts triangles with a non-finite vertex in the header. */
inline void gather_triangle(__global const float4* restrict verts,
                            __global const uint* restrict tris, uint nv,
                            __global const uint* restrict order, __global BvhTri* restrict out,
                            int tri_base, __global BvhInfo* info, int i, float3* lo, float3* hi) {
    uint t = order[i];
    float4 a, b, c;
    load_triangle(verts, tris, nv, t, &a, &b, &c);
    BvhTri bt;
    bt.p0 = (float4)(a.xyz, as_float(t));
    bt.p1 = (float4)(b.xyz, 0.0f);
    bt.p2 = (float4)(c.xyz, 0.0f);
    out[tri_base + i] = bt;
    if (!(finite3(a.xyz) && finite3(b.xyz) && finite3(c.xyz))) atomic_inc(&info->n_bad_pending);
    *lo = fmin(fmin(a.xyz, b.xyz), c.xyz);
    *hi = fmax(fmax(a.xyz, b.xyz), c.xyz);
}

/* Gather and hierarchy in one launch: each work-item gathers its sorted triangle, then walks up
   the tree with its box (see bvh_walk), so a refit is this kernel after the header reset. */
__kernel void bvh_gather_hierarchy(__global const float4* restrict verts,
                                   __global const uint* restrict tris, int n, uint nv,
                                   __global const uint* restrict order,
                                   __global BvhTri* restrict prims, int leaf_size, int node_base,
                                   int prim_base, __global const uint* restrict keys,
                                   __global BvhNode* nodes, __global int* flags,
                                   __global BvhInfo* infos, int info_index) {
    int i = get_global_id(0);
    if (i >= n) return;
    __global BvhInfo* info = infos + info_index;
    float3 lo, hi;
    if (n <= leaf_size) { /* one leaf: work-item 0 gathers all and writes the root */
        if (i != 0) return;
        gather_triangle(verts, tris, nv, order, prims, prim_base, info, 0, &lo, &hi);
        for (int k = 1; k < n; ++k) {
            float3 a, b;
            gather_triangle(verts, tris, nv, order, prims, prim_base, info, k, &a, &b);
            lo = fmin(lo, a);
            hi = fmax(hi, b);
        }
        bvh_small_root(n, node_base, prim_base, nodes, info, lo, hi);
        return;
    }
    gather_triangle(verts, tris, nv, order, prims, prim_base, info, i, &lo, &hi);
    bvh_walk(i, n, leaf_size, node_base, prim_base, keys, nodes, flags, info, lo, hi);
}
