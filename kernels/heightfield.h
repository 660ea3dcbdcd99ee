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

/* 112 bytes: seven float4-sized rows.
   lo, hi: the vertices' box (w unused), from the last bounds pass;
   x0, z0: vertex (0, 0)'s x and z; cells_per_x, cells_per_z: 1 / dx, 1 / dz (from the corners);
   nx, ny: vertices along x (i) and z (j); nbx, nby: blocks along x and z;
   mesh: the mesh id traced as this height field (HF_NONE: none); n_bad: vertices of the last
   pass that are non-finite or off the grid (raytrace.scene.Scene.check raises on them);
   ticket, acc_bad, acc_lo, acc_hi: the pass's scratch (the last work-group to finish moves the
   accumulators into lo, hi, n_bad and zeroes them: no reset launch). */
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
} HeightField;

#endif
