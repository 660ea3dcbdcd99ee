/* The guard's action, decided on the device by lbm_reduce_final: copy the current state to the
 * checkpoint (save), the checkpoint back to the current state (restore), or nothing. A
 * device-to-device copy that the host never has to wait for; populations are copied as raw
 * words (LBM_RAW: the storage's bits). A restored cell that was non-finite is marked for a longer
 * local damping (LBM_DAMP_NAN_STEPS). Launch: 1D over the cells.
 */
#include "lbm.h"

__kernel void lbm_guard_apply(__global LBM_RAW* f, __global float* h_buf,
                              __global LBM_RAW* f_ckpt, __global float* h_ckpt,
                              __global uchar* mark, const LbmParams p,
                              __global const LbmGuard* guard)
{
    const int n = get_global_id(0);
    if (n >= p.n_cells) return;
    const uint action = guard->action;
    if (action == LBM_GUARD_SAVE) {
        for (int a = 0; a < 9; ++a) f_ckpt[a * p.n_cells + n] = f[a * p.n_cells + n];
        h_ckpt[n] = h_buf[n];
    } else if (action == LBM_GUARD_RESTORE) {
        float h = 0.0f;
        for (int a = 0; a < 9; ++a) h += lbm_load((__global const LBM_FT*)f, a, n, p);
        if (!isfinite(h)) mark[n] = LBM_DAMP_NAN_STEPS;
        for (int a = 0; a < 9; ++a) f[a * p.n_cells + n] = f_ckpt[a * p.n_cells + n];
        h_buf[n] = h_ckpt[n];
    }
}
