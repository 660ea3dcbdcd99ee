/* One LABSWE time step, fused: pull-stream (with walls and the well-balanced bed force), moments,
 * limiter, BGK collision with drag. Two buffers: reads f_src (post-collision populations of the
 * last step at their origin cells), writes f_dst. Launch: 2D over (nx, ny).
 *
 * Defines: LBM_BOUNDARY (LBM_SLIP | LBM_NOSLIP), LBM_BED (0: flat bed, the bed force and the depth
 * buffers are skipped; 1: uneven bed, or a floating hull's pressure head added to the bed),
 * LBM_GUARD (1: limiter and local damping marks; 0: the plain scheme), LBM_FP16S (storage).
 *
 * Memory per cell and step: 9 float loads + 9 float stores (72 B; 36 B with LBM_FP16S); with
 * LBM_BED also the depth at t and the bed (8 B, neighbours come from cache) and the new depth
 * (4 B): 84 B; with LBM_GUARD the damping mark (1 B read, neighbours from cache, 1 B written).
 */
#include "lbm.h"

#ifndef LBM_BOUNDARY
#define LBM_BOUNDARY LBM_SLIP
#endif
#ifndef LBM_BED
#define LBM_BED 1
#endif

/* Population a arriving at (i, j): pulled from the upwind cell (i - cx, j - cy). Where that cell
 * lies outside, a wall sends it back: slip mirrors the crossing component (mx: direction with cx
 * negated, my: cy negated), noslip reverses it (opp). The bed force of the link, split with the
 * equilibrium weight w, makes a lake at rest an exact fixed point (REFERENCES.md sec. 1):
 *   F_a = -w_a G (h(x) + h(src)) / 2 (z(x) - z(src)),  zero for bounce-back (src = x),
 * evaluated as P_a(x) - P_a(src) - w_a G (h(x) + h(src)) / 2 (eta(x) - eta(src)) with the
 * equilibrium's pressure term P_a = w_a G h^2 / 2 and the surface eta = h + z (equal in exact
 * arithmetic), each term rounded to the quantum: the force is exactly antisymmetric per link
 * (volume is conserved to the bit) and over a lake at rest it is exactly the difference of the
 * rounded equilibria, so that lake stays an exact fixed point (lbm_collide). */
float lbm_pull(__global const LBM_FT* restrict f, __global const float* restrict h_src,
               __global const float* restrict bed, const LbmParams p, const int i, const int j,
               const int a, const int cx, const int cy, const int mx, const int my,
               const int opp, const float w, const float h_here, const float z_here,
               const float q, const float p_here)
{
    int si = i - cx, sj = j - cy, m = a;
    const int out_x = si < 0 || si >= p.nx;
    const int out_y = sj < 0 || sj >= p.ny;
#if LBM_BOUNDARY == LBM_NOSLIP
    if (out_x || out_y) {
        si = i;
        sj = j;
        m = opp;
    }
#else
    if (out_x && out_y) {
        si = i;
        sj = j;
        m = opp;
    } else if (out_x) {
        si = i;
        m = mx;
    } else if (out_y) {
        sj = j;
        m = my;
    }
#endif
    const int s = LBM_CELL(p, si, sj);
    float fa = lbm_load(f, m, s, p);
#if LBM_BED
    /* P_a as lbm_equilibrium computes it at rest (the same bits); p_here: P_a(x), rounded */
    const float h_s = h_src[s], z_s = bed[s];
    const float p_src = w * (0.5f * p.g_lat * h_s * h_s);
    /* eta(x) - eta(src) from the two exact differences: a single rounding */
    const float slope = w * (0.5f * p.g_lat) * (h_here + h_s) * ((h_here - h_s) + (z_here - z_s));
    fa += (p_here - lbm_quantize(p_src, q)) - lbm_quantize(slope, q);
#else
    (void)h_src;
    (void)bed;
    (void)w;
    (void)h_here;
    (void)z_here;
    (void)q;
    (void)p_here;
#endif
    return fa;
}

/* Collision of nine streamed populations in place with relaxation rate omega; returns the
 * depth after the limiter. With LBM_GUARD, a cell beyond the limits is set to the equilibrium of
 * its limited moments (*clamped = 1, *dh the depth the limiter added, *fr2 its Froude^2 before).
 * Delta form: each moving population gets d_a = omega (feq_a - f_a) + drag_a, with feq_a and
 * d_a rounded to the quantum (lbm_quantize), and the rest population -sum d_a, so the collision
 * changes no volume (exactly, with float32 storage) and a state at its (rounded) equilibrium is
 * an exact fixed point. */
float lbm_collide(float* f, const LbmParams p, const float omega, int* clamped, float* dh,
                  float* fr2, const float q)
{
    float h, mx, my;
    lbm_moments(f, &h, &mx, &my);
    float ux = mx / h, uy = my / h;
    float feq[9];
#if LBM_GUARD
    const float h0 = h;
    if (lbm_limit(&h, &ux, &uy, p)) {
        *clamped = 1;
        const float u2 = (mx * mx + my * my) / (h0 * h0);
        *fr2 = h0 > 0.0f ? u2 / (p.g_lat * h0) : 0.0f;  /* no Froude without depth */
        lbm_equilibrium(h, ux, uy, p.g_lat, feq);
        for (int a = 0; a < 9; ++a) f[a] = lbm_quantize(feq[a], q);
        /* the depth now stored (exact with float32 storage: a sum of multiples of q) */
        h = ((f[0] + f[1]) + (f[2] + f[3])) + ((f[4] + f[5]) + (f[6] + f[7])) + f[8];
        *dh = h - h0;
        return h;
    }
#else
    (void)clamped;
    (void)dh;
    (void)fr2;
#endif
    lbm_equilibrium(h, ux, uy, p.g_lat, feq);
    /* Linear drag: momentum change dM = -drag * (mx, my), split as w_a c_a.dM (sum = dM). */
    const float dmx = -p.drag * mx, dmy = -p.drag * my;
    float d[9];
    for (int a = 1; a < 9; ++a) feq[a] = lbm_quantize(feq[a], q);
    d[1] = omega * (feq[1] - f[1]) + LBM_W_AXIS * dmx;
    d[5] = omega * (feq[5] - f[5]) - LBM_W_AXIS * dmx;
    d[3] = omega * (feq[3] - f[3]) + LBM_W_AXIS * dmy;
    d[7] = omega * (feq[7] - f[7]) - LBM_W_AXIS * dmy;
    d[2] = omega * (feq[2] - f[2]) + LBM_W_DIAG * (dmx + dmy);
    d[6] = omega * (feq[6] - f[6]) - LBM_W_DIAG * (dmx + dmy);
    d[4] = omega * (feq[4] - f[4]) + LBM_W_DIAG * (dmy - dmx);
    d[8] = omega * (feq[8] - f[8]) - LBM_W_DIAG * (dmy - dmx);
    for (int a = 1; a < 9; ++a) d[a] = lbm_quantize(d[a], q);
    f[0] -= ((d[1] + d[5]) + (d[3] + d[7])) + ((d[2] + d[6]) + (d[4] + d[8]));
    for (int a = 1; a < 9; ++a) f[a] += d[a];
    return h;
}

/* The damping mark of cell (i, j) after this step: a clipped cell gets LBM_DAMP_STEPS; others
 * keep the larger of their own mark - 1 and the largest neighbour's - LBM_DAMP_SPREAD. */
int lbm_mark_spread(__global const uchar* restrict mark, const LbmParams p, const int i,
                    const int j, const int own)
{
    int nb = 0;
    for (int dj = -1; dj <= 1; ++dj) {
        const int jj = j + dj;
        if (jj < 0 || jj >= p.ny) continue;
        for (int di = -1; di <= 1; ++di) {
            const int ii = i + di;
            if (ii < 0 || ii >= p.nx || (di == 0 && dj == 0)) continue;
            nb = max(nb, (int)mark[LBM_CELL(p, ii, jj)]);
        }
    }
    return max(0, max(own - 1, nb - LBM_DAMP_SPREAD));
}

__kernel void lbm_step(__global const LBM_FT* restrict f_src, __global LBM_FT* restrict f_dst,
                       __global const float* restrict h_src, __global float* restrict h_dst,
                       __global const float* restrict bed,
                       __global const uchar* restrict mark_src, __global uchar* restrict mark_dst,
                       const LbmParams p, __global LbmGuard* guard)
{
    const int i = get_global_id(0), j = get_global_id(1);
    if (i >= p.nx || j >= p.ny) return;
    const int n = LBM_CELL(p, i, j);
#if LBM_BED
    const float h_here = h_src[n], z_here = bed[n];
#else
    const float h_here = 0.0f, z_here = 0.0f;
#endif
    const float wa = LBM_W_AXIS, wd = LBM_W_DIAG, q = p.quantum;
#if LBM_BED
    const float p_rest = 0.5f * p.g_lat * h_here * h_here;   /* P_a(x) / w_a, rounded below */
    const float pa = lbm_quantize(wa * p_rest, q), pd = lbm_quantize(wd * p_rest, q);
#else
    const float pa = 0.0f, pd = 0.0f;
#endif
    float f[9];
    /*                                           a  cx  cy mx my opp w */
    f[0] = lbm_load(f_src, 0, n, p);
    f[1] = lbm_pull(f_src, h_src, bed, p, i, j, 1, 1, 0, 5, 1, 5, wa, h_here, z_here, q, pa);
    f[2] = lbm_pull(f_src, h_src, bed, p, i, j, 2, 1, 1, 4, 8, 6, wd, h_here, z_here, q, pd);
    f[3] = lbm_pull(f_src, h_src, bed, p, i, j, 3, 0, 1, 3, 7, 7, wa, h_here, z_here, q, pa);
    f[4] = lbm_pull(f_src, h_src, bed, p, i, j, 4, -1, 1, 2, 6, 8, wd, h_here, z_here, q, pd);
    f[5] = lbm_pull(f_src, h_src, bed, p, i, j, 5, -1, 0, 1, 5, 1, wa, h_here, z_here, q, pa);
    f[6] = lbm_pull(f_src, h_src, bed, p, i, j, 6, -1, -1, 8, 4, 2, wd, h_here, z_here, q, pd);
    f[7] = lbm_pull(f_src, h_src, bed, p, i, j, 7, 0, -1, 7, 3, 3, wa, h_here, z_here, q, pa);
    f[8] = lbm_pull(f_src, h_src, bed, p, i, j, 8, 1, -1, 6, 2, 4, wd, h_here, z_here, q, pd);

    const float tau = guard->tau;
    int clamped = 0;
    float dh = 0.0f, fr2 = 0.0f;
#if LBM_GUARD
    const int own = mark_src[n];
    const float omega = 1.0f / (own > 0 ? fmax(tau, LBM_TAU_DAMPED) : tau);
#else
    const float omega = 1.0f / tau;
    (void)mark_src;
    (void)mark_dst;
#endif
    const float h = lbm_collide(f, p, omega, &clamped, &dh, &fr2, q);
#if LBM_GUARD
    if (clamped) {
        atomic_inc(&guard->clamped);
        lbm_account(guard, dh);
        if (fr2 > 0.0f) atomic_max((volatile __global uint*)&guard->peak_acc, as_uint(fr2));
    }
    mark_dst[n] = (uchar)(clamped ? LBM_DAMP_STEPS : lbm_mark_spread(mark_src, p, i, j, own));
#endif

    for (int a = 0; a < 9; ++a) lbm_store(f_dst, a, n, p, f[a]);
#if LBM_BED
    h_dst[n] = h;
#else
    (void)h;
    (void)h_dst;
#endif
}
