/* Ray traversal of the two-level scene, usable from any kernel:
       __kernel void k(SCENE_PARAMS, ...) { Hit h = scene_closest_hit(SCENE_ARGS, o, d, 0, INFINITY); }
   World-space rays; the direction need not be unit length and t is in units of it.
   Triangle test: watertight (Woop, Benthin & Wald 2013), two-sided, with a float64 re-evaluation
   of edge functions that come out exactly zero. Box test: slabs with the far distance enlarged by
   2 gamma(3) (pbrt), so rounding never culls a box the triangle test would hit, and NaN-safe for
   rays parallel to an axis that run in a box's face (trace_box).
   Traversal: both child boxes per node, leaves tested when met, near child first, one stack per
   level of TRACE_STACK entries. The builder's trees are at most 64 levels deep (bvh_delta), so the
   stack cannot overflow; the guard still counts an overflow in trace_stats instead of writing
   past the stack, so it could never be silent.
   The BLAS layout is TRACE_WIDE's (scene.h): binary nodes as above (GPUs), or 8-wide nodes and
   4-triangle blocks (CPUs): eight slab tests in float8, four triangle tests in float4 with the
   same arithmetic per lane, children pushed with their entry distance and popped nearest first;
   its stack holds (WIDE_WIDTH - 1) entries per level of the at most 64, so it cannot overflow
   either, and the same guard counts it. The TLAS is binary in both. */
#ifndef LBWATER_TRAVERSE_H
#define LBWATER_TRAVERSE_H

#include "scene.h"

/* Fused multiply-adds would make a shared edge's function differ between its two triangles. */
#pragma OPENCL FP_CONTRACT OFF

#ifdef cl_khr_fp64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#define TRAVERSE_FP64 1
#endif

/* TRACE_CPU selects the scalar-CPU flavour of two details (the hits are the same): slab
   min/max as compare-selects, which a CPU compiler turns into single min/max instructions where
   PoCL's fmin/fmax are out-of-line calls with NaN handling (the slab distances are never NaN:
   finite boxes and origins, reciprocals finite and non-zero), and a prefetch of both inner
   children as soon as their parent is read, so their cache misses overlap the box tests (one
   ray per work-item runs as scalar code on a CPU, so nothing else hides that latency). It
   defaults to 1 when the OpenCL C compiler targets a CPU instruction set (PoCL compiles for the
   host: x86-64, AArch64) and 0 otherwise (NVIDIA: nvptx, whose code is unchanged);
   -DTRACE_CPU=0 or 1 overrides it (the benchmark compares both). */
#ifndef TRACE_CPU
#if defined(__x86_64__) || defined(__i386__) || defined(__aarch64__)
#define TRACE_CPU 1
#else
#define TRACE_CPU 0
#endif
#endif
#if TRACE_CPU
#define TRACE_MIN(a, b) ((a) < (b) ? (a) : (b))
#define TRACE_MAX(a, b) ((a) > (b) ? (a) : (b))
/* PoCL 3.0's OpenCL prefetch() emits nothing; clang's builtin emits a prefetch instruction on a
   CPU target (NVIDIA's compiler is clang-based too but rejects it for __global pointers). */
#if defined(__clang__) && (defined(__x86_64__) || defined(__i386__) || defined(__aarch64__))
#define TRACE_PREFETCH(p) __builtin_prefetch((const __global void*)(p))
#else
#define TRACE_PREFETCH(p) prefetch((const __global char*)(p), 64)
#endif
#else
#define TRACE_MIN(a, b) fmin(a, b)
#define TRACE_MAX(a, b) fmax(a, b)
#endif

/* PoCL builds with -Dinline= and leaves helper functions out of line; on a CPU every call in
   this loop costs as much as a box test, so force them inline there (GPU code is unchanged). */
#if TRACE_CPU
#define TRACE_INLINE inline __attribute__((always_inline))
#else
#define TRACE_INLINE inline
#endif

/* TRACE_COUNT=1 (a debug build: raytrace.scene.Scene.trace_counts, bench/trace_visits.py)
   counts each traversal's work in private counters and adds them to trace_stats by ray kind
   (scene.h: TRACE_STAT_COUNT) with one atomic per field when it ends; 0 (the default) compiles
   the counting away. */
#ifndef TRACE_COUNT
#define TRACE_COUNT 0
#endif
#if TRACE_COUNT
#define TRACE_TICK(w, field, n) ((w)[field] += (uint)(n))
#else
#define TRACE_TICK(w, field, n) ((void)0)
#endif

#define TRACE_STACK 64
/* 1 + 2 gamma(3), gamma(n) = n eps / (1 - n eps), eps = 2^-24 */
#define TRACE_BOX_GROW 1.0000003576278687f

/* A ray prepared for one level of traversal (world for the TLAS, object space for a BLAS). */
typedef struct {
    float3 org;
    float3 idir;
    int kx, ky, kz;
    float sx, sy, sz;
} TraceRay;

TRACE_INLINE float trace_axis(float3 v, int k) {
    return k == 0 ? v.x : (k == 1 ? v.y : v.z);
}

TRACE_INLINE TraceRay trace_ray_setup(float3 org, float3 dir) {
    TraceRay r;
    r.org = org;
    r.idir = 1.0f / dir; /* a zero component gives +-inf: see trace_box */
    float3 ad = fabs(dir);
    int kz = (ad.x >= ad.y && ad.x >= ad.z) ? 0 : (ad.y >= ad.z ? 1 : 2);
    int kx = kz == 2 ? 0 : kz + 1;
    int ky = kx == 2 ? 0 : kx + 1;
    float dz = trace_axis(dir, kz);
    if (dz < 0.0f) {
        int s = kx;
        kx = ky;
        ky = s;
    }
    r.kx = kx;
    r.ky = ky;
    r.kz = kz;
    r.sx = trace_axis(dir, kx) / dz;
    r.sy = trace_axis(dir, ky) / dz;
    r.sz = 1.0f / dz;
    return r;
}

/* Entry distance of the ray into [lo, hi] within [tmin, tmax], or INFINITY when it misses.
   Near and far planes are picked by the direction's signs. A zero direction component has an
   infinite reciprocal: a plane on either side gives -inf/+inf, the right slab of a parallel ray,
   and a plane through the origin gives 0 x inf = NaN, which the min/max chains drop (the NaN is
   always the left operand of TRACE_MIN/MAX, whose right operand is never NaN; fmin/fmax drop it
   on either side), so a ray running exactly in a face of the box still enters it. */
TRACE_INLINE float trace_box(float3 lo, float3 hi, const TraceRay* r, float tmin, float tmax) {
    int3 neg = r->idir < 0.0f;
    float3 tn = ((neg ? hi : lo) - r->org) * r->idir;
    float3 tf = ((neg ? lo : hi) - r->org) * r->idir * TRACE_BOX_GROW;
    float tnear = TRACE_MAX(tn.x, TRACE_MAX(tn.y, TRACE_MAX(tn.z, tmin)));
    float tfar = TRACE_MIN(tf.x, TRACE_MIN(tf.y, TRACE_MIN(tf.z, tmax)));
    return tnear <= tfar ? tnear : INFINITY;
}

/* Watertight ray-triangle test. On a hit in [tmin, tmax) writes t and Embree barycentrics. */
TRACE_INLINE bool trace_triangle(const TraceRay* r, float3 p0, float3 p1, float3 p2, float tmin,
                                 float tmax, float* t_out, float* u_out, float* v_out) {
    float3 A = p0 - r->org, B = p1 - r->org, C = p2 - r->org;
    float az = trace_axis(A, r->kz), bz = trace_axis(B, r->kz), cz = trace_axis(C, r->kz);
    float ax = trace_axis(A, r->kx) - r->sx * az, ay = trace_axis(A, r->ky) - r->sy * az;
    float bx = trace_axis(B, r->kx) - r->sx * bz, by = trace_axis(B, r->ky) - r->sy * bz;
    float cx = trace_axis(C, r->kx) - r->sx * cz, cy = trace_axis(C, r->ky) - r->sy * cz;
    float U = cx * by - cy * bx;
    float V = ax * cy - ay * cx;
    float W = bx * ay - by * ax;
#ifdef TRAVERSE_FP64
    if (U == 0.0f || V == 0.0f || W == 0.0f) {
        U = (float)((double)cx * (double)by - (double)cy * (double)bx);
        V = (float)((double)ax * (double)cy - (double)ay * (double)cx);
        W = (float)((double)bx * (double)ay - (double)by * (double)ax);
    }
#endif
    if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f)) return false;
    float det = U + V + W;
    if (det == 0.0f) return false;
    float T = U * (r->sz * az) + V * (r->sz * bz) + W * (r->sz * cz);
    float rcp = 1.0f / det;
    float t = T * rcp;
    if (!(t >= tmin && t < tmax)) return false;
    *t_out = t;
    *u_out = V * rcp;
    *v_out = W * rcp;
    return true;
}

/* Of two hits at one distance, is (inst, prim) the one to keep over *hit? The smaller pair:
   the same rule as the cooperative walk (traverse_coop.h), so both give the same hit whatever
   order they meet the triangles in. */
TRACE_INLINE bool trace_tie_wins(int inst, int prim, const Hit* hit) {
    return inst < hit->inst || (inst == hit->inst && prim < hit->prim);
}

#include "traverse_heightfield.h"

TRACE_INLINE void trace_push(int* stack, int* sp, int node, __global int* restrict trace_stats) {
    if (*sp < TRACE_STACK) stack[(*sp)++] = node;
    else atomic_inc(trace_stats + TRACE_STAT_OVERFLOW);
}

/* The next node after visiting one: the nearer of the children hit (gl, gr at distances tl, tr),
   the farther one pushed; with neither, pop. False when the stack is empty (traversal done). */
TRACE_INLINE bool trace_next(bool gl, bool gr, float tl, float tr, int rl, int rr, int* stack,
                             int* sp, int* node, __global int* restrict trace_stats) {
    if (gl && gr) {
        bool left_first = tl <= tr;
        trace_push(stack, sp, left_first ? rr : rl, trace_stats);
        *node = left_first ? rl : rr;
    } else if (gl) {
        *node = rl;
    } else if (gr) {
        *node = rr;
    } else {
        if (*sp == 0) return false;
        *node = stack[--*sp];
    }
    return true;
}

#if TRACE_WIDE
#ifndef TRACE_WIDE_PREFETCH /* 0 turns the prefetch of the next nodes off */
#define TRACE_WIDE_PREFETCH 1
#endif
/* Each wide level pushes at most WIDE_WIDTH - 1 children and pops one. */
#define TRACE_WIDE_STACK ((WIDE_WIDTH - 1) * WIDE_MAX_LEVELS)

/* Vector lanes by index without vstore (a library call on PoCL). */
typedef union {
    float4 v;
    float a[4];
} TraceLanes4;
typedef union {
    int4 v;
    int a[4];
} TraceLanes4i;
typedef union {
    float8 v;
    float a[8];
} TraceLanes8;
typedef union {
    int8 v;
    int a[8];
} TraceLanes8i;

/* any() of a comparison result, without the library call */
TRACE_INLINE bool trace_any4(int4 m) {
    return (m.x | m.y | m.z | m.w) != 0;
}

/* Four triangles of a block at once: the same watertight test as trace_triangle, lane by lane
   (same operations in the same order, so the same hits), including its float64 re-evaluation of
   exact-zero edge functions. Shrinks *tmax to the closest hit in [tmin, *tmax) and records it. */
TRACE_INLINE bool trace_block(__global const TriBlock* restrict b, const TraceRay* r, float tmin,
                              float* tmax, Hit* hit, int inst) {
    float4 ox = (float4)(trace_axis(r->org, r->kx)), oy = (float4)(trace_axis(r->org, r->ky)),
           oz = (float4)(trace_axis(r->org, r->kz));
    float4 az = b->v[0][r->kz] - oz, bz = b->v[1][r->kz] - oz, cz = b->v[2][r->kz] - oz;
    float4 sx = (float4)(r->sx), sy = (float4)(r->sy);
    float4 ax = (b->v[0][r->kx] - ox) - sx * az, ay = (b->v[0][r->ky] - oy) - sy * az;
    float4 bx = (b->v[1][r->kx] - ox) - sx * bz, by = (b->v[1][r->ky] - oy) - sy * bz;
    float4 cx = (b->v[2][r->kx] - ox) - sx * cz, cy = (b->v[2][r->ky] - oy) - sy * cz;
    float4 U = cx * by - cy * bx;
    float4 V = ax * cy - ay * cx;
    float4 W = bx * ay - by * ax;
#ifdef TRAVERSE_FP64
    if (trace_any4((U == 0.0f) | (V == 0.0f) | (W == 0.0f))) {
        TraceLanes4 u = {.v = U}, v = {.v = V}, w = {.v = W}, pax = {.v = ax}, pay = {.v = ay},
                    pbx = {.v = bx}, pby = {.v = by}, pcx = {.v = cx}, pcy = {.v = cy};
        for (int j = 0; j < 4; ++j) {
            if (u.a[j] == 0.0f || v.a[j] == 0.0f || w.a[j] == 0.0f) {
                double dax = pax.a[j], day = pay.a[j], dbx = pbx.a[j], dby = pby.a[j],
                       dcx = pcx.a[j], dcy = pcy.a[j];
                u.a[j] = (float)(dcx * dby - dcy * dbx);
                v.a[j] = (float)(dax * dcy - day * dcx);
                w.a[j] = (float)(dbx * day - dby * dax);
            }
        }
        U = u.v;
        V = v.v;
        W = w.v;
    }
#endif
    int4 outside = ((U < 0.0f) | (V < 0.0f) | (W < 0.0f)) & ((U > 0.0f) | (V > 0.0f) | (W > 0.0f));
    float4 det = U + V + W;
    float4 sz = (float4)(r->sz);
    float4 T = U * (sz * az) + V * (sz * bz) + W * (sz * cz);
    float4 rcp = 1.0f / det;
    float4 t = T * rcp;
    int4 ok = ~outside & (det != 0.0f) & (t >= (float4)(tmin)) & (t < (float4)(*tmax));
    if (!trace_any4(ok)) return false;
    TraceLanes4 ta = {.v = t}, va = {.v = V}, wa = {.v = W}, ra = {.v = rcp};
    TraceLanes4i oka = {.v = ok}, pa = {.v = b->prim};
    int best = -1;
    float tb = *tmax;
    for (int j = 0; j < 4; ++j) {
        if (oka.a[j] && ta.a[j] < tb) {
            tb = ta.a[j];
            best = j;
        }
    }
    *tmax = tb;
    hit->t = tb;
    hit->u = va.a[best] * ra.a[best];
    hit->v = wa.a[best] * ra.a[best];
    hit->prim = pa.a[best];
    hit->inst = inst;
    return true;
}

/* Index of the lowest set bit of x != 0 (OpenCL 1.2 has clz but not ctz). */
TRACE_INLINE int trace_lowest_bit(int x) {
#if TRACE_CPU && defined(__clang__)
    return __builtin_ctz((uint)x);
#else
    return 31 - clz(x & -x);
#endif
}

/* The movemask of a comparison result (lanes -1 or 0). */
TRACE_INLINE int trace_mask8(int8 m) {
    m &= (int8)(1, 2, 4, 8, 16, 32, 64, 128);
    int4 h = m.lo | m.hi;
    int2 q = h.lo | h.hi;
    return q.x | q.y;
}

/* One mesh's wide BVH from `root`: all eight child boxes per node with float8 slabs, the leaves
   hit tested at once (closest first is not needed: they shrink *tmax), the inner children hit
   pushed far to near with their entry distance, popped nearest first and dropped when a closer
   hit has been found since. Same contract as trace_blas. */
TRACE_INLINE bool trace_blas(__global const WideNode* restrict nodes,
                             __global const TriBlock* restrict blocks, int root, const TraceRay* r,
                             float tmin, float* tmax, Hit* hit, int inst, bool any,
                             __global int* restrict trace_stats, uint* work) {
    /* the near and far plane of each axis for this ray's direction signs */
    int nx = r->idir.x >= 0.0f ? 0 : 3, ny = r->idir.y >= 0.0f ? 1 : 4,
        nz = r->idir.z >= 0.0f ? 2 : 5;
    int fx = 3 - nx, fy = 5 - ny, fz = 7 - nz;
    float8 ox = (float8)(r->org.x), oy = (float8)(r->org.y), oz = (float8)(r->org.z);
    float8 ix = (float8)(r->idir.x), iy = (float8)(r->idir.y), iz = (float8)(r->idir.z);
    int stack_node[TRACE_WIDE_STACK];
    float stack_t[TRACE_WIDE_STACK];
    int sp = 0, node = root;
    bool found = false;
    for (;;) {
        __global const WideNode* n = nodes + node;
        TRACE_TICK(work, TRACE_CNT_BLAS, 1);
        float8 tnx = (n->plane[nx] - ox) * ix, tny = (n->plane[ny] - oy) * iy,
               tnz = (n->plane[nz] - oz) * iz;
        float8 tfx = (n->plane[fx] - ox) * ix, tfy = (n->plane[fy] - oy) * iy,
               tfz = (n->plane[fz] - oz) * iz;
        /* NaN-safe chains as in trace_box */
        float8 tn = TRACE_MAX(tnx, TRACE_MAX(tny, TRACE_MAX(tnz, (float8)(tmin))));
        float8 tf = TRACE_MIN(tfx * TRACE_BOX_GROW,
                              TRACE_MIN(tfy * TRACE_BOX_GROW,
                                        TRACE_MIN(tfz * TRACE_BOX_GROW, (float8)(*tmax))));
        int8 cnt = n->cnt;
        int bits = trace_mask8(tn <= tf); /* empty slots: tn = +inf > tf = -inf */
        if (bits) {
            int leaves = bits & trace_mask8(cnt > 0), inner = bits ^ leaves;
            TraceLanes8i ref = {.v = n->ref};
#if TRACE_CPU && TRACE_WIDE_PREFETCH
            /* start reading the inner children hit (the next nodes) before the leaf tests:
               +14-20% incoherent rays on PoCL; their leaf blocks are needed at once, no gain */
            for (int pf = inner; pf; pf &= pf - 1) {
                __global const char* p =
                    (__global const char*)(nodes + ref.a[trace_lowest_bit(pf)]);
                TRACE_PREFETCH(p);
                TRACE_PREFETCH(p + 64);
                TRACE_PREFETCH(p + 128);
                TRACE_PREFETCH(p + 192);
            }
#endif
            if (leaves) {
                TraceLanes8i c = {.v = cnt};
                do {
                    int k = trace_lowest_bit(leaves);
                    leaves &= leaves - 1;
                    int last = ref.a[k] + (c.a[k] + WIDE_BLOCK - 1) / WIDE_BLOCK;
                    TRACE_TICK(work, TRACE_CNT_TRIS, WIDE_BLOCK * (last - ref.a[k]));
                    for (int bk = ref.a[k]; bk < last; ++bk) {
                        if (trace_block(blocks + bk, r, tmin, tmax, hit, inst)) {
                            found = true;
                            if (any) return true;
                        }
                    }
                } while (leaves);
            }
            if (inner) {
                TraceLanes8 te = {.v = tn};
                int k = trace_lowest_bit(inner);
                inner &= inner - 1;
                if (!inner) { /* one inner child: go straight on */
                    if (te.a[k] < *tmax) {
                        node = ref.a[k];
                        continue;
                    }
                } else { /* insertion-sort the children into the stack, nearest on top */
                    int base = sp;
                    for (;;) {
                        float tk = te.a[k];
                        if (tk < *tmax) {
                            if (sp < TRACE_WIDE_STACK) {
                                int q = sp++;
                                while (q > base && stack_t[q - 1] < tk) {
                                    stack_t[q] = stack_t[q - 1];
                                    stack_node[q] = stack_node[q - 1];
                                    --q;
                                }
                                stack_t[q] = tk;
                                stack_node[q] = ref.a[k];
                            } else {
                                atomic_inc(trace_stats + TRACE_STAT_OVERFLOW);
                            }
                        }
                        if (!inner) break;
                        k = trace_lowest_bit(inner);
                        inner &= inner - 1;
                    }
                }
            }
        }
        for (;;) { /* pop the nearest child still in front of the closest hit */
            if (sp == 0) return found;
            --sp;
            if (stack_t[sp] < *tmax) {
                node = stack_node[sp];
                break;
            }
        }
    }
}
#else
/* One mesh's BVH from `root`. Shrinks *tmax to each closer hit and records it in *hit; of hits
   at one distance, the smaller (inst, prim) (trace_tie_wins). */
TRACE_INLINE bool trace_blas(__global const BvhNode* restrict nodes,
                             __global const BvhTri* restrict tris, int root, const TraceRay* r,
                             float tmin, float* tmax, Hit* hit, int inst, bool any,
                             __global int* restrict trace_stats, uint* work) {
    int stack[TRACE_STACK];
    int sp = 0, node = root;
    bool found = false;
    for (;;) {
        __global const BvhNode* n = nodes + node;
        TRACE_TICK(work, TRACE_CNT_BLAS, 1);
        float4 a = n->lo_l, b = n->hi_l, c = n->lo_r, d = n->hi_r;
        int cl = as_int(b.w), cr = as_int(d.w);
        int rl = as_int(a.w), rr = as_int(c.w);
#if TRACE_CPU
        if (cl == 0) TRACE_PREFETCH(nodes + rl);
        if (cr == 0) TRACE_PREFETCH(nodes + rr);
#endif
        float tl = cl >= 0 ? trace_box(a.xyz, b.xyz, r, tmin, *tmax) : INFINITY;
        float tr = cr >= 0 ? trace_box(c.xyz, d.xyz, r, tmin, *tmax) : INFINITY;
        for (int side = 0; side < 2; ++side) {
            int cnt = side ? cr : cl, first = side ? rr : rl;
            float te = side ? tr : tl;
            if (cnt > 0 && te < INFINITY) {
                TRACE_TICK(work, TRACE_CNT_TRIS, cnt);
                for (int k = first; k < first + cnt; ++k) {
                    float t, u, v;
                    BvhTri tri = tris[k];
                    /* a hit at the distance of the closest so far is tested too: of two at one
                       distance the smaller (inst, prim) wins (trace_tie_wins) */
                    const bool have = hit->prim >= 0;
                    if (trace_triangle(r, tri.p0.xyz, tri.p1.xyz, tri.p2.xyz, tmin,
                                       have ? nextafter(*tmax, INFINITY) : *tmax, &t, &u, &v)
                        && (!have || t < *tmax || trace_tie_wins(inst, as_int(tri.p0.w), hit))) {
                        *tmax = t;
                        hit->t = t;
                        hit->u = u;
                        hit->v = v;
                        hit->prim = as_int(tri.p0.w);
                        hit->inst = inst;
                        found = true;
                        if (any) return true;
                    }
                }
            }
        }
        /* tl is INFINITY on a miss; boxes behind the closest hit are dropped, those entered at
           its distance kept (a tie may be there) */
        bool gl = cl == 0 && tl <= *tmax && tl < INFINITY;
        bool gr = cr == 0 && tr <= *tmax && tr < INFINITY;
        if (!trace_next(gl, gr, tl, tr, rl, rr, stack, &sp, &node, trace_stats)) break;
    }
    return found;
}
#endif

/* A world ray in instance ``ins``'s object space, prepared for its BLAS; *o, *d: that origin and
   direction. */
TRACE_INLINE TraceRay trace_object_ray_od(__global const Instance* ins, float3 org, float3 dir,
                                          float3* o, float3* d) {
    float4 m0 = ins->object_from_world[0], m1 = ins->object_from_world[1],
           m2 = ins->object_from_world[2];
    *o = (float3)(dot(m0.xyz, org) + m0.w, dot(m1.xyz, org) + m1.w, dot(m2.xyz, org) + m2.w);
    *d = (float3)(dot(m0.xyz, dir), dot(m1.xyz, dir), dot(m2.xyz, dir));
    return trace_ray_setup(*o, *d);
}

TRACE_INLINE TraceRay trace_object_ray(__global const Instance* ins, float3 org, float3 dir) {
    float3 o, d;
    return trace_object_ray_od(ins, org, dir, &o, &d);
}

/* Instance id's BLAS, or the height field's walk when its mesh is hf_mesh, for a world ray:
   shrinks *tmax and records the hit as trace_blas; nothing for an instance without a BLAS.
   `work`, `inst_work`: the counters of a TRACE_COUNT build (unused otherwise). */
TRACE_INLINE bool trace_instance(SCENE_PARAMS, int id, int hf_mesh, float3 org, float3 dir,
                                 float tmin, float* tmax, bool any, Hit* hit, uint* work,
                                 uint* inst_work) {
    __global const Instance* ins = instances + id;
    int broot = ins->blas_root;
    if (broot < 0) return false;
    float3 oo, od;
    TraceRay lr = trace_object_ray_od(ins, org, dir, &oo, &od);
    TRACE_TICK(work, TRACE_CNT_ENTRIES, 1);
#if TRACE_COUNT
    uint before = work[TRACE_CNT_BLAS];
#endif
    bool got = ins->mesh == hf_mesh
        ? trace_heightfield(hf_info, hf_vertices, hf_blocks, &lr, oo, od, tmin, tmax, hit, id, any,
                            trace_stats)
        : trace_blas(blas_nodes, blas_tris, broot, &lr, tmin, tmax, hit, id, any, trace_stats,
                     work);
#if TRACE_COUNT
    inst_work[min(id, TRACE_COUNT_INST - 1)] += work[TRACE_CNT_BLAS] - before;
#endif
    return got;
}

/* The whole scene: the TLAS over instances, each instance's BLAS in its object space; only
   instances whose visibility mask shares a bit with `mask`. With `only` >= 0, the caller knows
   that instance to be the one `mask` can match: its BLAS alone, no TLAS walk (the same hit).
   `work`: the counters of a TRACE_COUNT build (unused otherwise). */
TRACE_INLINE bool trace_scene_walk(SCENE_PARAMS, float3 org, float3 dir, float tmin, float tmax,
                                   bool any, uint mask, int only, Hit* hit, uint* work,
                                   uint* inst_work) {
    hit->t = INFINITY;
    hit->u = 0.0f;
    hit->v = 0.0f;
    hit->prim = -1;
    hit->inst = -1;
    int root = tlas_info->root;
    if (root < 0 || !(tmax > tmin) || (dir.x == 0.0f && dir.y == 0.0f && dir.z == 0.0f))
        return false;
    const int hf_mesh = hf_info->mesh;
    float tbest = tmax;
    if (only >= 0)
        return trace_instance(SCENE_ARGS, only, hf_mesh, org, dir, tmin, &tbest, any, hit, work,
                              inst_work);
    TraceRay wr = trace_ray_setup(org, dir);
    int stack[TRACE_STACK];
    int sp = 0, node = root;
    bool found = false;
    for (;;) {
        __global const BvhNode* n = tlas_nodes + node;
        TRACE_TICK(work, TRACE_CNT_TLAS, 1);
        float4 a = n->lo_l, b = n->hi_l, c = n->lo_r, d = n->hi_r;
        int cl = as_int(b.w), cr = as_int(d.w);
        int rl = as_int(a.w), rr = as_int(c.w);
        float tl = cl >= 0 ? trace_box(a.xyz, b.xyz, &wr, tmin, tbest) : INFINITY;
        float tr = cr >= 0 ? trace_box(c.xyz, d.xyz, &wr, tmin, tbest) : INFINITY;
        for (int side = 0; side < 2; ++side) {
            int cnt = side ? cr : cl, first = side ? rr : rl;
            float te = side ? tr : tl;
            if (cnt > 0 && te < INFINITY) {
                for (int k = first; k < first + cnt; ++k) {
                    int id = tlas_prims[k];
                    if (!(instances[id].mask & mask)) continue;
                    if (trace_instance(SCENE_ARGS, id, hf_mesh, org, dir, tmin, &tbest, any, hit,
                                       work, inst_work)) {
                        found = true;
                        if (any) return true;
                    }
                }
            }
        }
        bool gl = cl == 0 && tl <= tbest && tl < INFINITY;
        bool gr = cr == 0 && tr <= tbest && tr < INFINITY;
        if (!trace_next(gl, gr, tl, tr, rl, rr, stack, &sp, &node, trace_stats)) break;
    }
    return found;
}

/* trace_scene_walk, its work added to kind's counters in a TRACE_COUNT build. */
TRACE_INLINE bool trace_scene(SCENE_PARAMS, float3 org, float3 dir, float tmin, float tmax,
                              bool any, uint mask, int only, Hit* hit, int kind) {
#if TRACE_COUNT
    uint work[TRACE_COUNT_FIELDS], inst_work[TRACE_COUNT_INST];
    for (int f = 0; f < TRACE_COUNT_FIELDS; ++f) work[f] = 0;
    for (int f = 0; f < TRACE_COUNT_INST; ++f) inst_work[f] = 0;
    bool found =
        trace_scene_walk(SCENE_ARGS, org, dir, tmin, tmax, any, mask, only, hit, work, inst_work);
    work[TRACE_CNT_RAYS] = (kind & TRACE_CONTINUE) ? 0u : 1u;
    work[TRACE_CNT_TRAVERSALS] = 1u;
    work[TRACE_CNT_HITS] = found ? 1u : 0u;
    int k = clamp(kind & 0xff, 0, TRACE_KINDS - 1);
    __global uint* c = (__global uint*)trace_stats + TRACE_STAT_COUNT + k * TRACE_COUNT_FIELDS;
    for (int f = 0; f < TRACE_COUNT_FIELDS; ++f)
        if (work[f]) atomic_add(c + f, work[f]);
    __global uint* ci = (__global uint*)trace_stats + TRACE_STAT_INST + k * TRACE_COUNT_INST;
    for (int f = 0; f < TRACE_COUNT_INST; ++f)
        if (inst_work[f]) atomic_add(ci + f, inst_work[f]);
    return found;
#else
    return trace_scene_walk(SCENE_ARGS, org, dir, tmin, tmax, any, mask, only, hit, 0, 0);
#endif
}

/* Closest hit in [tmin, tmax) among the instances whose mask shares a bit with `mask`: prim
   and inst -1, t INFINITY on a miss. `kind` (scene.h: TRACE_KIND_*, optionally | TRACE_CONTINUE)
   names the ray for the TRACE_COUNT counters. */
TRACE_INLINE Hit scene_closest_hit_masked(SCENE_PARAMS, float3 org, float3 dir, float tmin,
                                          float tmax, uint mask, int kind) {
    Hit h;
    trace_scene(SCENE_ARGS, org, dir, tmin, tmax, false, mask, -1, &h, kind);
    return h;
}

/* Is any of those instances hit in [tmin, tmax)? (shadow rays; ends at the first hit found) */
TRACE_INLINE bool scene_any_hit_masked(SCENE_PARAMS, float3 org, float3 dir, float tmin,
                                       float tmax, uint mask, int kind) {
    Hit h;
    return trace_scene(SCENE_ARGS, org, dir, tmin, tmax, true, mask, -1, &h, kind);
}

/* The same over every instance. */
TRACE_INLINE Hit scene_closest_hit(SCENE_PARAMS, float3 org, float3 dir, float tmin, float tmax) {
    return scene_closest_hit_masked(SCENE_ARGS, org, dir, tmin, tmax, ~0u, TRACE_KIND_QUERY);
}

TRACE_INLINE bool scene_any_hit(SCENE_PARAMS, float3 org, float3 dir, float tmin, float tmax) {
    return scene_any_hit_masked(SCENE_ARGS, org, dir, tmin, tmax, ~0u, TRACE_KIND_QUERY);
}

/* Any hit, and which one was found first (not necessarily the closest). */
TRACE_INLINE bool scene_any_hit_record(SCENE_PARAMS, float3 org, float3 dir, float tmin, float tmax,
                                       Hit* h) {
    return trace_scene(SCENE_ARGS, org, dir, tmin, tmax, true, ~0u, -1, h, TRACE_KIND_QUERY);
}

#endif
