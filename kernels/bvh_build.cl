/* LBVH over a triangle mesh on the device (raytrace.bvh.Blas). Launch order of a build:
     bvh_reset_info -> bvh_tri_bounds -> bvh_tri_morton -> sort (sort_*.cl) -> bvh_tri_gather
     -> bvh_hierarchy_tris
   A refit (same topology, moved vertices) is bvh_reset_info(keep bounds) -> bvh_tri_gather ->
   bvh_hierarchy_tris on the stored sorted keys and order.
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

/* Start a build (keep_bounds = 0) or a refit (1): root unknown, bad-primitive count zero. */
__kernel void bvh_reset_info(__global BvhInfo* infos, int info_index, int n_prims,
                             int keep_bounds) {
    if (get_global_id(0) != 0) return;
    __global BvhInfo* info = infos + info_index;
    info->n_prims = n_prims;
    info->n_bad = 0;
    info->depth_guard = 0;
    if (!keep_bounds) {
        info->root = -1;
        info->cmin = (int4)(float_to_ordered(INFINITY));
        info->cmax = (int4)(float_to_ordered(-INFINITY));
    }
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

/* Triangles in sorted (leaf) order with their vertices gathered: out[tri_base + i]. Counts
   triangles with a non-finite vertex in the header. */
__kernel void bvh_tri_gather(__global const float4* restrict verts,
                             __global const uint* restrict tris, uint n_tris, uint nv,
                             __global const uint* restrict order, __global BvhTri* restrict out,
                             int tri_base, __global BvhInfo* infos, int info_index) {
    uint i = get_global_id(0);
    if (i >= n_tris) return;
    uint t = order[i];
    float4 a, b, c;
    load_triangle(verts, tris, nv, t, &a, &b, &c);
    BvhTri bt;
    bt.p0 = (float4)(a.xyz, as_float(t));
    bt.p1 = (float4)(b.xyz, 0.0f);
    bt.p2 = (float4)(c.xyz, 0.0f);
    out[tri_base + i] = bt;
    if (!(finite3(a.xyz) && finite3(b.xyz) && finite3(c.xyz)))
        atomic_inc(&infos[info_index].n_bad);
}

inline void tri_box(__global const BvhTri* restrict prims, int k, float3* lo, float3* hi) {
    float3 a = prims[k].p0.xyz, b = prims[k].p1.xyz, c = prims[k].p2.xyz;
    *lo = fmin(fmin(a, b), c);
    *hi = fmax(fmax(a, b), c);
}

/* Hierarchy and boxes in one bottom-up pass over the gathered triangles (see bvh_walk). */
__kernel void bvh_hierarchy_tris(int n, int leaf_size, int node_base, int prim_base,
                                 __global const uint* restrict keys,
                                 __global const BvhTri* restrict prims, __global BvhNode* nodes,
                                 __global int* flags, __global BvhInfo* infos, int info_index) {
    int i = get_global_id(0);
    if (i >= n) return;
    float3 lo, hi;
    if (n <= leaf_size) {
        if (i != 0) return;
        tri_box(prims, prim_base, &lo, &hi);
        for (int k = 1; k < n; ++k) {
            float3 a, b;
            tri_box(prims, prim_base + k, &a, &b);
            lo = fmin(lo, a);
            hi = fmax(hi, b);
        }
        bvh_small_root(n, node_base, prim_base, nodes, infos + info_index, lo, hi);
        return;
    }
    tri_box(prims, prim_base + i, &lo, &hi);
    bvh_walk(i, n, leaf_size, node_base, prim_base, keys, nodes, flags, infos + info_index, lo,
             hi);
}
