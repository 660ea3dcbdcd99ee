/* The walk of a height field (heightfield.h): the ray, in the grid's object space, is clipped to
   the grid's box, then its cells are visited in the ray's order, a column at a time along the
   horizontal axis the ray moves faster on ("u"; the other is "w"). A column's cells are those
   the ray passes over while inside it (one or two, three with the margins); a cell's two
   triangles are tested only when the ray's height over the column meets the cell's y range.
   Columns go HF_BLOCK at a time: a span whose blocks' y ranges the ray misses is skipped whole,
   so a ray crosses the grid's slab in a few steps where the water is flat. A ray that starts
   in the slab and departs from the surface (over it and rising, under it and sinking; the
   water's reflections, refractions and shadow rays, as a rule) faster than every slope walks
   nothing, and faster than the slopes of a span's blocks skips that span, up to the first span
   it walks (heightfield.h: hf_climbs, hf_departs; the blocks' slope bounds).

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
/* 1: a ray that cannot meet the surface (hf_unreachable) walks nothing; 0: every ray walks
   (the A/B: the same hits) */
#ifndef HF_CULL_UNREACHABLE
#define HF_CULL_UNREACHABLE 1
#endif
/* 1: with the cull, a walk from the surface skips the spans whose blocks slope less than the ray
   departs, up to the first span it walks; 0: it walks them (the A/B: the same hits) */
#ifndef HF_SKIP_SPANS
#define HF_SKIP_SPANS HF_CULL_UNREACHABLE
#endif

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

/* Closest (or, with any, some) hit of the grid, same contract as trace_blas: shrinks *tmax to
   each closer hit and records it in *hit. r: the object-space ray prepared for the triangle
   test; o, d: its origin and direction. */
TRACE_INLINE bool trace_heightfield(__global const HeightField* restrict hf,
                                    __global const float4* restrict verts,
                                    __global const float4* restrict blocks, const TraceRay* r,
                                    float3 o, float3 d, float tmin, float* tmax, Hit* hit, int inst,
                                    bool any, __global int* restrict stats)
{
    /* the grid's box: entry ta and exit tb (NaN-safe as trace_box) */
    const float3 lo = hf->lo.xyz, hi = hf->hi.xyz;
    const int3 neg = r->idir < 0.0f;
    const float3 tn = ((neg ? hi : lo) - r->org) * r->idir;
    const float3 tf = ((neg ? lo : hi) - r->org) * r->idir * TRACE_BOX_GROW;
    const float ta = TRACE_MAX(tn.x, TRACE_MAX(tn.y, TRACE_MAX(tn.z, tmin)));
    const float tb = TRACE_MIN(tf.x, TRACE_MIN(tf.y, TRACE_MIN(tf.z, *tmax)));
    if (!(ta <= tb)) return false;
#if HF_CULL_UNREACHABLE
    /* A ray from the slab that departs from the surface (over it and rising, under it and
       sinking: a reflection or refraction off the water, a shadow ray from it) faster than
       every slope meets nothing; faster than a span's blocks slope, it meets nothing there and
       stays on its side (clear: 1, -1 while its side is not looked up), up to the first span
       it walks. One from outside the slab that reached the box here may meet it (a camera
       ray); one whose walk starts past its origin (tmin > 0) may have crossed before. */
    int clear = 0;   /* read only where HF_SKIP_SPANS */
    if (o.y >= lo.y && o.y <= hi.y && tmin <= 0.0f) {
        if (!(hf_climbs(hf, d) || hf_sinks(hf, d))) {
            clear = -1;
        } else if (hf_departs(hf, verts, o, d)) {
#if TRACE_COUNT
            atomic_inc(stats + TRACE_STAT_HF_CULLED);
#endif
            return false;
        }
    }
#if HF_SKIP_SPANS
    const float run = 1.0001f * sqrt(d.x * d.x + d.z * d.z);
#endif
#endif
    const int nx = hf->nx, ny = hf->ny, nbx = hf->nbx;
    /* u along x (cells i) or along z (cells j): the axis the ray crosses more cells of */
    const bool ux = fabs(d.x * hf->cells_per_x) >= fabs(d.z * hf->cells_per_z);
    const float cu = ux ? hf->cells_per_x : hf->cells_per_z;
    const float cw = ux ? hf->cells_per_z : hf->cells_per_x;
    const float u_o = ((ux ? o.x : o.z) - (ux ? hf->x0 : hf->z0)) * cu;
    const float w_o = ((ux ? o.z : o.x) - (ux ? hf->z0 : hf->x0)) * cw;
    const float u_d = (ux ? d.x : d.z) * cu, w_d = (ux ? d.z : d.x) * cw;
    const int nu = (ux ? nx : ny) - 1, nw = (ux ? ny : nx) - 1;
    /* the columns from entry to exit, in the ray's order */
    const float ua = u_o + ta * u_d, ub = u_o + tb * u_d;
    const int step = u_d < 0.0f ? -1 : 1;
    const int c_first = clamp((int)floor(ua - (float)step * HF_EPS), 0, nu - 1);
    const int c_last = clamp((int)floor(ub + (float)step * HF_EPS), 0, nu - 1);
    if ((c_last - c_first) * step < 0) return false;
    bool found = false;
    /* spans of the columns of one block */
    for (int s0 = c_first;;) {
        const int block_u = s0 / HF_BLOCK;
        const int edge = step > 0 ? block_u * HF_BLOCK + HF_BLOCK - 1 : block_u * HF_BLOCK;
        const int s1 = step > 0 ? min(edge, c_last) : max(edge, c_last);
        float t0, t1;
        hf_span(u_o, u_d, min(s0, s1), max(s0, s1), ta, tb, &t0, &t1);
        if (t0 > *tmax) break; /* every later column is beyond the closest hit */
        int r0, r1;
        hf_rows(w_o, w_d, t0, t1, nw, &r0, &r1);
        float2 y = hf_heights(o.y, d.y, t0, t1);
        bool meets = false;
        float steep = 0.0f;
        for (int br = r0 / HF_BLOCK; br <= r1 / HF_BLOCK; ++br) {
            const float4 by = blocks[ux ? br * nbx + block_u : block_u * nbx + br];
            meets = meets || (by.y >= y.x && by.x <= y.y);
            steep = fmax(steep, by.z);
        }
#if HF_CULL_UNREACHABLE && HF_SKIP_SPANS
        if (meets && clear != 0 && fabs(d.y) > steep * run) {
            if (clear < 0) clear = hf_departs(hf, verts, o, d);
            meets = clear == 0;
#if TRACE_COUNT
            if (!meets) atomic_inc(stats + TRACE_STAT_HF_SKIPPED);
#endif
        }
        if (meets) clear = 0;
#endif
        if (meets) {
            for (int c = s0;; c += step) {
                hf_span(u_o, u_d, c, c, ta, tb, &t0, &t1);
                if (t0 > *tmax) return found;
                hf_rows(w_o, w_d, t0, t1, nw, &r0, &r1);
                y = hf_heights(o.y, d.y, t0, t1);
                for (int row = r0; row <= r1; ++row) {
                    const bool got = hf_cell(verts, nx, ux ? c : row, ux ? row : c, r, tmin, tmax,
                                             hit, inst, any, y.x, y.y);
                    if (got) {
                        found = true;
                        if (any) return true;
                    }
                }
                if (c == s1) break;
            }
        }
        if (s1 == c_last) break;
        s0 = s1 + step;
    }
    return found;
}

#endif
