/* The guard's device reduction: total depth (mass, a compensated sum), max (|u|/e)^2, max
 * Froude^2, min depth, the count of non-finite cells and of cells with a damping mark, in two
 * stages (no float atomics):
 * lbm_reduce_partial (many work-groups of LBM_REDUCE_WG, grid-stride over the cells) then
 * lbm_reduce_final (one work-group) which also keeps the volume budget and decides the guard's
 * action (lbm_guard.cl applies it). The guard never changes tau: damping is local (lbm_step.cl).
 */
#include "lbm.h"

/* Accumulators are LbmPartial values (lbm.h), the layout the partials are stored in. */
#define LBM_ACC_ZERO {0.0f, 0.0f, 0.0f, INFINITY, 0u, 0u, 0.0f, 0u}

/* The depth sum as a float pair (hi, lo): hi + x by Knuth's TwoSum, its rounding error into lo
 * (exact; FP_CONTRACT is off in lbm.h). A plain float32 sum of 10^6 depths is off by up to
 * ~1e-7 of the total, the size of the volume drift the guard watches for. */
void lbm_sum2(float* hi, float* lo, const float x)
{
    const float s = *hi + x;
    const float bp = s - *hi;
    *lo += (*hi - (s - bp)) + (x - bp);
    *hi = s;
}

void lbm_acc_merge(LbmPartial* a, const LbmPartial b)
{
    lbm_sum2(&a->mass, &a->mass_lo, b.mass);
    a->mass_lo += b.mass_lo;
    a->max_u2 = fmax(a->max_u2, b.max_u2);
    a->max_fr2 = fmax(a->max_fr2, b.max_fr2);
    a->min_h = fmin(a->min_h, b.min_h);
    a->nan_cells += b.nan_cells;
    a->damped_cells += b.damped_cells;
}

/* Tree reduction of one work-group's accumulators; the result is valid in work-item 0. */
LbmPartial lbm_acc_reduce_local(LbmPartial acc, __local float* l_mass, __local float* l_lo,
                                __local float* l_u2, __local float* l_fr2, __local float* l_h,
                                __local uint* l_nan, __local uint* l_damp)
{
    const int lid = get_local_id(0);
    l_mass[lid] = acc.mass;
    l_lo[lid] = acc.mass_lo;
    l_u2[lid] = acc.max_u2;
    l_fr2[lid] = acc.max_fr2;
    l_h[lid] = acc.min_h;
    l_nan[lid] = acc.nan_cells;
    l_damp[lid] = acc.damped_cells;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = LBM_REDUCE_WG / 2; s > 0; s >>= 1) {
        if (lid < s) {
            float hi = l_mass[lid], lo = l_lo[lid] + l_lo[lid + s];
            lbm_sum2(&hi, &lo, l_mass[lid + s]);
            l_mass[lid] = hi;
            l_lo[lid] = lo;
            l_u2[lid] = fmax(l_u2[lid], l_u2[lid + s]);
            l_fr2[lid] = fmax(l_fr2[lid], l_fr2[lid + s]);
            l_h[lid] = fmin(l_h[lid], l_h[lid + s]);
            l_nan[lid] += l_nan[lid + s];
            l_damp[lid] += l_damp[lid + s];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    LbmPartial out = {l_mass[0], l_u2[0], l_fr2[0], l_h[0], l_nan[0], l_damp[0], l_lo[0], 0u};
    return out;
}

#define LBM_LOCALS                                                                             \
    __local float l_mass[LBM_REDUCE_WG], l_lo[LBM_REDUCE_WG], l_u2[LBM_REDUCE_WG],           \
        l_fr2[LBM_REDUCE_WG], l_h[LBM_REDUCE_WG];                                              \
    __local uint l_nan[LBM_REDUCE_WG], l_damp[LBM_REDUCE_WG]

__kernel __attribute__((reqd_work_group_size(LBM_REDUCE_WG, 1, 1)))
void lbm_reduce_partial(__global const LBM_FT* restrict f, __global const uchar* restrict mark,
                        const LbmParams p, __global LbmPartial* partials)
{
    LBM_LOCALS;
    LbmPartial acc = LBM_ACC_ZERO;
    for (int n = get_global_id(0); n < p.n_cells; n += get_global_size(0)) {
        float fl[9], h, mx, my;
        for (int a = 0; a < 9; ++a) fl[a] = lbm_load(f, a, n, p);
        lbm_moments(fl, &h, &mx, &my);
#if LBM_GUARD
        acc.damped_cells += mark[n] > 0 ? 1u : 0u;
#else
        (void)mark;
#endif
        if (!(isfinite(h) && isfinite(mx) && isfinite(my))) {
            acc.nan_cells += 1u;
            continue;
        }
        lbm_sum2(&acc.mass, &acc.mass_lo, h);
        acc.min_h = fmin(acc.min_h, h);
        if (h > 0.0f) {
            const float u2 = (mx * mx + my * my) / (h * h);
            acc.max_u2 = fmax(acc.max_u2, u2);
            acc.max_fr2 = fmax(acc.max_fr2, u2 / (p.g_lat * h));
        }
    }
    acc = lbm_acc_reduce_local(acc, l_mass, l_lo, l_u2, l_fr2, l_h, l_nan, l_damp);
    if (get_local_id(0) == 0) {
        partials[get_group_id(0)] = acc;
    }
}

/* The reduced partials acc into the guard record, and the decision: non-finite cells -> restore the
 * checkpoint (LBM_GUARD only; the volume it changes is booked as clipped or created so the
 * budget mass0 + sources - clipped + created = mass holds); a clean interval (no NaN, no clamp)
 * -> save a checkpoint when asked (save: LBM_SAVE_*; LBM_SAVE_FORCE saves whatever the interval
 * was). The first check after set_state (checks == 0) sets mass0. */
void lbm_guard_decide(__global LbmGuard* g, const LbmPartial acc, const int save)
{
    if (g->checks == 0u) g->mass0 = acc.mass;
    g->checks += 1u;
    g->nan_cells = acc.nan_cells;
    g->damped_cells = acc.damped_cells;
    if (acc.damped_cells > 0u) g->damped += 1u;
    const int clipped = g->clamped != g->clamped_checked;
    const int clean = acc.nan_cells == 0u && !clipped;
    g->clamped_checked = g->clamped;
    /* the limiter's peak Froude^2 over the current run of intervals with clips */
    g->peak_fr2 = clipped ? fmax(g->peak_fr2, g->peak_acc) : 0.0f;
    g->peak_acc = 0.0f;
#if LBM_GUARD
    if (acc.nan_cells > 0u) {
        g->action = LBM_GUARD_RESTORE;
        g->restored += 1u;
        /* the state is now the checkpoint's; book the volume the restore changed */
        const float expected = g->mass0 + g->sources - g->clipped + g->created;
        const float delta = g->ckpt_mass - expected;
        if (delta > 0.0f) g->created += delta;
        else g->clipped -= delta;
        g->mass = g->ckpt_mass;
        g->max_u2 = g->ckpt_max_u2;
        g->max_fr2 = g->ckpt_max_fr2;
        g->min_h = g->ckpt_min_h;
        return;
    }
#endif
    g->mass = acc.mass;
    g->max_u2 = acc.max_u2;
    g->max_fr2 = acc.max_fr2;
    g->min_h = acc.min_h;
#if LBM_GUARD
    if (save == LBM_SAVE_FORCE || (save == LBM_SAVE_IF_CLEAN && clean)) {
        g->action = LBM_GUARD_SAVE;
        g->saved += 1u;
        g->ckpt_mass = acc.mass;
        g->ckpt_max_u2 = acc.max_u2;
        g->ckpt_max_fr2 = acc.max_fr2;
        g->ckpt_min_h = acc.min_h;
        return;
    }
#else
    (void)save;
    (void)clean;
#endif
    g->action = LBM_GUARD_NONE;
}

/* The statistics of the partials and the decision (lbm_guard_decide) into the guard record g,
 * and a copy of the record into snapshot: the record as of this check for a reader on another
 * queue, which the next steps' counts must not reach (the World's read-back). */
__kernel __attribute__((reqd_work_group_size(LBM_REDUCE_WG, 1, 1)))
void lbm_reduce_final(__global const LbmPartial* partials, const int n_partials,
                      __global LbmGuard* g, const int save, __global LbmGuard* snapshot)
{
    LBM_LOCALS;
    LbmPartial acc = LBM_ACC_ZERO;
    for (int k = get_local_id(0); k < n_partials; k += LBM_REDUCE_WG) {
        lbm_acc_merge(&acc, partials[k]);
    }
    acc = lbm_acc_reduce_local(acc, l_mass, l_lo, l_u2, l_fr2, l_h, l_nan, l_damp);
    if (get_local_id(0) != 0) return;
    acc.mass += acc.mass_lo;   /* the pair's float32 value */
    lbm_guard_decide(g, acc, save);
    *snapshot = *g;
}
