/* The light buffer (Haines & Greenberg 1986): for a directional light, a map of cells across the
 * light's direction, each listing the opaque triangles whose shadow falls on it. Every point on a
 * light ray projects to the same cell, so a shadow ray toward that light can only be blocked by
 * the triangles its origin's cell lists: tested there (the traversal's own triangle test, in
 * each instance's object space, the same floats as its BLAS), the answer is the any-hit
 * traversal's, bit for bit, with no tree walked. A cell keeps its first LB_SLOTS triangles in
 * its slots and the rest in a list of its own (the map's overflow region, filled after the
 * raster). Where that region had no room, or for an origin off the map while some triangle
 * reached past it, the answer is "unknown" and the ray walks the BVH. A map with neither is
 * complete: it answers every ray (raytrace/light_buffer.py LightBuffer.complete; the shadow
 * kernels' SHADOW_MAPPED flavour walks no BVH). Built on the device from the scene's transform
 * rows whenever they were written (light_buffer.cl); raytrace/light_buffer.py plans it. */
#ifndef LBWATER_LIGHT_BUFFER_H
#define LBWATER_LIGHT_BUFFER_H

#include "traverse.h"

/* triangles a cell keeps in its slots, the rest in its overflow list (16 against 8: the
   baseline scene's shadow rays 2% faster on the H200: BENCHMARKS.md) */
#define LB_SLOTS 16
/* a triangle over more cells is rastered by a work-group (light_buffer_raster_big) */
#define LB_SMALL_CELLS 32
/* one over more cells by the whole launch */
#define LB_MEDIUM_CELLS 4096
/* a cell of more triangles has each tested first against its footprint's box in the map
   (LightBuffer.box_base): most of a long list's small triangles miss the origin's point */
#ifndef LB_BOX_FROM
#define LB_BOX_FROM LB_SLOTS
#endif
/* light_buffer_blocked's answers */
#define LB_UNKNOWN (-1)
#define LB_CLEAR 0
#define LB_BLOCKED 1

/* 96 bytes. Light l's map (lb_maps[l]; n_u == 0: none, its rays walk the BVH). A point p lies
 * in cell (floor(cu), floor(cv)), cu = dot(p, u.xyz) + u.w, likewise cv; its depth toward the
 * light is dot(p, toward.xyz). */
typedef struct {
    float4 u;          /* xyz: the map's first axis in cells per metre; w: offset (cells) */
    float4 v;          /* xyz: the second axis; w: offset */
    float4 toward;     /* xyz: unit direction toward the light (its direction negated) */
    int n_u, n_v;      /* cells along u and v */
    int cell_base;     /* the map's first cell in lb_cells (its slots: LB_SLOTS per cell) */
    int outside_cell;  /* lb_cells[outside_cell].x: triangles that reach off the map */
    int big_cell;      /* lb_cells[big_cell]: triangles left to light_buffer_raster_big (x:
                          medium, y: huge; light_buffer.cl) */
    float margin;      /* cells a triangle's footprint grows by: rounding of the projections */
    float depth_slack; /* metres a cell's depth bound grows by: rounding of the depths */
    int over_cell;     /* lb_cells[over_cell]: x: triangles past a cell's slots that the raster
                          met (each a pair in lb_pairs), y: of those given a place in lb_extra */
    int over_base;     /* the map's overflow region: lb_pairs and lb_extra from over_base, */
    int over_cap;      /* over_cap entries; more met than that: the full cells say "unknown" */
    int box_base;      /* lb_boxes[box_base + t]: listed triangle t's footprint in the map's cell
                          coordinates, grown by the margin (lo.xy, hi.xy) */
    int pad;
} LightBuffer;

/* The kernel parameters of a stage that reads the light buffer (shadow rays), and their names.
 * lb_cells[c]: x = triangles listed (the first LB_SLOTS in lb_slots[c * LB_SLOTS ..], the rest
 * from lb_extra[lb_over[c].x]), y = float_to_ordered of the nearest-to-the-light depth any of
 * them reaches over the cell; lb_tris: three float4 per listed triangle, its object-space
 * vertices, p0.w = as_float(instance); lb_boxes: each map's footprints of them.
 */
#define LIGHT_BUFFER_PARAMS                                                                   \
    __global const LightBuffer* restrict lb_maps, __global const int2* restrict lb_cells,   \
        __global const int* restrict lb_slots, __global const float4* restrict lb_tris,     \
        __global const int2* restrict lb_over, __global const int* restrict lb_extra,      \
        __global const float4* restrict lb_boxes
#define LIGHT_BUFFER_ARGS lb_maps, lb_cells, lb_slots, lb_tris, lb_over, lb_extra, lb_boxes

/* TRACE_COUNT builds count each answer's kind (scene.h TRACE_STAT_LB: Scene.trace_counts()
 * ["light_buffer"]); others nothing */
#if TRACE_COUNT
#define LB_COUNT(field, n) atomic_add(stats + TRACE_STAT_LB + (field), (n))
#else
#define LB_COUNT(field, n)
#endif
#define LB_CNT_EMPTY 0
#define LB_CNT_NEARER 1
#define LB_CNT_TESTED_CLEAR 2
#define LB_CNT_BLOCKED 3
#define LB_CNT_FULL 4
#define LB_CNT_OFF_MAP 5
#define LB_CNT_TRIANGLES 6
#define LB_CNT_LONG_LISTS 7

/* Whether a shadow ray from org along dir (toward light l) within [0, tmax) is blocked by an
 * opaque triangle of the map: LB_BLOCKED, LB_CLEAR, or LB_UNKNOWN (no map, a full cell whose
 * list found no room, off a map that some triangle reached past): walk the BVH. stats: the
 * scene's trace_stats (TRACE_COUNT). */
inline int light_buffer_blocked(LIGHT_BUFFER_PARAMS, __global const Instance* restrict instances,
                                uint light, float3 org, float3 dir, float tmax,
                                __global int* restrict stats)
{
    const LightBuffer m = lb_maps[light];
    if (m.n_u == 0) return LB_UNKNOWN;
    const float cu = dot(org, m.u.xyz) + m.u.w, cv = dot(org, m.v.xyz) + m.v.w;
    if (!(cu >= 0.0f && cu < (float)m.n_u && cv >= 0.0f && cv < (float)m.n_v)) {
        LB_COUNT(LB_CNT_OFF_MAP, 1);
        return lb_cells[m.outside_cell].x ? LB_UNKNOWN : LB_CLEAR;
    }
    const int cell = m.cell_base + (int)cv * m.n_u + (int)cu;
    const int2 c = lb_cells[cell];
    if (c.x == 0) {
        LB_COUNT(LB_CNT_EMPTY, 1);
        return LB_CLEAR;
    }
    if (dot(org, m.toward.xyz) > ordered_to_float(c.y)) {
        LB_COUNT(LB_CNT_NEARER, 1);
        return LB_CLEAR;
    }
    int extra = 0;   /* lb_extra[extra + k]: triangle k past the slots */
    if (c.x > LB_SLOTS) {
        if (lb_cells[m.over_cell].x > m.over_cap) {
            LB_COUNT(LB_CNT_FULL, 1);
            return LB_UNKNOWN;
        }
        LB_COUNT(LB_CNT_LONG_LISTS, 1);
        extra = lb_over[cell].x - LB_SLOTS;
    }
    int inst = -1;
    TraceRay r;
    const bool boxed = c.x > LB_BOX_FROM;
    for (int k = 0; k < c.x; ++k) {
        const int t = k < LB_SLOTS ? lb_slots[cell * LB_SLOTS + k] : lb_extra[extra + k];
        if (boxed) {   /* the origin's point off the triangle's footprint: it cannot block */
            const float4 b = lb_boxes[m.box_base + t];
            if (cu < b.x || cv < b.y || cu > b.z || cv > b.w) continue;
        }
        const float4 p0 = lb_tris[3 * t], p1 = lb_tris[3 * t + 1], p2 = lb_tris[3 * t + 2];
        if (as_int(p0.w) != inst) {
            inst = as_int(p0.w);
            r = trace_object_ray(instances + inst, org, dir);
        }
        float th, uh, vh;
        if (trace_triangle(&r, p0.xyz, p1.xyz, p2.xyz, 0.0f, tmax, &th, &uh, &vh)) {
            LB_COUNT(LB_CNT_BLOCKED, 1);
            LB_COUNT(LB_CNT_TRIANGLES, k + 1);
            return LB_BLOCKED;
        }
    }
    LB_COUNT(LB_CNT_TESTED_CLEAR, 1);
    LB_COUNT(LB_CNT_TRIANGLES, c.x);
    return LB_CLEAR;
}

#endif
