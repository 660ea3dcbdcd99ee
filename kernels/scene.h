/* The two-level scene as kernel parameters: a kernel that traces rays declares
       __kernel void k(SCENE_PARAMS, __global ... its own ...)
   and passes SCENE_ARGS on to scene_closest_hit / scene_any_hit (traverse.h). The host side,
   raytrace.scene.Scene.trace_args(), returns the buffers in exactly this order. */
#ifndef LBWATER_SCENE_H
#define LBWATER_SCENE_H

#include "bvh.h"

/* tlas_info  : header of the top-level BVH (root node, -1 when the scene has no instance);
   tlas_nodes : top-level nodes over instance boxes; leaves index tlas_prims;
   tlas_prims : instance ids in top-level leaf order;
   instances  : Instance records by instance id;
   blas_nodes : every mesh's nodes in one array (instances hold their root index);
   blas_tris  : every mesh's triangles in one array, in leaf order (wide: in blocks);
   trace_stats: [0] counts traversal-stack overflows (never expected: the stack is deeper than
                any tree the builder can make; a non-zero count means hits may be missing). */
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
    __global int* restrict trace_stats

#define SCENE_ARGS tlas_info, tlas_nodes, tlas_prims, instances, blas_nodes, blas_tris, trace_stats

#define TRACE_STAT_OVERFLOW 0
#define TRACE_STATS_LEN 4

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
