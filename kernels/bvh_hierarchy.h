/* Device functions of the LBVH builder shared by the triangle (bvh_build.cl) and instance
   (bvh_tlas.cl) builds: extended isotropic Morton codes and the one-pass bottom-up hierarchy of
   Apetrei (2014) with boxes written into the parent, the leaf collapse, and the root record. */
#ifndef LBWATER_BVH_HIERARCHY_H
#define LBWATER_BVH_HIERARCHY_H

#include "common.h"
#include "bvh.h"

#ifdef cl_khr_fp64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#endif

/* Bits per axis are capped: float32 centroids carry 24 bits, and the cap keeps (c - lo) * scale
   exact enough that neighbouring cells are ordered correctly. */
#define MORTON_MAX_AXIS_BITS 21

/* Which key bits each axis supplies, for one scale on all axes ("isotropic"): each key bit, from
   the top, halves the axis whose cells are currently the longest (ties go to x, then y, then z).
   A flat height field therefore spends its first bits on its two long axes and only a few on its
   thin one, and the cells stay near-cubic; a cube gets the classic x,y,z interleave. Returns the
   three bit masks (xyz) and the number of bits used (w). All in registers: every thread derives
   the same masks from the same bounds, which costs less than a launch to share them. */
inline uint4 morton_masks(float3 ext, int key_bits) {
    float cx = ext.x, cy = ext.y, cz = ext.z;
    int nx = 0, ny = 0, nz = 0;
    uint mx = 0, my = 0, mz = 0;
    int b = key_bits - 1;
    for (; b >= 0; --b) {
        float vx = nx < MORTON_MAX_AXIS_BITS ? cx : 0.0f;
        float vy = ny < MORTON_MAX_AXIS_BITS ? cy : 0.0f;
        float vz = nz < MORTON_MAX_AXIS_BITS ? cz : 0.0f;
        if (!(vx > 0.0f || vy > 0.0f || vz > 0.0f)) break; /* flat or exhausted: bits stay 0 */
        if (vx >= vy && vx >= vz) {
            mx |= 1u << b;
            cx *= 0.5f;
            nx += 1;
        } else if (vy >= vz) {
            my |= 1u << b;
            cy *= 0.5f;
            ny += 1;
        } else {
            mz |= 1u << b;
            cz *= 0.5f;
            nz += 1;
        }
    }
    return (uint4)(mx, my, mz, (uint)(key_bits - 1 - b));
}

/* Software bit deposit: the low bits of q go, in order, to the set bits of mask. */
inline uint deposit_bits(uint q, uint mask) {
    uint r = 0;
    for (uint m = mask; m != 0u; m &= m - 1u) {
        if (q & 1u) r |= m & (~m + 1u);
        q >>= 1;
    }
    return r;
}

/* Cell index along one axis: (c - lo) * (cells / ext), the scale correctly rounded (a double
   division where the device has doubles: OpenCL's float division may be off by ulps, which at 21
   bits per axis moves points across cell boundaries differently on different devices). */
inline uint morton_quantize(float c, float lo, float ext, uint mask) {
    float cells = (float)(1u << popcount(mask));
#ifdef cl_khr_fp64
    float scale = (float)((double)cells / (double)ext);
#else
    float scale = cells / ext;
#endif
    float f = (c - lo) * scale;
    f = isnan(f) ? 0.0f : clamp(f, 0.0f, cells - 1.0f);
    return (uint)f;
}

/* Morton key of centroid c in the frame (lo, ext) with the masks of morton_masks. NaN -> 0. */
inline uint morton_isotropic(float3 c, float3 lo, float3 ext, uint4 masks) {
    uint key = 0;
    if (masks.x) key |= deposit_bits(morton_quantize(c.x, lo.x, ext.x, masks.x), masks.x);
    if (masks.y) key |= deposit_bits(morton_quantize(c.y, lo.y, ext.y, masks.y), masks.y);
    if (masks.z) key |= deposit_bits(morton_quantize(c.z, lo.z, ext.z, masks.z), masks.z);
    return key;
}

/* Morton bounds of a BVH from its header (set by the bounds pass). */
inline void morton_frame(__global const BvhInfo* info, float3* lo, float3* ext) {
    __global const int* cmin = (__global const int*)&info->cmin;
    __global const int* cmax = (__global const int*)&info->cmax;
    float3 a = (float3)(ordered_to_float(cmin[0]), ordered_to_float(cmin[1]),
                        ordered_to_float(cmin[2]));
    float3 b = (float3)(ordered_to_float(cmax[0]), ordered_to_float(cmax[1]),
                        ordered_to_float(cmax[2]));
    *lo = a;
    *ext = fmax(b - a, (float3)(0.0f));
}

/* Work-group reduction of centroid bounds [a, b] (pass a = +inf, b = -inf for nothing), then 6
   atomics per group into the header. Every thread of the group must call it. */
#define BOUNDS_WG 256
inline void reduce_centroid_bounds(float3 a, float3 b, __local float* lmin, __local float* lmax,
                                   __global BvhInfo* info) {
    int lid = get_local_id(0);
    lmin[3 * lid] = a.x; lmin[3 * lid + 1] = a.y; lmin[3 * lid + 2] = a.z;
    lmax[3 * lid] = b.x; lmax[3 * lid + 1] = b.y; lmax[3 * lid + 2] = b.z;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = BOUNDS_WG / 2; s > 0; s >>= 1) {
        if (lid < s) {
            for (int k = 0; k < 3; ++k) {
                lmin[3 * lid + k] = fmin(lmin[3 * lid + k], lmin[3 * (lid + s) + k]);
                lmax[3 * lid + k] = fmax(lmax[3 * lid + k], lmax[3 * (lid + s) + k]);
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid < 3) {
        __global int* cmin = (__global int*)&info->cmin;
        __global int* cmax = (__global int*)&info->cmax;
        if (lmin[lid] <= lmax[lid]) {
            atomic_min(cmin + lid, float_to_ordered(lmin[lid]));
            atomic_max(cmax + lid, float_to_ordered(lmax[lid]));
        }
    }
}

/* Split "distance" between sorted neighbours j and j+1: the xor of their keys, extended below by
   the xor of their positions, so equal keys still split in a balanced way (the key with its index
   appended is unique) and no ladder of equal keys forms. At most 64 significant bits, so the tree
   is a radix tree at most 64 levels deep. */
inline ulong bvh_delta(__global const uint* restrict keys, int j) {
    return ((ulong)(keys[j] ^ keys[j + 1]) << 32) | (ulong)(uint)(j ^ (j + 1));
}

/* Bottom-up walk of leaf i (Apetrei 2014). Internal node k (0 <= k < n-1) splits between sorted
   positions k and k+1. A node [l, r] becomes the left child of node r if delta(r) < delta(l-1), else
   the right child of node l-1. It writes its box and reference into its side of the parent, and
   the second of the two children to arrive (atomic exchange on flags[parent]) goes on with the
   union. Subtrees of at most leaf_size primitives are referenced as one leaf (the collapse); the
   inner nodes below them are computed but never referenced. The second arrival restores
   flags[parent] = -1, so the flags are ready for the next build or refit without a fill. */
inline void bvh_walk(int i, int n, int leaf_size, int node_base, int prim_base,
                     __global const uint* restrict keys, __global BvhNode* nodes,
                     __global int* flags, __global BvhInfo* info, float3 lo, float3 hi) {
    int l = i, r = i, cur = -1;
    for (;;) { /* the range grows every round: at most n rounds, at most 64 levels in practice */
        bool is_left = l == 0 || (r != n - 1 && bvh_delta(keys, r) < bvh_delta(keys, l - 1));
        int parent = is_left ? r : l - 1;
        int size = r - l + 1;
        int ref = size <= leaf_size ? prim_base + l : node_base + cur;
        int count = size <= leaf_size ? size : 0;
        __global BvhNode* p = nodes + node_base + parent;
        if (is_left) {
            p->lo_l = (float4)(lo, as_float(ref));
            p->hi_l = (float4)(hi, as_float(count));
        } else {
            p->lo_r = (float4)(lo, as_float(ref));
            p->hi_r = (float4)(hi, as_float(count));
        }
        DEVICE_FENCE(); /* our box is visible to the sibling's work-group before the flag */
        int other = atomic_xchg(flags + parent, is_left ? l : r);
        if (other < 0) return; /* first to arrive: the sibling finishes the parent */
        DEVICE_FENCE(); /* and the sibling's box is read after the flag */
        flags[parent] = -1;
        volatile __global float4* pv = (volatile __global float4*)p;
        float4 slo = is_left ? pv[2] : pv[0];
        float4 shi = is_left ? pv[3] : pv[1];
        lo = fmin(lo, slo.xyz);
        hi = fmax(hi, shi.xyz);
        if (is_left) r = other;
        else l = other;
        cur = parent;
        if (l == 0 && r == n - 1) {
            /* every leaf's gather came before its walk, and all walks reached the root */
            info->n_bad = atomic_xchg(&info->n_bad_pending, 0);
            info->root = node_base + cur;
            info->lo = (float4)(lo, 0.0f);
            info->hi = (float4)(hi, 0.0f);
            return;
        }
    }
}

/* A BVH of n <= leaf_size primitives: one node whose left child is the whole leaf. */
inline void bvh_small_root(int n, int node_base, int prim_base, __global BvhNode* nodes,
                           __global BvhInfo* info, float3 lo, float3 hi) {
    __global BvhNode* p = nodes + node_base;
    p->lo_l = (float4)(lo, as_float(prim_base));
    p->hi_l = (float4)(hi, as_float(n));
    p->lo_r = (float4)(0.0f, 0.0f, 0.0f, as_float(0));
    p->hi_r = (float4)(0.0f, 0.0f, 0.0f, as_float(BVH_CHILD_EMPTY));
    info->n_bad = atomic_xchg(&info->n_bad_pending, 0);
    info->root = node_base;
    info->lo = (float4)(lo, 0.0f);
    info->hi = (float4)(hi, 0.0f);
}

/* Start a build: root unknown, counts zero, empty centroid bounds (one work-item). */
inline void bvh_info_reset(__global BvhInfo* info, int n_prims) {
    info->n_prims = n_prims;
    info->n_bad = 0;
    info->n_bad_pending = 0;
    info->depth_guard = 0;
    info->root = -1;
    info->cmin = (int4)(float_to_ordered(INFINITY));
    info->cmax = (int4)(float_to_ordered(-INFINITY));
}

/* Morton key of box i's centroid (boxes: lo, hi pairs) in the frame of info's centroid bounds. */
inline uint bvh_box_key(__global const float4* restrict boxes, int i,
                        __global const BvhInfo* info, int key_bits) {
    float3 lo, ext;
    morton_frame(info, &lo, &ext);
    const uint4 masks = morton_masks(ext, key_bits);
    return morton_isotropic(0.5f * (boxes[2 * i].xyz + boxes[2 * i + 1].xyz), lo, ext, masks);
}

/* Work-item i (< n) of the hierarchy over boxes in sorted order (order[k] = box of sorted
   position k): a leaf walk up, or with n <= leaf_size item 0 writes the one root. */
inline void bvh_hierarchy_box_item(int i, int n, int leaf_size, __global const uint* restrict keys,
                                   __global const uint* restrict order,
                                   __global const float4* restrict boxes,
                                   __global BvhNode* nodes, __global int* flags,
                                   __global BvhInfo* info) {
    if (n <= leaf_size) {
        if (i != 0) return;
        float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
        for (int k = 0; k < n; ++k) {
            lo = fmin(lo, boxes[2 * order[k]].xyz);
            hi = fmax(hi, boxes[2 * order[k] + 1].xyz);
        }
        bvh_small_root(n, 0, 0, nodes, info, lo, hi);
        return;
    }
    const uint b = order[i];
    bvh_walk(i, n, leaf_size, 0, 0, keys, nodes, flags, info, boxes[2 * b].xyz,
             boxes[2 * b + 1].xyz);
}

#endif
