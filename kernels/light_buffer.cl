/* Light-buffer stage (light_buffer.h): the opaque triangles' shadows, cell by cell, for each
 * directional light with a map. Launch order per frame (raytrace/light_buffer.py,
 * LightBuffer.enqueue), no host sync:
 *   light_buffer_clear   every map's cells: no triangle, depth bound -inf; the counters after
 *                        them (LightBuffer.outside_cell, big_cell): 0
 *   light_buffer_raster  per map: a work-item per triangle moves it to world space by its
 *                        instance's transform row (as the TLAS build and the shader do), projects
 *                        it across the light and lists it in every cell its footprint (grown by
 *                        the margin) touches, raising the cell's depth bound to the most the
 *                        triangle's plane reaches over the cell (or its nearest vertex); a
 *                        triangle over more than LB_SMALL_CELLS cells is left to
 *   light_buffer_raster_big  a work-group per such triangle (a boat's sail), or the whole
 *                        launch, one after the other, for those over LB_MEDIUM_CELLS (the pool's
 *                        floor and walls)
 *                        Both list each (triangle, cell) past a cell's LB_SLOTS in lb_pairs.
 *   light_buffer_fine    per map: a work-item per cell hands each full cell (more than LB_SLOTS
 *                        triangles) a fine grid while the map's last, empties it, lists its
 *                        slots' triangles in lb_pairs too, and puts the grid's number in its
 *                        first slot
 *   light_buffer_fine_raster  LB_FINE work-items per pair list the triangle in the fine cells it
 *                        meets, a row each: every triangle of a full cell with a grid, in
 *                        parallel however many cells the triangle covers (a raster pass over
 *                        the triangles, one after another in a work-item, took 20 times longer
 *                        for the pool's floating boat on the H200: BENCHMARKS.md)
 * The order in which triangles land in a cell's slots varies, and so does which full cells get
 * a grid when they run out; what a query answers does not. */
#include "common.h"
#include "transform.h"
#include "light_buffer.h"

__kernel void light_buffer_clear(__global int2* restrict lb_cells, const uint n_cells,
                                 const uint n_map_cells)
{
    const int2 empty = (int2)(0, float_to_ordered(-INFINITY));
    for (uint i = get_global_id(0); i < n_cells; i += get_global_size(0))
        lb_cells[i] = i < n_map_cells ? empty : (int2)(0);   /* after the maps: counters */
}

/* Whether the triangle (a, b, c) in cell coordinates meets the square [lo, hi] (separating axes:
 * the square's two, the triangle's three edge normals; a degenerate triangle loses no overlap). */
inline bool lb_overlaps(float2 a, float2 b, float2 c, float2 lo, float2 hi)
{
    const float2 mid = 0.5f * (lo + hi), ext = 0.5f * (hi - lo);
    const float2 e[3] = {b - a, c - b, a - c};
    for (int k = 0; k < 3; ++k) {
        const float2 n = (float2)(e[k].y, -e[k].x);
        const float pa = dot(n, a), pb = dot(n, b), pc = dot(n, c);
        const float r = ext.x * fabs(n.x) + ext.y * fabs(n.y), pm = dot(n, mid);
        if (fmin(pa, fmin(pb, pc)) > pm + r || fmax(pa, fmax(pb, pc)) < pm - r) return false;
    }
    return true;
}

/* Triangle t of lb_tris projected across map m: its cells' box, its depths and the depth's
 * plane over the map where it is well shaped (its height at least 1% of its extent). */
typedef struct {
    float2 a, b, c;    /* the vertices in cell coordinates */
    float s0, smax;    /* depth of a, the nearest vertex's */
    float slack;       /* the bound's growth: rounding */
    float2 g;          /* d(depth)/d(cu, cv), where plane */
    bool plane;
    int i0, j0, w, n;  /* first cell, cells across, cells in the box (0: off the map) */
    float2 lo, hi;     /* the box in cell coordinates, grown by the margin */
} LbTriangle;

inline LbTriangle lb_project(const LightBuffer* m, __global const float4* restrict lb_tris,
                             __global const Transform* restrict xforms, uint t,
                             __global int* restrict cells, bool count_outside)
{
    LbTriangle o;
    o.n = 0;
    const float4 q0 = lb_tris[3 * t], q1 = lb_tris[3 * t + 1], q2 = lb_tris[3 * t + 2];
    const Transform x = xforms[as_int(q0.w)];
    const float3 p0 = xform_point(x, q0.xyz), p1 = xform_point(x, q1.xyz),
                 p2 = xform_point(x, q2.xyz);
    o.a = (float2)(dot(p0, m->u.xyz) + m->u.w, dot(p0, m->v.xyz) + m->v.w);
    o.b = (float2)(dot(p1, m->u.xyz) + m->u.w, dot(p1, m->v.xyz) + m->v.w);
    o.c = (float2)(dot(p2, m->u.xyz) + m->u.w, dot(p2, m->v.xyz) + m->v.w);
    const float s0 = dot(p0, m->toward.xyz), s1 = dot(p1, m->toward.xyz),
                s2 = dot(p2, m->toward.xyz);
    o.s0 = s0;
    o.smax = fmax(s0, fmax(s1, s2));
    o.slack = m->depth_slack + 1e-4f * (o.smax - fmin(s0, fmin(s1, s2)));
    const float2 lo = o.lo = fmin(o.a, fmin(o.b, o.c)) - m->margin;
    const float2 hi = o.hi = fmax(o.a, fmax(o.b, o.c)) + m->margin;
    if (!(all(isfinite(lo)) && all(isfinite(hi)) && isfinite(o.smax))) return o;
    if (count_outside
        && (lo.x < 0.0f || lo.y < 0.0f || hi.x >= (float)m->n_u || hi.y >= (float)m->n_v))
        atomic_inc(cells + 2 * m->outside_cell);
    o.i0 = max((int)floor(lo.x), 0);
    o.j0 = max((int)floor(lo.y), 0);
    const int i1 = min((int)floor(hi.x), m->n_u - 1), j1 = min((int)floor(hi.y), m->n_v - 1);
    if (i1 < o.i0 || j1 < o.j0) return o;
    o.w = i1 - o.i0 + 1;
    o.n = o.w * (j1 - o.j0 + 1);
    const float2 ab = o.b - o.a, ac = o.c - o.a;
    const float det = ab.x * ac.y - ab.y * ac.x;
    const float span = fmax(hi.x - lo.x, hi.y - lo.y);
    o.plane = fabs(det) >= 0.01f * span * span;
    o.g = o.plane ? (float2)((s1 - s0) * ac.y - (s2 - s0) * ab.y,
                             (s2 - s0) * ab.x - (s1 - s0) * ac.x) / det
                  : (float2)(0.0f);
    return o;
}

/* Row b of the fine grid g of full cell (i, j): list triangle t in the fine cells its footprint
 * meets. A fine cell's box is exact in floats ((i LB_FINE + a) / LB_FINE), and grows by the same
 * margin as a cell's: the fine cell a query reads holds its origin's projection. */
inline void lb_insert_fine_row(const LightBuffer* m, const LbTriangle* o, uint t, int i, int j,
                               int g, int b, __global int* restrict cells,
                               __global int* restrict lb_slots)
{
    const float2 lo = o->lo, hi = o->hi;
    const float y0 = (float)(j * LB_FINE + b) / (float)LB_FINE - m->margin;
    const float y1 = (float)(j * LB_FINE + b + 1) / (float)LB_FINE + m->margin;
    if (hi.y < y0 || lo.y > y1) return;
    const int a0 = max((int)floor((lo.x - (float)i) * LB_FINE), 0);
    const int a1 = min((int)floor((hi.x - (float)i) * LB_FINE), LB_FINE - 1);
    for (int a = a0; a <= a1; ++a) {
        const float2 flo = (float2)((float)(i * LB_FINE + a) / (float)LB_FINE - m->margin, y0);
        const float2 fhi = (float2)((float)(i * LB_FINE + a + 1) / (float)LB_FINE + m->margin,
                                    y1);
        if (!lb_overlaps(o->a, o->b, o->c, flo, fhi)) continue;
        const int f = lb_fine_cell(m, g, b, a);
        const int slot = atomic_inc(cells + 2 * f);
        if (slot < LB_FINE_SLOTS) lb_slots[f * LB_SLOTS + slot] = (int)t;
    }
}

/* Cell k of the triangle's box: list triangle t there when its footprint meets the cell; past
 * the cell's slots, the pair (t, cell) in lb_pairs for its fine grid. */
inline void lb_insert(const LightBuffer* m, const LbTriangle* o, uint t, int k,
                      __global int* restrict cells, __global int* restrict lb_slots,
                      __global int2* restrict lb_pairs)
{
    const int i = o->i0 + k % o->w, j = o->j0 + k / o->w;
    const float2 clo = (float2)((float)i, (float)j) - m->margin;
    const float2 chi = (float2)((float)(i + 1), (float)(j + 1)) + m->margin;
    if (!lb_overlaps(o->a, o->b, o->c, clo, chi)) return;
    float bound = o->smax;
    if (o->plane) {   /* the plane's most over the cell's corners, at most the nearest vertex */
        const float2 d0 = clo - o->a, d1 = chi - o->a;
        const float reach = fmax(o->g.x * d0.x, o->g.x * d1.x) + fmax(o->g.y * d0.y, o->g.y * d1.y);
        bound = fmin(bound, o->s0 + reach);
    }
    const int cell = m->cell_base + j * m->n_u + i;
    const int slot = atomic_inc(cells + 2 * cell);
    if (slot < LB_SLOTS) {
        lb_slots[cell * LB_SLOTS + slot] = (int)t;
    } else {
        const int p = atomic_inc(cells + 2 * m->fine_cell + 1);
        if (p < m->fine_pairs) lb_pairs[p] = (int2)((int)t, cell);
    }
    atomic_max(cells + 2 * cell + 1, float_to_ordered(bound + o->slack));
}

__kernel void light_buffer_raster(__global const LightBuffer* restrict lb_maps, const uint light,
                                  __global const float4* restrict lb_tris, const uint n_tris,
                                  __global const Transform* restrict xforms,
                                  __global int2* restrict lb_cells,
                                  __global int* restrict lb_slots, __global uint* restrict lb_big,
                                  __global int2* restrict lb_pairs)
{
    const LightBuffer m = lb_maps[light];
    __global int* cells = (__global int*)lb_cells;
    for (uint t = get_global_id(0); t < n_tris; t += get_global_size(0)) {
        const LbTriangle o = lb_project(&m, lb_tris, xforms, t, cells, true);
        if (o.n > LB_MEDIUM_CELLS)   /* huge: from the list's back */
            lb_big[n_tris - 1u - atomic_inc(cells + 2 * m.big_cell + 1)] = t;
        else if (o.n > LB_SMALL_CELLS)   /* medium: from its front */
            lb_big[atomic_inc(cells + 2 * m.big_cell)] = t;
        else
            for (int k = 0; k < o.n; ++k) lb_insert(&m, &o, t, k, cells, lb_slots, lb_pairs);
    }
}

/* Every full cell of map `light`: a fine grid, while the map's fine_grids last, its fine cells
 * emptied and its slots' triangles listed in lb_pairs; then its number in the cell's first
 * slot, which a full cell's query does not read as a triangle (-1: none). */
__kernel void light_buffer_fine(__global const LightBuffer* restrict lb_maps, const uint light,
                                __global int2* restrict lb_cells, __global int* restrict lb_slots,
                                __global int2* restrict lb_pairs)
{
    const LightBuffer m = lb_maps[light];
    __global int* cells = (__global int*)lb_cells;
    const int n = m.n_u * m.n_v;
    for (int c = get_global_id(0); c < n; c += get_global_size(0)) {
        const int cell = m.cell_base + c;
        if (lb_cells[cell].x <= LB_SLOTS) continue;
        const int g = atomic_inc(cells + 2 * m.fine_cell);
        if (g < m.fine_grids) {
            for (int f = 0; f < LB_FINE_CELLS; ++f)
                lb_cells[lb_fine_cell(&m, g, f / LB_FINE, f % LB_FINE)] = (int2)(0);
            const int p = atomic_add(cells + 2 * m.fine_cell + 1, LB_SLOTS);
            for (int k = 0; k < LB_SLOTS && p + k < m.fine_pairs; ++k)
                lb_pairs[p + k] = (int2)(lb_slots[cell * LB_SLOTS + k], cell);
        }
        lb_slots[cell * LB_SLOTS] = g < m.fine_grids ? g : -1;
    }
}

/* The pairs' triangles in their full cells' fine grids: work-item r of a pair takes row r. */
__kernel void light_buffer_fine_raster(__global const LightBuffer* restrict lb_maps,
                                       const uint light, __global const float4* restrict lb_tris,
                                       __global const Transform* restrict xforms,
                                       __global int2* restrict lb_cells,
                                       __global int* restrict lb_slots,
                                       __global const int2* restrict lb_pairs)
{
    const LightBuffer m = lb_maps[light];
    __global int* cells = (__global int*)lb_cells;
    const int listed = lb_cells[m.fine_cell].y;
    if (listed > m.fine_pairs) return;   /* some were left out: no grid is read */
    for (int q = get_global_id(0); q < listed * LB_FINE; q += get_global_size(0)) {
        const int2 pair = lb_pairs[q / LB_FINE];
        const int g = lb_slots[pair.y * LB_SLOTS];
        if (g < 0) continue;
        const LbTriangle o = lb_project(&m, lb_tris, xforms, (uint)pair.x, cells, false);
        const int c = pair.y - m.cell_base;
        lb_insert_fine_row(&m, &o, (uint)pair.x, c % m.n_u, c / m.n_u, g, q % LB_FINE, cells,
                           lb_slots);
    }
}

/* The triangles light_buffer_raster left: the huge ones one after the other, each one's cells
 * spread over the whole launch, then the medium ones a work-group each. */
__kernel void light_buffer_raster_big(__global const LightBuffer* restrict lb_maps,
                                      const uint light, __global const float4* restrict lb_tris,
                                      const uint n_tris, __global const Transform* restrict xforms,
                                      __global int2* restrict lb_cells,
                                      __global int* restrict lb_slots,
                                      __global const uint* restrict lb_big,
                                      __global int2* restrict lb_pairs)
{
    const LightBuffer m = lb_maps[light];
    __global int* cells = (__global int*)lb_cells;
    const int2 n_big = lb_cells[m.big_cell];   /* x: medium, y: huge */
    /* light_buffer_raster counted their reach off the map */
    for (int b = 0; b < n_big.y; ++b) {
        const uint t = lb_big[n_tris - 1u - (uint)b];
        const LbTriangle o = lb_project(&m, lb_tris, xforms, t, cells, false);
        for (int k = get_global_id(0); k < o.n; k += get_global_size(0))
            lb_insert(&m, &o, t, k, cells, lb_slots, lb_pairs);
    }
    for (int b = get_group_id(0); b < n_big.x; b += get_num_groups(0)) {   /* uniform */
        const uint t = lb_big[b];
        const LbTriangle o = lb_project(&m, lb_tris, xforms, t, cells, false);
        for (int k = get_local_id(0); k < o.n; k += get_local_size(0))
            lb_insert(&m, &o, t, k, cells, lb_slots, lb_pairs);
    }
}

/* The map's answer beside the BVH's for n shadow rays from org[i] toward light `light` (tests:
 * tests/raytrace/test_light_buffer.py): out[i] = (light_buffer_blocked, any-hit of `mask`). */
__kernel void light_buffer_answers(SCENE_PARAMS, LIGHT_BUFFER_PARAMS, const uint light,
                                   const uint mask, __global const float4* restrict org,
                                   const uint n, __global int2* restrict out)
{
    const uint i = get_global_id(0);
    if (i >= n) return;
    const float3 o = org[i].xyz, d = lb_maps[light].toward.xyz;
    out[i] = (int2)(light_buffer_blocked(LIGHT_BUFFER_ARGS, instances, light, o, d, INFINITY,
                                         trace_stats),
                    scene_any_hit_masked(SCENE_ARGS, o, d, 0.0f, INFINITY, mask,
                                         TRACE_KIND_QUERY) ? 1 : 0);
}
