/* The guard's action, decided on the device by lbm_reduce_final: copy the current state to the
 * checkpoint (save), the checkpoint back to the current state (restore), or nothing. A
 * device-to-device copy that the host never has to wait for. Launch: 1D over the cells.
 */
#include "lbm.h"

__kernel void lbm_guard_apply(__global float* f, __global float* h_buf, __global float* f_ckpt,
                              __global float* h_ckpt, const LbmParams p,
                              __global const LbmGuard* guard)
{
    const int n = get_global_id(0);
    if (n >= p.n_cells) return;
    const uint action = guard->action;
    if (action == LBM_GUARD_SAVE) {
        for (int a = 0; a < 9; ++a) f_ckpt[a * p.n_cells + n] = f[a * p.n_cells + n];
        h_ckpt[n] = h_buf[n];
    } else if (action == LBM_GUARD_RESTORE) {
        for (int a = 0; a < 9; ++a) f[a * p.n_cells + n] = f_ckpt[a * p.n_cells + n];
        h_buf[n] = h_ckpt[n];
    }
}
