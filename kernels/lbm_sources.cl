/* Sources that change the water between steps: drops (add volume) and pushes (add momentum).
 * Both act on the stored post-collision populations of the current buffer, replacing their
 * equilibrium part (f += feq(h', U') - feq(h, U)) so the non-equilibrium part is kept. With
 * LBM_GUARD the new state passes through the limiter: a clipped cell counts in guard->clamped,
 * the depth it lost or gained goes to the volume account and the cell is marked for damping.
 * Work-item (0, 0) adds the volume the source asked for (s.volume) to guard->sources.
 * Launch: 2D over the source's cell box, starting at (s.i0, s.j0).
 */
#include "lbm.h"

/* Cell n's populations and their moments. */
void lbm_source_read(__global const LBM_FT* f, const LbmParams p, const int n, float* fl,
                     float* h, float* mx, float* my)
{
    for (int a = 0; a < 9; ++a) fl[a] = lbm_load(f, a, n, p);
    lbm_moments(fl, h, mx, my);
}

/* Move cell n from (h, U) to (h2, U2), after the limiter, keeping the non-equilibrium part.
 * Returns the new depth (as stored). */
float lbm_source_apply(__global LBM_FT* f, const LbmParams p, const int n, const float* fl,
                       const float h, const float ux, const float uy, float h2, float ux2,
                       float uy2, __global uchar* mark, __global LbmGuard* guard)
{
#if LBM_GUARD
    const float h_asked = h2;
    if (lbm_limit(&h2, &ux2, &uy2, p)) {
        atomic_inc(&guard->clamped);
        lbm_account(guard, h2 - h_asked);
        mark[n] = LBM_DAMP_STEPS;
    }
#else
    (void)mark;
    (void)guard;
#endif
    float feq_old[9], feq_new[9];
    lbm_equilibrium(h, ux, uy, p.g_lat, feq_old);
    lbm_equilibrium(h2, ux2, uy2, p.g_lat, feq_new);
    /* changes are multiples of the quantum (lbm.h lbm_quantize) and the rest population takes
     * the rounded change of depth less the others': a push changes no volume, exactly */
    const float q = p.quantum;
    float moved = 0.0f;
    for (int a = 1; a < 9; ++a) {
        const float da = lbm_quantize(feq_new[a] - feq_old[a], q);
        moved += da;
        lbm_store(f, a, n, p, fl[a] + da);
    }
    const float dh = lbm_quantize(h2 - h, q);
    lbm_store(f, 0, n, p, fl[0] + (dh - moved));
    return h + dh;
}

/* A drop: a raised-cosine bump dh = amount (1 + cos(pi r / radius)) / 2 for r < radius, added
 * at constant velocity. */
__kernel void lbm_drop(__global LBM_FT* f, __global float* h_buf, __global uchar* mark,
                       const LbmParams p, const LbmSource s, __global LbmGuard* guard)
{
    if (get_global_id(0) == 0 && get_global_id(1) == 0) guard->sources += s.volume;
    const int i = s.i0 + (int)get_global_id(0), j = s.j0 + (int)get_global_id(1);
    if (i < 0 || j < 0 || i >= p.nx || j >= p.ny) return;
    const float rx = ((float)i + 0.5f) * p.dx - s.x, ry = ((float)j + 0.5f) * p.dx - s.y;
    const float r = sqrt(rx * rx + ry * ry);
    if (r >= s.radius) return;
    const float dh = s.amount * 0.5f * (1.0f + cospi(r / s.radius));
    const int n = LBM_CELL(p, i, j);
    float fl[9], h, mx, my;
    lbm_source_read(f, p, n, fl, &h, &mx, &my);
    const float ux = mx / h, uy = my / h;
    h_buf[n] = lbm_source_apply(f, p, n, fl, h, ux, uy, h + dh, ux, uy, mark, guard);
}

/* A push along a drag: every cell within radius of the segment from (x, y) to (x + dx, y + dy)
 * gains the velocity amount * (1 - (d / radius)^2)^2 along the drag (d: distance to the
 * segment), at constant depth. */
__kernel void lbm_push(__global LBM_FT* f, __global float* h_buf, __global uchar* mark,
                       const LbmParams p, const LbmSource s, __global LbmGuard* guard)
{
    const int i = s.i0 + (int)get_global_id(0), j = s.j0 + (int)get_global_id(1);
    if (i < 0 || j < 0 || i >= p.nx || j >= p.ny) return;
    const float len2 = s.dx * s.dx + s.dy * s.dy;
    if (!(len2 > 0.0f)) return;
    const float px = ((float)i + 0.5f) * p.dx - s.x, py = ((float)j + 0.5f) * p.dx - s.y;
    const float t = clamp((px * s.dx + py * s.dy) / len2, 0.0f, 1.0f);
    const float qx = px - t * s.dx, qy = py - t * s.dy;
    const float d2 = (qx * qx + qy * qy) / (s.radius * s.radius);
    if (d2 >= 1.0f) return;
    /* velocity change in lattice units along the unit drag direction */
    const float k = (1.0f - d2) * (1.0f - d2) * s.amount / p.e / sqrt(len2);
    const int n = LBM_CELL(p, i, j);
    float fl[9], h, mx, my;
    lbm_source_read(f, p, n, fl, &h, &mx, &my);
    const float ux = mx / h, uy = my / h;
    h_buf[n] = lbm_source_apply(f, p, n, fl, h, ux, uy, h, ux + k * s.dx, uy + k * s.dy, mark,
                                guard);
}
