/* Macroscopic fields in SI units from the stored populations: depth h (m), velocity u, v (m/s)
 * along the grid's x (i) and y (j). Used by ShallowWater.fields(), not inside a frame.
 * Launch: 1D over the cells.
 */
#include "lbm.h"

__kernel void lbm_fields(__global const LBM_FT* restrict f, const LbmParams p,
                         __global float* h_out, __global float* u_out, __global float* v_out)
{
    const int n = get_global_id(0);
    if (n >= p.n_cells) return;
    float fl[9], h, mx, my;
    for (int a = 0; a < 9; ++a) fl[a] = lbm_load(f, a, n, p);
    lbm_moments(fl, &h, &mx, &my);
    h_out[n] = h;
    u_out[n] = p.e * mx / h;
    v_out[n] = p.e * my / h;
}
