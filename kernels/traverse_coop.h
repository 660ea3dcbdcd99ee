/* Cooperative traversal: the 32 work-items of one work-group (one NVIDIA warp) trace ONE ray
   together, so that the chain of dependent node reads of a ray shrinks by up to 32x. For the
   tail levels of the renderer (a few thousand rays or fewer), which are latency-bound: each
   ray is a chain of ~200-300 dependent node reads, and there are too few rays to hide it.

   Use: every work-item of the group calls trace_scene_coop with the SAME ray, the same
   arguments and the same scratch (a `__local TraceCoop` declared in the kernel): identical
   inputs give identical control flow in the caller, so the barriers in here are reached by the
   whole group. Every work-item gets the identical Hit back. The caller's global writes are for
   one work-item only (TRACE_LEADER). Work-groups must be TRACE_COOP_WIDTH wide.

   The walk (binary layout): a local stack of (node, instance or -1 for a TLAS node, entry
   distance); each round the lanes pop up to 32 entries, drop those farther than the closest
   hit so far, and process one node each: a TLAS node tests both child boxes with the world ray
   and pushes the inner children hit, and for a leaf child each instance's BLAS root (mask
   test, object-space ray as trace_scene_walk); a BLAS node tests both child boxes with its
   instance's object-space ray and pushes the inner children hit, and tests the triangles of
   its leaf children; the scene's height field (heightfield.h) is walked by the lane that
   enters its instance, alone (trace_heightfield). The closest hit so far is shared through an atomic_min on an
   order-preserving integer key of t. Boxes and triangles are kept up to AND including that
   distance, so every triangle hit at the final distance is tested and the result is the hit
   of smallest (t, inst, prim): deterministic whatever the order of the lanes. Where the
   serial walk (traverse.h) meets two triangles at exactly the same t (a shared edge or vertex)
   it keeps the first it finds; this keeps the smallest (inst, prim): the only difference.
   Any-hit: the first hit sets a shared flag and the group stops after that round (same
   boolean as the serial walk; the hit is the closest of those found).
   A full stack (TRACE_COOP_STACK entries) is never silent nor wrong: the ray is traced again
   with the serial walk (by every lane, the same) and counted in trace_stats at
   TRACE_STAT_COOP_REDO.

   Compiled in only with TRACE_COOP=1 and the binary layout without the TRACE_COUNT counters:
   under TRACE_WIDE, TRACE_COUNT or TRACE_COOP_SERIAL, trace_scene_coop is the serial walk per
   work-item (the same hit; TRACE_COUNT counts each ray once, by the first work-item). */
#ifndef LBWATER_TRAVERSE_COOP_H
#define LBWATER_TRAVERSE_COOP_H

#include "traverse.h"

#ifndef TRACE_COOP
#define TRACE_COOP 0
#endif
#define TRACE_COOP_WIDTH 32
#ifndef TRACE_COOP_STACK /* entries; a define so tests can force the overflow fallback */
#define TRACE_COOP_STACK 512
#endif
/* TRACE_COOP_SERIAL=1: the cooperative kernels with the serial walk per work-item (the same hits;
   raytrace.render.Renderer sets it on a CPU, where PoCL takes minutes to compile the walk's
   barriers inside the renderer's light and crossing loops; the walk itself is tested there
   through trace_query.cl). */
#ifndef TRACE_COOP_SERIAL
#define TRACE_COOP_SERIAL 0
#endif
#define TRACE_COOP_WALK (TRACE_COOP && !TRACE_WIDE && !TRACE_COUNT && !TRACE_COOP_SERIAL)
#define TRACE_COOP_FOUND 1 /* any-hit: a hit was found */
#define TRACE_COOP_FULL 2  /* the stack overflowed: redo serially */

#if TRACE_COOP
/* The group's scratch, declared `__local TraceCoop name;` in the kernel. */
typedef struct {
    int node[TRACE_COOP_STACK];
    int inst[TRACE_COOP_STACK];
    float t[TRACE_COOP_STACK];
    int top[2]; /* stack size: read from top[round & 1], pushed onto top[~round & 1] */
    int best;   /* trace_coop_key of the closest hit so far (of tmax before one) */
    int flags;  /* TRACE_COOP_FOUND | TRACE_COOP_FULL */
    float rt[TRACE_COOP_WIDTH], ru[TRACE_COOP_WIDTH], rv[TRACE_COOP_WIDTH];
    int rprim[TRACE_COOP_WIDTH], rinst[TRACE_COOP_WIDTH];
} TraceCoop;

/* The per-ray bodies take TRACE_PARAMS: the scene plus the scratch and whether to walk
   cooperatively (a uniform flag: a kernel may trace some rays per work-item, some per group). */
#define TRACE_PARAMS SCENE_PARAMS, __local TraceCoop* restrict coop, const bool coop_on
#define TRACE_ARGS SCENE_ARGS, coop, coop_on
#define TRACE_SERIAL_ARGS SCENE_ARGS, (__local TraceCoop*)0, false
#define TRACE_COOP_ARGS(scratch) SCENE_ARGS, (scratch), true
#define TRACE_COOP_IF_ARGS(scratch, on) SCENE_ARGS, (scratch), (on)
/* A level's rays are traversed one per work-group only while they are few: at most
   TRACE_COOP_MAX_RAYS (the device-side count; raytrace.query.COOP_MAX_RAYS mirrors it). Above
   it (the H200: the pool's 36k depth-2 rays a group each took 2x as long as a work-item each;
   its tail levels of 4k-12k rays gained) a cooperative kernel takes one ray per work-item. */
#define TRACE_COOP_MAX_RAYS 16384
/* for each ray i < n: one per work-group (coop_on) or one per work-item */
#define TRACE_COOP_FOR(i, n, on)                                                            \
    for (uint i = (on) ? get_group_id(0) : get_global_id(0); i < (n);                      \
         i += (on) ? get_num_groups(0) : get_global_size(0))
/* the one work-item that writes a cooperative ray's results */
#define TRACE_LEADER (!coop_on || get_local_id(0) == 0)
#else
#define TRACE_PARAMS SCENE_PARAMS
#define TRACE_ARGS SCENE_ARGS
#define TRACE_SERIAL_ARGS SCENE_ARGS
#define TRACE_LEADER 1
#endif

#if TRACE_COOP_WALK
/* Floats as ints of the same order (negative ones too), so atomic_min orders distances. */
TRACE_INLINE int trace_coop_key(float f) {
    int i = as_int(f);
    return i ^ ((i >> 31) & 0x7fffffff);
}
TRACE_INLINE float trace_coop_unkey(int k) {
    return as_float(k ^ ((k >> 31) & 0x7fffffff));
}

TRACE_INLINE void trace_coop_push(__local TraceCoop* c, int slot, int node, int inst, float t) {
    int k = atomic_inc(&c->top[slot]);
    if (k < TRACE_COOP_STACK) {
        c->node[k] = node;
        c->inst[k] = inst;
        c->t[k] = t;
    } else {
        atomic_or(&c->flags, TRACE_COOP_FULL);
    }
}

/* (t, inst, prim) before (pt, pinst, pprim)? */
TRACE_INLINE bool trace_coop_before(float t, int inst, int prim, float pt, int pinst, int pprim) {
    return t < pt || (t == pt && (inst < pinst || (inst == pinst && prim < pprim)));
}

/* Triangles are kept up to and including distance b, below the caller's tmax. */
TRACE_INLINE float trace_coop_tri_max(float b, float tmax) {
    return b < tmax ? nextafter(b, INFINITY) : tmax;
}

TRACE_INLINE bool trace_scene_coop_walk(SCENE_PARAMS, __local TraceCoop* coop, float3 org,
                                        float3 dir, float tmin, float tmax, bool any, uint mask,
                                        Hit* hit) {
    hit->t = INFINITY;
    hit->u = 0.0f;
    hit->v = 0.0f;
    hit->prim = -1;
    hit->inst = -1;
    int root = tlas_info->root;
    if (root < 0 || !(tmax > tmin) || (dir.x == 0.0f && dir.y == 0.0f && dir.z == 0.0f))
        return false; /* the same for every lane: the scratch is untouched */
    const int lid = get_local_id(0);
    const int hf_mesh = hf_info->mesh;
    const TraceRay wr = trace_ray_setup(org, dir);
    if (lid == 0) {
        coop->node[0] = root;
        coop->inst[0] = -1;
        coop->t[0] = tmin;
        coop->top[0] = 1;
        coop->best = trace_coop_key(tmax);
        coop->flags = 0;
    }
    /* this lane's closest hit */
    float pt = INFINITY, pu = 0.0f, pv = 0.0f;
    int pprim = -1, pinst = -1;
    int flags = 0;
    for (int round = 0;; ++round) {
        barrier(CLK_LOCAL_MEM_FENCE); /* last round's pushes and hits are in */
        const int p = round & 1;
        const int sp = coop->top[p];
        flags = coop->flags;
        const float sb = trace_coop_unkey(coop->best);
        if (sp == 0 || flags) break; /* the same values in every lane */
        const int take = min(sp, TRACE_COOP_WIDTH);
        int e_node = 0, e_inst = -1;
        float e_t = INFINITY;
        if (lid < take) {
            const int k = sp - 1 - lid;
            e_node = coop->node[k];
            e_inst = coop->inst[k];
            e_t = coop->t[k];
        }
        if (lid == 0) coop->top[p ^ 1] = sp - take; /* pushes go above what is left */
        barrier(CLK_LOCAL_MEM_FENCE); /* the popped entries are read: pushes may overwrite */
        float b = fmin(sb, pt);
        if (!(lid < take && e_t <= b)) continue;
        TraceRay r = wr;
        if (e_inst >= 0) r = trace_object_ray(instances + e_inst, org, dir);
        __global const BvhNode* n = (e_inst < 0 ? tlas_nodes : blas_nodes) + e_node;
        float4 a = n->lo_l, bb = n->hi_l, c = n->lo_r, d = n->hi_r;
        int cl = as_int(bb.w), cr = as_int(d.w);
        int rl = as_int(a.w), rr = as_int(c.w);
        float tl = cl >= 0 ? trace_box(a.xyz, bb.xyz, &r, tmin, b) : INFINITY;
        float tr = cr >= 0 ? trace_box(c.xyz, d.xyz, &r, tmin, b) : INFINITY;
        for (int side = 0; side < 2; ++side) {
            int cnt = side ? cr : cl, first = side ? rr : rl;
            float te = side ? tr : tl;
            if (te == INFINITY) continue;
            if (cnt == 0) {
                trace_coop_push(coop, p ^ 1, first, e_inst, te);
            } else if (cnt > 0 && e_inst < 0) { /* TLAS leaf: enter its instances */
                for (int k = first; k < first + cnt; ++k) {
                    int id = tlas_prims[k];
                    __global const Instance* ins = instances + id;
                    int broot = ins->blas_root;
                    if (broot < 0 || !(ins->mask & mask)) continue;
                    if (ins->mesh != hf_mesh) {
                        trace_coop_push(coop, p ^ 1, broot, id, te);
                        continue;
                    }
                    /* the height field: this lane walks it alone, its hit merged as a leaf's */
                    float3 oo, od;
                    const TraceRay hr = trace_object_ray_od(ins, org, dir, &oo, &od);
                    Hit hh;
                    hh.prim = -1;
                    hh.inst = -1;
                    float hmax = trace_coop_tri_max(b, tmax);
                    if (!trace_heightfield(hf_info, hf_vertices, hf_blocks, &hr, oo, od, tmin,
                                           &hmax, &hh, id, any, trace_stats))
                        continue;
                    if (trace_coop_before(hh.t, id, hh.prim, pt, pinst, pprim)) {
                        pt = hh.t;
                        pu = hh.u;
                        pv = hh.v;
                        pprim = hh.prim;
                        pinst = id;
                    }
                    if (any) {
                        atomic_or(&coop->flags, TRACE_COOP_FOUND);
                        break;
                    }
                    b = fmin(b, hh.t);
                    atomic_min(&coop->best, trace_coop_key(hh.t));
                }
            } else if (cnt > 0) { /* BLAS leaf: its triangles */
                float tri_max = trace_coop_tri_max(b, tmax);
                for (int k = first; k < first + cnt; ++k) {
                    float t, u, v;
                    BvhTri tri = blas_tris[k];
                    if (!trace_triangle(&r, tri.p0.xyz, tri.p1.xyz, tri.p2.xyz, tmin, tri_max,
                                        &t, &u, &v))
                        continue;
                    int prim = as_int(tri.p0.w);
                    if (trace_coop_before(t, e_inst, prim, pt, pinst, pprim)) {
                        pt = t;
                        pu = u;
                        pv = v;
                        pprim = prim;
                        pinst = e_inst;
                    }
                    if (any) {
                        atomic_or(&coop->flags, TRACE_COOP_FOUND);
                        break;
                    }
                    b = fmin(b, t);
                    tri_max = trace_coop_tri_max(b, tmax);
                    atomic_min(&coop->best, trace_coop_key(t));
                }
            }
        }
    }
    if (flags & TRACE_COOP_FULL) { /* stack full: the serial walk, the same in every lane */
        if (lid == 0) atomic_inc(trace_stats + TRACE_STAT_COOP_REDO);
        barrier(CLK_LOCAL_MEM_FENCE); /* the scratch may be reused at once */
        return trace_scene_walk(SCENE_ARGS, org, dir, tmin, tmax, any, mask, -1, hit, 0, 0);
    }
    /* the smallest (t, inst, prim) over the lanes, found by every lane alike */
    coop->rt[lid] = pt;
    coop->ru[lid] = pu;
    coop->rv[lid] = pv;
    coop->rprim[lid] = pprim;
    coop->rinst[lid] = pinst;
    barrier(CLK_LOCAL_MEM_FENCE);
    int w = 0;
    for (int k = 1; k < TRACE_COOP_WIDTH; ++k)
        if (trace_coop_before(coop->rt[k], coop->rinst[k], coop->rprim[k], coop->rt[w],
                              coop->rinst[w], coop->rprim[w]))
            w = k;
    bool found = coop->rprim[w] >= 0;
    if (found) {
        hit->t = coop->rt[w];
        hit->u = coop->ru[w];
        hit->v = coop->rv[w];
        hit->prim = coop->rprim[w];
        hit->inst = coop->rinst[w];
    }
    barrier(CLK_LOCAL_MEM_FENCE); /* all have read: the scratch may be reused at once */
    return found;
}
#endif

#if TRACE_COOP
/* The hit of trace_scene, found by the whole work-group (see above) or, without the
   cooperative walk in this build or for one instance alone (`only` >= 0, trace_scene_walk), by
   each work-item alike. */
TRACE_INLINE bool trace_scene_coop(SCENE_PARAMS, __local TraceCoop* coop, float3 org,
                                   float3 dir, float tmin, float tmax, bool any, uint mask,
                                   int only, Hit* hit, int kind) {
#if TRACE_COOP_WALK
    if (only < 0)
        return trace_scene_coop_walk(SCENE_ARGS, coop, org, dir, tmin, tmax, any, mask, hit);
#endif
#if TRACE_COUNT
    if (get_local_id(0) != 0) { /* count the ray once */
        uint work[TRACE_COUNT_FIELDS], inst_work[TRACE_COUNT_INST];
        for (int f = 0; f < TRACE_COUNT_FIELDS; ++f) work[f] = 0;
        for (int f = 0; f < TRACE_COUNT_INST; ++f) inst_work[f] = 0;
        return trace_scene_walk(SCENE_ARGS, org, dir, tmin, tmax, any, mask, only, hit, work,
                                inst_work);
    }
#endif
    return trace_scene(SCENE_ARGS, org, dir, tmin, tmax, any, mask, only, hit, kind);
}
#endif

/* scene_closest_hit_masked / scene_any_hit_masked for the per-ray bodies (TRACE_PARAMS):
   per work-item, or per work-group when coop_on in a TRACE_COOP build. trace_closest_only:
   with `only` >= 0, the caller knows that instance to be the one `mask` can match
   (trace_scene_walk): its BLAS alone, per work-item. */
TRACE_INLINE Hit trace_closest_only(TRACE_PARAMS, float3 org, float3 dir, float tmin, float tmax,
                                    uint mask, int only, int kind) {
    Hit h;
#if TRACE_COOP
    if (coop_on) {
        trace_scene_coop(SCENE_ARGS, coop, org, dir, tmin, tmax, false, mask, only, &h, kind);
        return h;
    }
#endif
    trace_scene(SCENE_ARGS, org, dir, tmin, tmax, false, mask, only, &h, kind);
    return h;
}

TRACE_INLINE Hit trace_closest_masked(TRACE_PARAMS, float3 org, float3 dir, float tmin,
                                      float tmax, uint mask, int kind) {
    return trace_closest_only(TRACE_ARGS, org, dir, tmin, tmax, mask, -1, kind);
}

TRACE_INLINE bool trace_any_masked(TRACE_PARAMS, float3 org, float3 dir, float tmin, float tmax,
                                   uint mask, int kind) {
#if TRACE_COOP
    if (coop_on) {
        Hit h;
        return trace_scene_coop(SCENE_ARGS, coop, org, dir, tmin, tmax, true, mask, -1, &h, kind);
    }
#endif
    return scene_any_hit_masked(SCENE_ARGS, org, dir, tmin, tmax, mask, kind);
}

#endif
