/* The water surface as a mesh in world units (Y up), written into buffers the caller owns:
 * vertex (i, j) = index j*nx + i at (ox + (i+1/2) dx, oy + bed + h, oz + (j+1/2) dx, 0), and
 * unit normals from central differences of the surface height (the wall mirrors the height, so
 * the outside neighbour of an edge cell is the cell itself). Two launches: lbm_surface_height
 * (one read of the populations per cell) then lbm_surface_mesh. A non-finite depth is written as
 * zero depth, so no NaN ever reaches a vertex.
 */
#include "lbm.h"

/* eta = bed + h. Launch: 1D over the cells. */
__kernel void lbm_surface_height(__global const LBM_FT* restrict f,
                                 __global const float* restrict bed, const LbmParams p,
                                 __global float* eta)
{
    const int n = get_global_id(0);
    if (n >= p.n_cells) return;
    float h = 0.0f;
    for (int a = 0; a < 9; ++a) h += lbm_load(f, a, n, p);
    eta[n] = bed[n] + (isfinite(h) ? h : 0.0f);
}

/* Vertices (and normals when write_normals != 0) from eta. Launch: 2D over (nx, ny). */
__kernel void lbm_surface_mesh(__global const float* restrict eta, const LbmParams p,
                               const float4 origin, __global float4* vertices,
                               __global float4* normals, const int write_normals)
{
    const int i = get_global_id(0), j = get_global_id(1);
    if (i >= p.nx || j >= p.ny) return;
    const int n = LBM_CELL(p, i, j);
    vertices[n] = (float4)(origin.x + ((float)i + 0.5f) * p.dx, origin.y + eta[n],
                           origin.z + ((float)j + 0.5f) * p.dx, 0.0f);
    if (!write_normals) return;
    const float e_w = eta[LBM_CELL(p, max(i - 1, 0), j)];
    const float e_e = eta[LBM_CELL(p, min(i + 1, p.nx - 1), j)];
    const float e_s = eta[LBM_CELL(p, i, max(j - 1, 0))];
    const float e_n = eta[LBM_CELL(p, i, min(j + 1, p.ny - 1))];
    const float gx = (e_e - e_w) / (2.0f * p.dx), gz = (e_n - e_s) / (2.0f * p.dx);
    normals[n] = (float4)(normalize((float3)(-gx, 1.0f, -gz)), 0.0f);
}
