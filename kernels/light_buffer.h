/* The light buffer (Haines & Greenberg 1986): for a directional light, a map of cells across the
 * light's direction, each listing the opaque triangles whose shadow falls on it. Every point on a
 * light ray projects to the same cell, so a shadow ray toward that light can only be blocked by
 * the triangles its origin's cell lists: tested there (the traversal's own triangle test, in
 * each instance's object space, the same floats as its BLAS), the answer is the any-hit
 * traversal's, bit for bit, with no tree walked. A cell that lists more than LB_SLOTS
 * triangles (under a boat's rigging) has a fine grid of LB_FINE x LB_FINE cells of its own,
 * each listing the triangles that meet it, while the map's fine grids last. A fine cell that
 * lists more too, or an origin off the map while some triangle reached past it, says "unknown"
 * and the ray walks the BVH as before. Built on the device from the scene's transform rows
 * whenever they were written (light_buffer.cl); raytrace/light_buffer.py plans it. */
#ifndef LBWATER_LIGHT_BUFFER_H
#define LBWATER_LIGHT_BUFFER_H

#include "traverse.h"

/* triangles a cell lists; a cell with more says "unknown" (16 against 8: the baseline scene's
   shadow rays 2% faster on the H200, with half as many walks of the BVH: BENCHMARKS.md) */
#define LB_SLOTS 16
/* a triangle over more cells is rastered by a work-group (light_buffer_raster_big) */
#define LB_SMALL_CELLS 32
/* one over more cells by the whole launch */
#define LB_MEDIUM_CELLS 4096
/* a full cell's fine grid: LB_FINE x LB_FINE cells (on the baseline scene's map of 1024 cells,
   the queries that walk the BVH go from 1,005 to 63 of 99,133 in PoCL's counts: BENCHMARKS.md,
   thirteenth session) */
#define LB_FINE 8
#define LB_FINE_CELLS (LB_FINE * LB_FINE)
/* triangles a fine cell lists: the room of LB_FINE_STRIDE cells, whose entries it takes in
   lb_cells (a count in the first) and lb_slots (of the baseline scene's 91,584 fine cells, 5,200
   list more than 16 triangles and 512 more than 32) */
#define LB_FINE_SLOTS 32
#define LB_FINE_STRIDE (LB_FINE_SLOTS / LB_SLOTS)
/* light_buffer_blocked's answers */
#define LB_UNKNOWN (-1)
#define LB_CLEAR 0
#define LB_BLOCKED 1

/* 96 bytes. Light l's map (lb_maps[l]; n_u == 0: none, its rays walk the BVH). A point p lies
 * in cell (floor(cu), floor(cv)), cu = dot(p, u.xyz) + u.w, likewise cv; its depth toward the
 * light is dot(p, toward.xyz); in a full cell (i, j), in its fine cell (floor(LB_FINE (cu - i)),
 * floor(LB_FINE (cv - j))). */
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
    int fine_base;     /* the map's first fine cell in lb_cells (lb_fine_cell) */
    int fine_grids;    /* fine grids the map has room for */
    int fine_cell;     /* lb_cells[fine_cell]: x: fine grids handed out, y: (triangle, full
                          cell) pairs listed for them (light_buffer.cl) */
    int fine_pairs;    /* pairs the list has room for; past them no fine grid is read */
    int pad;
} LightBuffer;

/* The kernel parameters of a stage that reads the light buffer (shadow rays), and their names.
 * lb_cells[c]: x = triangles listed (the first LB_SLOTS in lb_slots[c * LB_SLOTS ..]),
 * y = float_to_ordered of the nearest-to-the-light depth any of them reaches over the cell (a
 * fine cell's: none); a full cell's first slot holds its fine grid (-1: none, the grids ran out),
 * read only while the pairs that filled the grids fit their list;
 * lb_tris: three float4 per listed triangle, its object-space vertices, p0.w = as_float(instance).
 */
#define LIGHT_BUFFER_PARAMS                                                                   \
    __global const LightBuffer* restrict lb_maps, __global const int2* restrict lb_cells,   \
        __global const int* restrict lb_slots, __global const float4* restrict lb_tris
#define LIGHT_BUFFER_ARGS lb_maps, lb_cells, lb_slots, lb_tris

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
#define LB_CNT_FINE 7

/* Fine cell (row b, column a) of fine grid g in lb_cells; its LB_FINE_SLOTS slots from
 * lb_slots[its index * LB_SLOTS]. */
inline int lb_fine_cell(const LightBuffer* m, int g, int b, int a)
{
    return m->fine_base + LB_FINE_STRIDE * (g * LB_FINE_CELLS + b * LB_FINE + a);
}

/* Map m's cell of org in lb_cells (its coordinates in *cu, *cv); -1 off the map (or no map). */
inline int lb_cell_of(const LightBuffer* m, float3 org, float* cu, float* cv)
{
    *cu = dot(org, m->u.xyz) + m->u.w;
    *cv = dot(org, m->v.xyz) + m->v.w;
    if (!(*cu >= 0.0f && *cu < (float)m->n_u && *cv >= 0.0f && *cv < (float)m->n_v)) return -1;
    return m->cell_base + (int)*cv * m->n_u + (int)*cu;
}

/* Whether org lies in a full cell of light l's map (its rays answered by a fine grid or a walk);
 * bench/shadow_lean_probe.py's order of rays. */
inline bool light_buffer_full(LIGHT_BUFFER_PARAMS, uint light, float3 org)
{
    const LightBuffer m = lb_maps[light];
    float cu, cv;
    const int cell = lb_cell_of(&m, org, &cu, &cv);
    return cell >= 0 && lb_cells[cell].x > LB_SLOTS;
}

/* Whether a shadow ray from org along dir (toward light l) within [0, tmax) is blocked by an
 * opaque triangle of the map: LB_BLOCKED, LB_CLEAR, or LB_UNKNOWN (no map, a full cell with no
 * fine grid or in a full fine cell, off a map that some triangle reached past): walk the BVH.
 * stats: the scene's trace_stats (TRACE_COUNT). */
inline int light_buffer_blocked(LIGHT_BUFFER_PARAMS, __global const Instance* restrict instances,
                                uint light, float3 org, float3 dir, float tmax,
                                __global int* restrict stats)
{
    const LightBuffer m = lb_maps[light];
    if (m.n_u == 0) return LB_UNKNOWN;
    float cu, cv;
    const int cell = lb_cell_of(&m, org, &cu, &cv);
    if (cell < 0) {
        LB_COUNT(LB_CNT_OFF_MAP, 1);
        return lb_cells[m.outside_cell].x ? LB_UNKNOWN : LB_CLEAR;
    }
    const int2 c = lb_cells[cell];
    if (c.x == 0) {
        LB_COUNT(LB_CNT_EMPTY, 1);
        return LB_CLEAR;
    }
    if (dot(org, m.toward.xyz) > ordered_to_float(c.y)) {
        LB_COUNT(LB_CNT_NEARER, 1);
        return LB_CLEAR;
    }
    int listed = cell, n = c.x;
    if (n > LB_SLOTS) {   /* its fine cell's list, where it has a fine grid */
        const int g = lb_slots[cell * LB_SLOTS];
        const bool fine = g >= 0 && lb_cells[m.fine_cell].y <= m.fine_pairs;
        if (fine) {
            /* cu - floor(cu) is exact (Sterbenz), and so is its product by LB_FINE */
            const int fu = min((int)((cu - floor(cu)) * LB_FINE), LB_FINE - 1);
            const int fv = min((int)((cv - floor(cv)) * LB_FINE), LB_FINE - 1);
            listed = lb_fine_cell(&m, g, fv, fu);
            n = lb_cells[listed].x;
            LB_COUNT(LB_CNT_FINE, 1);
        }
        if (!fine || n > LB_FINE_SLOTS) {
            LB_COUNT(LB_CNT_FULL, 1);
            return LB_UNKNOWN;
        }
    }
    int inst = -1;
    TraceRay r;
    for (int k = 0; k < n; ++k) {
        const int t = lb_slots[listed * LB_SLOTS + k];
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
    LB_COUNT(LB_CNT_TRIANGLES, n);
    return LB_CLEAR;
}

#endif
