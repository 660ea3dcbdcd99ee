/* The walk of a height field (heightfield.h): the ray, in the grid's object space, is clipped to
   the grid's box, then its cells are visited in the ray's order, a column at a time along the
   horizontal axis the ray moves faster on ("u"; the other is "w"). A column's cells are those
   the ray passes over while inside it (one or two, three with the margins); a cell's two
   triangles are tested only when the ray's height over the column meets the cell's y range.
   Columns go HF_BLOCK at a time: a span whose blocks' y ranges the ray misses is skipped whole,
   so a ray crosses the grid's slab in a few steps where the water is flat.

   Every range has a margin of HF_EPS cells, wider than the rounding of the ray's cell
   coordinates and the grid's own tolerance (HF_GRID_TOL), so no triangle the ray hits is left
   out; the triangle test is trace_triangle on the very vertex floats a BVH leaf would hold, and
   the acceptance rule is trace_blas's (ties: the smaller (inst, prim), trace_tie_wins). The walk
   stops at the first column entered beyond the closest hit. So the hit is the one the BVH gives
   on the binary layout, t bit for bit, and the same triangle except at a tie (a shared vertex or
   edge hit at exactly one distance), where this walk keeps the smallest prim of those hit and
   the BVH's may keep another (its box test can drop a box entered at exactly the hit's
   distance) (tests/raytrace/test_heightfield.py). */
#ifndef LBWATER_TRAVERSE_HEIGHTFIELD_H
#define LBWATER_TRAVERSE_HEIGHTFIELD_H

#define HF_EPS 0.01f /* cells */

/* The triangles of cell (i, j) if the ray's heights [ylo, yhi] meet the cell's. */
TRACE_INLINE bool hf_cell(__global const float4* restrict verts, int nx, int i, int j,
                          const TraceRay* r, float tmin, float* tmax, Hit* hit, int inst, bool any,
                          float ylo, float yhi)
{
    const int a = j * nx + i;
    const float4 pa = verts[a], pb = verts[a + 1], pc = verts[a + nx], pd = verts[a + nx + 1];
    if (fmax(fmax(pa.y, pb.y), fmax(pc.y, pd.y)) < ylo
        || fmin(fmin(pa.y, pb.y), fmin(pc.y, pd.y)) > yhi)
        return false;
    const int q = 2 * (j * (nx - 1) + i);
    bool found = false;
    for (int k = 0; k < 2; ++k) {
        const float3 p0 = k ? pb.xyz : pa.xyz, p2 = k ? pd.xyz : pb.xyz;
        const int prim = q + k;
        const bool have = hit->prim >= 0;
        float t, u, v;
        if (trace_triangle(r, p0, pc.xyz, p2, tmin, have ? nextafter(*tmax, INFINITY) : *tmax,
                           &t, &u, &v)
            && (!have || t < *tmax || trace_tie_wins(inst, prim, hit))) {
            *tmax = t;
            hit->t = t;
            hit->u = u;
            hit->v = v;
            hit->prim = prim;
            hit->inst = inst;
            found = true;
            if (any) return true;
        }
    }
    return found;
}

/* The t range [*t0, *t1] of the ray inside cells [c0, c1 + 1] along u (with the margin),
   within [ta, tb]; u_d == 0 (a vertical ray): all of [ta, tb]. */
TRACE_INLINE void hf_span(float u_o, float u_d, int c0, int c1, float ta, float tb, float* t0,
                          float* t1)
{
    if (u_d == 0.0f) {
        *t0 = ta;
        *t1 = tb;
        return;
    }
    const float ea = ((float)c0 - HF_EPS - u_o) / u_d, eb = ((float)(c1 + 1) + HF_EPS - u_o) / u_d;
    *t0 = fmax(fmin(ea, eb), ta);
    *t1 = fmin(fmax(ea, eb), tb);
}

/* Rows [*r0, *r1] (cells along w) under the ray over [t0, t1], with the margin, clamped. */
TRACE_INLINE void hf_rows(float w_o, float w_d, float t0, float t1, int nw, int* r0, int* r1)
{
    const float wa = w_o + t0 * w_d, wb = w_o + t1 * w_d;
    *r0 = clamp((int)floor(fmin(wa, wb) - HF_EPS), 0, nw - 1);
    *r1 = clamp((int)floor(fmax(wa, wb) + HF_EPS), 0, nw - 1);
}

/* The ray's heights over [t0, t1], widened by more than their rounding. */
TRACE_INLINE float2 hf_heights(float oy, float dy, float t0, float t1)
{
    const float y0 = oy + t0 * dy, y1 = oy + t1 * dy;
    const float tol = 1e-5f * (1.0f + fabs(oy) + fabs(y0) + fabs(y1));
    return (float2)(fmin(y0, y1) - tol, fmax(y0, y1) + tol);
}

/* A ray's walk of the grid, prepared: its t range in the grid's box, the axes, and its
   columns from entry to exit as spans of at most HF_BLOCK (one block's columns each). */
typedef struct {
    float ta, tb;          /* the ray inside the grid's box */
    float u_o, u_d, w_o, w_d, oy, dy;   /* the ray in cell units along u and w; its heights */
    int nx, nbx, nw, step; /* vertices along x, blocks along x, cells along w, column step */
    int c_first, c_last;   /* the first and last column, in the ray's order */
    int n_spans;           /* spans from c_first to c_last (0: the ray misses the box) */
    bool ux;               /* u along x (cells i), else along z (cells j) */
} HfWalk;

TRACE_INLINE HfWalk hf_walk_setup(__global const HeightField* restrict hf, const TraceRay* r,
                                  float3 o, float3 d, float tmin, float tmax)
{
    HfWalk w;
    w.n_spans = 0;
    /* the grid's box: entry ta and exit tb (NaN-safe as trace_box) */
    const float3 lo = hf->lo.xyz, hi = hf->hi.xyz;
    const int3 neg = r->idir < 0.0f;
    const float3 tn = ((neg ? hi : lo) - r->org) * r->idir;
    const float3 tf = ((neg ? lo : hi) - r->org) * r->idir * TRACE_BOX_GROW;
    w.ta = TRACE_MAX(tn.x, TRACE_MAX(tn.y, TRACE_MAX(tn.z, tmin)));
    w.tb = TRACE_MIN(tf.x, TRACE_MIN(tf.y, TRACE_MIN(tf.z, tmax)));
    if (!(w.ta <= w.tb)) return w;
    const int nx = hf->nx, ny = hf->ny;
    w.nx = nx;
    w.nbx = hf->nbx;
    /* u along x (cells i) or along z (cells j): the axis the ray crosses more cells of */
    w.ux = fabs(d.x * hf->cells_per_x) >= fabs(d.z * hf->cells_per_z);
    const float cu = w.ux ? hf->cells_per_x : hf->cells_per_z;
    const float cw = w.ux ? hf->cells_per_z : hf->cells_per_x;
    w.u_o = ((w.ux ? o.x : o.z) - (w.ux ? hf->x0 : hf->z0)) * cu;
    w.w_o = ((w.ux ? o.z : o.x) - (w.ux ? hf->z0 : hf->x0)) * cw;
    w.u_d = (w.ux ? d.x : d.z) * cu;
    w.w_d = (w.ux ? d.z : d.x) * cw;
    w.oy = o.y;
    w.dy = d.y;
    const int nu = (w.ux ? nx : ny) - 1;
    w.nw = (w.ux ? ny : nx) - 1;
    /* the columns from entry to exit, in the ray's order */
    const float ua = w.u_o + w.ta * w.u_d, ub = w.u_o + w.tb * w.u_d;
    w.step = w.u_d < 0.0f ? -1 : 1;
    w.c_first = clamp((int)floor(ua - (float)w.step * HF_EPS), 0, nu - 1);
    w.c_last = clamp((int)floor(ub + (float)w.step * HF_EPS), 0, nu - 1);
    if ((w.c_last - w.c_first) * w.step < 0) return w;
    w.n_spans = (w.c_last / HF_BLOCK - w.c_first / HF_BLOCK) * w.step + 1;
    return w;
}

/* Span k's first and last column, in the ray's order. */
TRACE_INLINE void hf_span_columns(const HfWalk* w, int k, int* s0, int* s1)
{
    const int block_u = w->c_first / HF_BLOCK + k * w->step;
    const int first = block_u * HF_BLOCK, last = first + HF_BLOCK - 1;
    *s0 = k == 0 ? w->c_first : (w->step > 0 ? first : last);
    const int edge = w->step > 0 ? last : first;
    *s1 = w->step > 0 ? min(edge, w->c_last) : max(edge, w->c_last);
}

/* Span k of the walk: the triangles of its columns' cells under the ray, when the ray's heights
   meet its blocks' y ranges; shrinks *tmax and records hits as trace_blas. *beyond: the span, or
   a column of it, is entered past *tmax (every later span is too). */
TRACE_INLINE bool hf_walk_span(const HfWalk* w, int k, __global const float4* restrict verts,
                               __global const float2* restrict blocks, const TraceRay* r,
                               float tmin, float* tmax, Hit* hit, int inst, bool any,
                               bool* beyond)
{
    int s0, s1;
    hf_span_columns(w, k, &s0, &s1);
    const int block_u = s0 / HF_BLOCK;
    float t0, t1;
    hf_span(w->u_o, w->u_d, min(s0, s1), max(s0, s1), w->ta, w->tb, &t0, &t1);
    *beyond = t0 > *tmax;
    if (*beyond) return false;
    int r0, r1;
    hf_rows(w->w_o, w->w_d, t0, t1, w->nw, &r0, &r1);
    float2 y = hf_heights(w->oy, w->dy, t0, t1);
    bool meets = false;
    for (int br = r0 / HF_BLOCK; br <= r1 / HF_BLOCK && !meets; ++br) {
        const float2 by = blocks[w->ux ? br * w->nbx + block_u : block_u * w->nbx + br];
        meets = by.y >= y.x && by.x <= y.y;
    }
    if (!meets) return false;
    bool found = false;
    for (int c = s0;; c += w->step) {
        hf_span(w->u_o, w->u_d, c, c, w->ta, w->tb, &t0, &t1);
        if (t0 > *tmax) {
            *beyond = true;
            return found;
        }
        hf_rows(w->w_o, w->w_d, t0, t1, w->nw, &r0, &r1);
        y = hf_heights(w->oy, w->dy, t0, t1);
        for (int row = r0; row <= r1; ++row) {
            if (hf_cell(verts, w->nx, w->ux ? c : row, w->ux ? row : c, r, tmin, tmax, hit, inst,
                        any, y.x, y.y)) {
                found = true;
                if (any) return true;
            }
        }
        if (c == s1) break;
    }
    return found;
}

/* Closest (or, with any, some) hit of the grid, same contract as trace_blas: shrinks *tmax to
   each closer hit and records it in *hit. r: the object-space ray prepared for the triangle
   test; o, d: its origin and direction. */
TRACE_INLINE bool trace_heightfield(__global const HeightField* restrict hf,
                                    __global const float4* restrict verts,
                                    __global const float2* restrict blocks, const TraceRay* r,
                                    float3 o, float3 d, float tmin, float* tmax, Hit* hit, int inst,
                                    bool any)
{
    const HfWalk w = hf_walk_setup(hf, r, o, d, tmin, *tmax);
    bool found = false;
    for (int k = 0; k < w.n_spans; ++k) {
        bool beyond;
        if (hf_walk_span(&w, k, verts, blocks, r, tmin, tmax, hit, inst, any, &beyond)) {
            found = true;
            if (any) return true;
        }
        if (beyond) break;
    }
    return found;
}

#endif
