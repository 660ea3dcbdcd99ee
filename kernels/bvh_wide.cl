/* The wide layout of a BLAS (raytrace.bvh_wide, structs in bvh.h), made from its binary tree on
   the device after every build, and refreshed after every refit. Launch order of a build:
     bvh_wide_collapse(level 0) -> bvh_wide_collapse(level 1) -> ... -> bvh_wide_refit
   A refit of the binary tree is followed by bvh_wide_refit alone (same topology).
   Collapse is top-down, one launch per level: each wide node takes its binary node's two children
   and keeps opening the inner child of largest surface area until it has WIDE_WIDTH children
   (or only leaves), the usual greedy collapse. It records where each child's box comes from
   (binary node, side), so the refit is a copy of boxes and triangles with no tree logic. */
#include "bvh.h"

/* the source code of a child slot: binary node * 2 + side (-1: no child) */
#define WIDE_SRC_NONE (-1)

inline float wide_half_area(float3 lo, float3 hi) {
    float3 e = hi - lo;
    return e.x * e.y + e.y * e.z + e.z * e.x;
}

/* The child record (box, ref, count) on `side` of binary node `b`. */
inline void wide_binary_child(__global const BvhNode* restrict nodes, int b, int side, int* ref,
                              int* cnt, float* area) {
    __global const BvhNode* n = nodes + b;
    float4 lo = side ? n->lo_r : n->lo_l, hi = side ? n->hi_r : n->hi_l;
    *ref = as_int(lo.w);
    *cnt = as_int(hi.w);
    *area = wide_half_area(lo.xyz, hi.xyz);
}

/* Wide nodes of one level, grid-stride. Level 0 (one work-item) resets the header and makes the
   root from the binary root. Each node allocates its inner children in the next level and its
   leaves' blocks with one atomic each. wide_bin[w]: the binary node wide node w was made from;
   wide_src[8w + k]: slot k's source code; block_src[b]: (first triangle, count <= 4). All indices
   are absolute (node_base, wide_base, block_base, tri_base are this BLAS's offsets). */
__kernel void bvh_wide_collapse(int level, __global const BvhNode* restrict nodes,
                                __global const BvhInfo* restrict infos, int info_index,
                                __global WideInfo* winfos, int wide_base, int block_base,
                                __global int* restrict wide_bin, __global int* restrict wide_src,
                                __global WideNode* restrict wnodes,
                                __global int2* restrict block_src) {
    __global WideInfo* wi = winfos + info_index;
    int start = 0, count;
    if (level == 0) {
        if (get_global_id(0) != 0) return;
        for (int l = 0; l < WIDE_MAX_LEVELS; ++l) wi->level_count[l] = 0;
        int root = infos[info_index].root;
        count = root >= 0 ? 1 : 0;
        wi->level_count[0] = count;
        wi->n_blocks = 0;
        wi->truncated = 0;
        if (count) wide_bin[wide_base] = root;
    } else {
        for (int l = 0; l < level; ++l) start += wi->level_count[l];
        count = wi->level_count[level];
    }
    int next = start + count; /* first node of the next level (local index) */
    for (int i = get_global_id(0); i < count; i += get_global_size(0)) {
        int w = start + i;
        int b = wide_bin[wide_base + w];
        int code[WIDE_WIDTH], ref[WIDE_WIDTH], cnt[WIDE_WIDTH];
        float area[WIDE_WIDTH];
        for (int side = 0; side < 2; ++side) {
            code[side] = 2 * b + side;
            wide_binary_child(nodes, b, side, &ref[side], &cnt[side], &area[side]);
        }
        int n = 2;
        while (n < WIDE_WIDTH) {
            int best = -1;
            float best_area = -1.0f;
            for (int k = 0; k < n; ++k) {
                if (cnt[k] == 0 && area[k] > best_area) {
                    best = k;
                    best_area = area[k];
                }
            }
            if (best < 0) break;
            int c = ref[best];
            code[best] = 2 * c;
            wide_binary_child(nodes, c, 0, &ref[best], &cnt[best], &area[best]);
            code[n] = 2 * c + 1;
            wide_binary_child(nodes, c, 1, &ref[n], &cnt[n], &area[n]);
            ++n;
        }
        int n_inner = 0, n_blocks = 0;
        for (int k = 0; k < n; ++k) {
            if (cnt[k] == 0) ++n_inner;
            else if (cnt[k] > 0) n_blocks += (cnt[k] + WIDE_BLOCK - 1) / WIDE_BLOCK;
        }
        bool deeper = level + 1 < WIDE_MAX_LEVELS;
        int child = 0, blk = 0;
        if (n_inner && deeper) child = next + atomic_add(&wi->level_count[level + 1], n_inner);
        if (n_inner && !deeper) wi->truncated = 1;
        if (n_blocks) blk = atomic_add(&wi->n_blocks, n_blocks);
        int out_ref[WIDE_WIDTH], out_cnt[WIDE_WIDTH];
        for (int k = 0; k < WIDE_WIDTH; ++k) {
            int r = 0, c = -1, src = WIDE_SRC_NONE;
            if (k < n && cnt[k] >= 0 && (cnt[k] > 0 || deeper)) {
                src = code[k];
                c = cnt[k];
                if (c == 0) {
                    r = wide_base + child;
                    wide_bin[r] = ref[k];
                    ++child;
                } else {
                    r = block_base + blk;
                    for (int j = 0; j < c; j += WIDE_BLOCK)
                        block_src[block_base + blk++] = (int2)(ref[k] + j, min(c - j, WIDE_BLOCK));
                }
            }
            out_ref[k] = r;
            out_cnt[k] = c;
            wide_src[WIDE_WIDTH * (wide_base + w) + k] = src;
        }
        wnodes[wide_base + w].ref = vload8(0, out_ref);
        wnodes[wide_base + w].cnt = vload8(0, out_cnt);
    }
}

/* Child slot `src`'s box (binary node src >> 1, side src & 1), or the empty box. */
inline void wide_slot_box(__global const BvhNode* restrict nodes, int src, float4* lo, float4* hi) {
    if (src == WIDE_SRC_NONE) {
        *lo = (float4)(INFINITY);
        *hi = (float4)(-INFINITY);
        return;
    }
    __global const BvhNode* n = nodes + (src >> 1);
    *lo = (src & 1) ? n->lo_r : n->lo_l;
    *hi = (src & 1) ? n->hi_r : n->hi_l;
}

#define WIDE_PLANE(v, c) \
    (float8)((v##0).c, (v##1).c, (v##2).c, (v##3).c, (v##4).c, (v##5).c, (v##6).c, (v##7).c)
#define WIDE_LANES(p, c) (float4)(t0.p.c, t1.p.c, t2.p.c, t3.p.c)

/* Boxes of every wide node and triangles of every block from the binary tree and the leaf-ordered
   triangles (both already built or refitted), grid-stride over the counts in the header. Written
   out lane by lane (no private arrays): a CPU compiler keeps it all in registers. */
__kernel void bvh_wide_refit(__global const BvhNode* restrict nodes,
                             __global const BvhTri* restrict tris,
                             __global WideInfo* restrict winfos, int info_index,
                             int wide_base, int block_base, __global const int* restrict wide_src,
                             __global WideNode* restrict wnodes,
                             __global const int2* restrict block_src,
                             __global TriBlock* restrict blocks) {
    __global WideInfo* wi = winfos + info_index;
    int n_nodes = 0, n_blocks = wi->n_blocks;
    for (int l = 0; l < WIDE_MAX_LEVELS; ++l) n_nodes += wi->level_count[l];
    if (get_global_id(0) == 0) wi->n_nodes = n_nodes; /* for the host's inspection */
    for (int i = get_global_id(0); i < n_nodes; i += get_global_size(0)) {
        int w = wide_base + i;
        int8 src = vload8(w, wide_src);
        float4 lo0, lo1, lo2, lo3, lo4, lo5, lo6, lo7, hi0, hi1, hi2, hi3, hi4, hi5, hi6, hi7;
        wide_slot_box(nodes, src.s0, &lo0, &hi0);
        wide_slot_box(nodes, src.s1, &lo1, &hi1);
        wide_slot_box(nodes, src.s2, &lo2, &hi2);
        wide_slot_box(nodes, src.s3, &lo3, &hi3);
        wide_slot_box(nodes, src.s4, &lo4, &hi4);
        wide_slot_box(nodes, src.s5, &lo5, &hi5);
        wide_slot_box(nodes, src.s6, &lo6, &hi6);
        wide_slot_box(nodes, src.s7, &lo7, &hi7);
        __global WideNode* out = wnodes + w;
        out->plane[0] = WIDE_PLANE(lo, x);
        out->plane[1] = WIDE_PLANE(lo, y);
        out->plane[2] = WIDE_PLANE(lo, z);
        out->plane[3] = WIDE_PLANE(hi, x);
        out->plane[4] = WIDE_PLANE(hi, y);
        out->plane[5] = WIDE_PLANE(hi, z);
    }
    for (int i = get_global_id(0); i < n_blocks; i += get_global_size(0)) {
        int2 src = block_src[block_base + i];
        BvhTri t0 = tris[src.x], t1 = tris[src.x + (src.y > 1 ? 1 : 0)],
               t2 = tris[src.x + (src.y > 2 ? 2 : 0)], t3 = tris[src.x + (src.y > 3 ? 3 : 0)];
        __global TriBlock* out = blocks + block_base + i;
        out->v[0][0] = WIDE_LANES(p0, x);
        out->v[0][1] = WIDE_LANES(p0, y);
        out->v[0][2] = WIDE_LANES(p0, z);
        out->v[1][0] = WIDE_LANES(p1, x);
        out->v[1][1] = WIDE_LANES(p1, y);
        out->v[1][2] = WIDE_LANES(p1, z);
        out->v[2][0] = WIDE_LANES(p2, x);
        out->v[2][1] = WIDE_LANES(p2, y);
        out->v[2][2] = WIDE_LANES(p2, z);
        out->prim = as_int4(WIDE_LANES(p0, w));
    }
}
