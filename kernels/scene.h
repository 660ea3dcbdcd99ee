/* The two-level scene as kernel parameters: a kernel that traces rays declares
       __kernel void k(SCENE_PARAMS, __global ... its own ...)
   and passes SCENE_ARGS on to scene_closest_hit / scene_any_hit (traverse.h). The host side,
   raytrace.scene.Scene.trace_args(), returns the buffers in exactly this order. */
#ifndef LBWATER_SCENE_H
#define LBWATER_SCENE_H

#include "bvh.h"
#include "heightfield.h"

/* tlas_info  : header of the top-level BVH (root node, -1 when the scene has no instance);
   tlas_nodes : top-level nodes over instance boxes; leaves index tlas_prims;
   tlas_prims : instance ids in top-level leaf order;
   instances  : Instance records by instance id;
   blas_nodes : every mesh's nodes in one array (instances hold their root index);
   blas_tris  : every mesh's triangles in one array, in leaf order (wide: in blocks);
   hf_info, hf_vertices, hf_blocks: the scene's height field (heightfield.h; hf_info->mesh is
                HF_NONE without one): its record, its vertices (the writer's buffer) and the y
                range and slope bound of each block of its cells;
   trace_stats: [0] counts traversal-stack overflows (never expected: the stack is deeper than
                any tree the builder can make; a non-zero count means hits may be missing);
                [1] counts cooperative walks redone serially (TRACE_STAT_COOP_REDO);
                [2] to [10] and, from TRACE_STAT_COUNT, the work counters of TRACE_COUNT
                builds follow. */
/* TRACE_WIDE picks the BLAS layout the kernels read; the host passes it (kernels.runtime adds
   the runtime's layout to every build, raytrace.scene.Scene.trace_defines names the scene's):
   0: binary nodes (BvhNode) and leaf-ordered triangles (BvhTri), the GPU layout;
   1: 8-wide nodes (WideNode) and 4-triangle blocks (TriBlock), the CPU layout. */
#ifndef TRACE_WIDE
#define TRACE_WIDE 0
#endif
#if TRACE_WIDE
#define BLAS_NODE WideNode
#define BLAS_PRIM TriBlock
#else
#define BLAS_NODE BvhNode
#define BLAS_PRIM BvhTri
#endif

#define SCENE_PARAMS                                                                            \
    __global const BvhInfo* restrict tlas_info, __global const BvhNode* restrict tlas_nodes,    \
    __global const int* restrict tlas_prims, __global const Instance* restrict instances,       \
    __global const BLAS_NODE* restrict blas_nodes, __global const BLAS_PRIM* restrict blas_tris, \
    __global const HeightField* restrict hf_info, __global const float4* restrict hf_vertices,  \
    __global const float4* restrict hf_blocks, __global int* restrict trace_stats

#define SCENE_ARGS                                                                             \
    tlas_info, tlas_nodes, tlas_prims, instances, blas_nodes, blas_tris, hf_info, hf_vertices,  \
        hf_blocks, trace_stats

#define TRACE_STAT_OVERFLOW 0
/* rays of the cooperative walk (traverse_coop.h) traced again serially because its local stack
   was full: never wrong, only slower */
#define TRACE_STAT_COOP_REDO 1
/* TRACE_COUNT builds: height-field walks culled whole, and spans a walk skipped, because the
   ray departs from the surface faster than its slopes (traverse_heightfield.h) */
#define TRACE_STAT_HF_CULLED 2
#define TRACE_STAT_HF_SKIPPED 3
/* TRACE_COUNT builds: the light buffer's answers (light_buffer.h), TRACE_STAT_LB_FIELDS from
   TRACE_STAT_LB: origins whose cell lists nothing, nearer the light than the cell's bound, in a
   cell whose triangles were tested clear, blocked by one of them, in a full cell (with no fine
   grid, or in a full fine cell), off the map; then the triangles tested, and the origins looked
   up in a full cell's fine grid */
#define TRACE_STAT_LB 4
#define TRACE_STAT_LB_FIELDS 8
/* Traversal work counters, written only by TRACE_COUNT=1 builds (a debug define, traverse.h;
   raytrace.scene.Scene.trace_counts reads them): per ray kind, TRACE_COUNT_FIELDS uint sums
   from TRACE_STAT_COUNT, then per kind the BLAS nodes visited per instance (ids above
   TRACE_COUNT_INST - 1 share the last slot) from TRACE_STAT_INST. */
#define TRACE_KIND_QUERY 0     /* trace_query.cl and other callers */
#define TRACE_KIND_PRIMARY 1   /* the renderer's depth-0 rays */
#define TRACE_KIND_SECONDARY 2 /* its reflection and refraction rays */
#define TRACE_KIND_SHADOW 3    /* its shadow rays (the any-hit query of what blocks light) */
#define TRACE_KIND_PHOTON 4    /* the caustics' photons */
#define TRACE_KIND_CROSSING 5  /* shadow rays on through dielectrics (render_shade.cl) */
#define TRACE_KINDS 6
#define TRACE_CONTINUE 0x100   /* or-ed into a kind: the same ray traced on (not counted again) */
#define TRACE_CNT_RAYS 0       /* rays */
#define TRACE_CNT_TRAVERSALS 1 /* scene traversals (a shadow ray through water makes several) */
#define TRACE_CNT_TLAS 2       /* TLAS nodes visited */
#define TRACE_CNT_ENTRIES 3    /* BLAS traversals started (instances entered) */
#define TRACE_CNT_BLAS 4       /* BLAS nodes visited */
#define TRACE_CNT_TRIS 5       /* triangle tests (wide layout: 4 per block) */
#define TRACE_CNT_HITS 6       /* traversals that found a hit */
#define TRACE_COUNT_FIELDS 8
#define TRACE_COUNT_INST 8
#define TRACE_STAT_COUNT (TRACE_STAT_LB + TRACE_STAT_LB_FIELDS)
#define TRACE_STAT_INST (TRACE_STAT_COUNT + TRACE_KINDS * TRACE_COUNT_FIELDS)
#define TRACE_STATS_LEN (TRACE_STAT_INST + TRACE_KINDS * TRACE_COUNT_INST)

/* A ray hit, 20 bytes. t in units of the ray direction (INFINITY on a miss); barycentrics in
   Embree's convention P = (1-u-v) p0 + u p1 + v p2; prim: triangle index in the instance's mesh
   (input order), -1 on a miss; inst: instance id, -1 on a miss. */
typedef struct {
    float t;
    float u;
    float v;
    int prim;
    int inst;
} Hit;

#endif
