/* A height field: a dynamic mesh that is a regular grid, traced by walking its cells instead of
   a BVH (raytrace.scene.Scene.add_mesh(..., grid=(nx, ny)); the water surface).

   The grid: nx x ny vertices, vertex (i, j) = index j*nx + i at x = x0 + i dx, z = z0 + j dz in
   object space (within HF_GRID_TOL cells; y free), quad q = j*(nx-1) + i holding triangles
   2q = (a, c, b) and 2q+1 = (b, c, d), a = (i, j), b = (i+1, j), c = (i, j+1), d = (i+1, j+1)
   (lbm.grid_triangles). Per frame, heightfield_bounds (heightfield.cl) reads the vertices once
   and writes the y range of every HF_BLOCK x HF_BLOCK block of cells and the box of the whole
   grid: that replaces the BVH refit. The walk (traverse_heightfield.h) reads the vertex buffer
   the writer fills, so the water's vertices exist once on the device. */
#ifndef LBWATER_HEIGHTFIELD_H
#define LBWATER_HEIGHTFIELD_H

#define HF_BLOCK 8      /* cells per side of a y-range block */
#define HF_WG 64        /* work-group of heightfield_bounds: one work-item per block */
#define HF_NONE (-1)    /* HeightField.mesh of a scene without a height field */
/* vertices may sit this many cells off the regular grid; the walk's cell ranges have a wider
   margin (HF_EPS, traverse_heightfield.h), so no triangle a ray hits is skipped */
#define HF_GRID_TOL 0.002f
/* HeightField.slope's factor over the regular grid's edge steps: vertices off the grid by
   HF_GRID_TOL change a triangle's gradient by under 2% */
#define HF_SLOPE_MARGIN 1.05f

/* 128 bytes: eight float4-sized rows.
   lo, hi: the vertices' box (w unused), from the last bounds pass;
   x0, z0: vertex (0, 0)'s x and z; cells_per_x, cells_per_z: 1 / dx, 1 / dz (from the corners);
   nx, ny: vertices along x (i) and z (j); nbx, nby: blocks along x and z;
   mesh: the mesh id traced as this height field (HF_NONE: none); n_bad: vertices of the last
   pass that are non-finite or off the grid (raytrace.scene.Scene.check raises on them);
   ticket, acc_bad, acc_lo, acc_hi, acc_rise_x, acc_rise_z: the pass's scratch (the last
   work-group to finish moves the accumulators into lo, hi, n_bad, slope and resets them: no
   reset launch);
   slope: a bound on every triangle's |grad y| over x and z, from the last pass: HF_SLOPE_MARGIN
   times the hypotenuse of the largest height step along an x edge over dx and along a z edge
   over dz (a triangle's gradient is one of each on the regular grid; the margin covers the
   off-grid tolerance), INFINITY where a vertex is not finite: hf_climbs. */
typedef struct {
    float4 lo;
    float4 hi;
    float x0;
    float z0;
    float cells_per_x;
    float cells_per_z;
    int nx;
    int ny;
    int nbx;
    int nby;
    int mesh;
    int n_bad;
    int ticket;
    int acc_bad;
    int4 acc_lo;
    int4 acc_hi;
    float slope;
    int acc_rise_x;
    int acc_rise_z;
    int pad0;
} HeightField;

/* Whether a straight ray along object-space direction d rises (sinks) faster than the grid's
   steepest triangle: then its height over the surface, y(t) - h(x(t), z(t)), grows (falls)
   with t (h is piecewise linear, its slope along d at most slope |d.xz|), so it crosses the
   surface at most once, upward (downward), and never where it starts over (under) it. The
   margin is wider than the rounding of slope and of d. */
inline bool hf_climbs(__global const HeightField* restrict hf, float3 d)
{
    return d.y > 0.0f && d.y > hf->slope * 1.0001f * sqrt(d.x * d.x + d.z * d.z);
}

inline bool hf_sinks(__global const HeightField* restrict hf, float3 d)
{
    return d.y < 0.0f && -d.y > hf->slope * 1.0001f * sqrt(d.x * d.x + d.z * d.z);
}

/* Which side of the surface object-space point o lies on: 1 over, -1 under, 0 not known. It
   compares o with the plane of the triangle of its cell it lies in (near the cell's diagonal,
   where the off-grid tolerance HF_GRID_TOL leaves that open, with both), by more than the
   rounding; not known off the grid, within HF_EPS_SIDE cells of a cell's edge (o may lie over
   a neighbouring cell) and within the rounding of the plane. */
#define HF_EPS_SIDE 0.01f
inline int hf_side(__global const HeightField* restrict hf, __global const float4* restrict verts,
                   float3 o)
{
    const float fu = (o.x - hf->x0) * hf->cells_per_x, fw = (o.z - hf->z0) * hf->cells_per_z;
    const int nx = hf->nx;
    if (!(fu >= 0.0f && fw >= 0.0f && fu < (float)(nx - 1) && fw < (float)(hf->ny - 1)))
        return 0;
    const int i = (int)fu, j = (int)fw;
    const float ru = fu - (float)i, rw = fw - (float)j;
    if (ru < HF_EPS_SIDE || ru > 1.0f - HF_EPS_SIDE || rw < HF_EPS_SIDE
        || rw > 1.0f - HF_EPS_SIDE)
        return 0;
    const int a = j * nx + i;
    const float3 pa = verts[a].xyz, pb = verts[a + 1].xyz, pc = verts[a + nx].xyz,
                 pd = verts[a + nx + 1].xyz;
    const float diag = ru + rw - 1.0f;   /* < 0: (a, c, b)'s side, > 0: (b, c, d)'s */
    float hmin = INFINITY, hmax = -INFINITY;
    for (int k = 0; k < 2; ++k) {   /* the triangles (a, c, b) and (b, c, d) */
        if (k ? diag < -2.0f * HF_EPS_SIDE : diag > 2.0f * HF_EPS_SIDE) continue;
        const float3 p0 = k ? pb : pa, p2 = k ? pd : pb;
        const float3 n = cross(pc - p0, p2 - p0);
        const float h = p0.y - (n.x * (o.x - p0.x) + n.z * (o.z - p0.z)) / n.y;
        hmin = fmin(hmin, h);
        hmax = fmax(hmax, h);
    }
    /* h's rounding: a few ulps of the larger of p0.y and the plane's rise (both small) */
    const float tol = 2e-6f * (fabs(o.y) + fmax(fabs(hmin), fabs(hmax))) + 1e-12f;
    return o.y > hmax + tol ? 1 : o.y < hmin - tol ? -1 : 0;
}

/* Whether o lies on the side of the surface that direction d leaves it toward: over it with
   d rising, under it with d sinking (hf_side; false where the side is not known). */
inline bool hf_departs(__global const HeightField* restrict hf,
                       __global const float4* restrict verts, float3 o, float3 d)
{
    const int side = hf_side(hf, verts, o);
    return side != 0 && (side > 0) == (d.y > 0.0f);
}

/* Whether the ray o + t d, t >= 0, cannot meet the surface: from over it rising faster than
   its slopes, or from under it sinking faster (trace_heightfield skips the walk then). */
inline bool hf_unreachable(__global const HeightField* restrict hf,
                           __global const float4* restrict verts, float3 o, float3 d)
{
    if (!(hf_climbs(hf, d) || hf_sinks(hf, d))) return false;
    return (d.y > 0.0f ? o.y > hf->hi.y : o.y < hf->lo.y) || hf_departs(hf, verts, o, d);
}

#endif
