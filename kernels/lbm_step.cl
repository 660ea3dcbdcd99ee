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

/* Population a arriving at (i, j) is pulled from the upwind cell (i - cx, j - cy). Where that
 * cell lies outside, a wall sends it back from (i, j) itself: slip mirrors the crossing component
 * (mx: direction with cx negated, my: cy negated), noslip reverses it (opp). Sets the source cell
 * (*si, *sj) and the direction *m stored there. */
void lbm_pull_source(const LbmParams p, const int i, const int j, const int a, const int cx,
                     const int cy, const int mx, const int my, const int opp, int* si, int* sj,
                     int* m)
{
    *si = i - cx;
    *sj = j - cy;
    *m = a;
    const int out_x = *si < 0 || *si >= p.nx;
    const int out_y = *sj < 0 || *sj >= p.ny;
#if LBM_BOUNDARY == LBM_NOSLIP
    (void)mx;
    (void)my;
    if (out_x || out_y) {
        *si = i;
        *sj = j;
        *m = opp;
    }
#else
    if (out_x && out_y) {
        *si = i;
        *sj = j;
        *m = opp;
    } else if (out_x) {
        *si = i;
        *m = mx;
    } else if (out_y) {
        *sj = j;
        *m = my;
    }
#endif
}

/* fa with the bed force of its link added, the link from a cell of depth h_s over bed z_s. The
 * force, split with the equilibrium weight w, makes a lake at rest an exact fixed point
 * (REFERENCES.md sec. 1):
 *   F_a = -w_a G (h(x) + h(src)) / 2 (z(x) - z(src)),  zero for bounce-back (src = x),
 * evaluated as P_a(x) - P_a(src) - w_a G (h(x) + h(src)) / 2 (eta(x) - eta(src)) with the
 * equilibrium's pressure term P_a = w_a G h^2 / 2 and the surface eta = h + z (equal in exact
 * arithmetic), each term rounded to the quantum: the force is exactly antisymmetric per link
 * (volume is conserved to the bit) and over a lake at rest it is exactly the difference of the
 * rounded equilibria, so that lake stays an exact fixed point (lbm_collide). p_here: P_a(x),
 * rounded. */
float lbm_bed_force(const float fa, const LbmParams p, const float w, const float h_here,
                    const float z_here, const float h_s, const float z_s, const float q,
                    const float p_here)
{
    /* P_a as lbm_equilibrium computes it at rest (the same bits) */
    const float p_src = w * (0.5f * p.g_lat * h_s * h_s);
    /* eta(x) - eta(src) from the two exact differences: a single rounding */
    const float slope = w * (0.5f * p.g_lat) * (h_here + h_s) * ((h_here - h_s) + (z_here - z_s));
    return fa + ((p_here - lbm_quantize(p_src, q)) - lbm_quantize(slope, q));
}

/* The eight moving links: X(a, cx, cy, mx, my, opp) for every direction a = 1..8. */
#define LBM_LINKS(X) \
    X(1, 1, 0, 5, 1, 5) X(2, 1, 1, 4, 8, 6) X(3, 0, 1, 3, 7, 7) X(4, -1, 1, 2, 6, 8) \
    X(5, -1, 0, 1, 5, 1) X(6, -1, -1, 8, 4, 2) X(7, 0, -1, 7, 3, 3) X(8, 1, -1, 6, 2, 4)

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

/* A window of the grid held in one buffer: origin (ox, oy), row width rw, rn cells (the stride
 * between population planes). The whole grid is (0, 0, nx, nx * ny); a work-group's tile with its
 * halo in local memory is smaller. Private to the device: never passed from the host. */
typedef struct {
    int ox, oy, rw, rn;
} LbmWindow;

LbmWindow lbm_window(const int ox, const int oy, const int rw, const int rn)
{
    LbmWindow w;
    w.ox = ox;
    w.oy = oy;
    w.rw = rw;
    w.rn = rn;
    return w;
}

/* Index of grid cell (i, j) in window w. */
#define LBM_AT(w, i, j) (((j) - (w).oy) * (w).rw + ((i) - (w).ox))


/* One link of lbm_stream: population a of cell (i, j) from its source cell, plus the bed force. */
#define LBM_PULL_LINK(a, cx, cy, mx, my, opp)                                                    \
    {                                                                                            \
        int si, sj, m;                                                                           \
        lbm_pull_source(p, i, j, a, cx, cy, mx, my, opp, &si, &sj, &m);                          \
        const int s = LBM_AT(w, si, sj);                                                         \
        fa[a] = LBM_LOAD_AT(f, m, s, w.rn, p);                                                    \
        if (LBM_BED)                                                                             \
            fa[a] = lbm_bed_force(fa[a], p, (a & 1) ? LBM_W_AXIS : LBM_W_DIAG, h_here, z_here,   \
                                  hs[s], zs[s], q, (a & 1) ? pa : pd);                           \
    }

/* NAME(f, hs, zs, w, p, i, j, fa): the nine populations fa of cell (i, j) after streaming, pulled
 * from the last step's populations f, depths hs and bed zs held for window w in SPACE memory (the
 * depths and the bed are read with LBM_BED only). */
#define LBM_DEFINE_STREAM(NAME, SPACE)                                                           \
    void NAME(SPACE const LBM_FT* restrict f, SPACE const float* restrict hs,                    \
              SPACE const float* restrict zs, const LbmWindow w, const LbmParams p, const int i, \
              const int j, float* fa)                                                            \
    {                                                                                            \
        const int n = LBM_AT(w, i, j);                                                           \
        const float q = p.quantum;                                                               \
        float h_here = 0.0f, z_here = 0.0f, pa = 0.0f, pd = 0.0f;                                \
        if (LBM_BED) {                                                                           \
            h_here = hs[n];                                                                      \
            z_here = zs[n];                                                                      \
            const float p_rest = 0.5f * p.g_lat * h_here * h_here; /* P_a(x) / w_a */            \
            pa = lbm_quantize(LBM_W_AXIS * p_rest, q);                                           \
            pd = lbm_quantize(LBM_W_DIAG * p_rest, q);                                           \
        }                                                                                        \
        fa[0] = LBM_LOAD_AT(f, 0, n, w.rn, p);                                                    \
        LBM_LINKS(LBM_PULL_LINK)                                                                 \
    }
LBM_DEFINE_STREAM(lbm_stream, __global)
LBM_DEFINE_STREAM(lbm_stream_local, __local)

/* NAME(mark, w, p, i, j): the largest damping mark among the eight neighbours of cell (i, j)
 * inside the grid, from the marks held for window w in SPACE memory. */
#define LBM_DEFINE_MARK_NEIGHBOURS(NAME, SPACE)                                                  \
    int NAME(SPACE const uchar* restrict mark, const LbmWindow w, const LbmParams p,             \
             const int i, const int j)                                                           \
    {                                                                                            \
        int nb = 0;                                                                              \
        for (int dj = -1; dj <= 1; ++dj) {                                                       \
            const int jj = j + dj;                                                               \
            if (jj < 0 || jj >= p.ny) continue;                                                  \
            for (int di = -1; di <= 1; ++di) {                                                   \
                const int ii = i + di;                                                           \
                if (ii < 0 || ii >= p.nx || (di == 0 && dj == 0)) continue;                      \
                nb = max(nb, (int)mark[LBM_AT(w, ii, jj)]);                                      \
            }                                                                                    \
        }                                                                                        \
        return nb;                                                                               \
    }
LBM_DEFINE_MARK_NEIGHBOURS(lbm_mark_neighbours, __global)
LBM_DEFINE_MARK_NEIGHBOURS(lbm_mark_neighbours_local, __local)

/* The damping mark of a cell after this step: a clipped cell gets LBM_DAMP_STEPS; others keep
 * the larger of their own mark - 1 and the largest neighbour's (nb) - LBM_DAMP_SPREAD. */
int lbm_mark_next(const int clamped, const int own, const int nb)
{
    return clamped ? LBM_DAMP_STEPS : max(0, max(own - 1, nb - LBM_DAMP_SPREAD));
}

/* The collision of one cell's streamed populations fa (lbm_collide) with the guard's part: the
 * relaxation rate from tau and the cell's damping mark own (LBM_GUARD), a clamped cell counted
 * and its volume booked in the guard record when count is set (a halo cell, computed again by
 * the work-group that owns it, is not). Returns the depth; *clamped: the limiter acted. */
float lbm_relax(float* fa, const LbmParams p, const float tau, const int own,
                __global LbmGuard* guard, const int count, int* clamped)
{
    float dh = 0.0f, fr2 = 0.0f;
    *clamped = 0;
#if LBM_GUARD
    const float omega = 1.0f / (own > 0 ? fmax(tau, LBM_TAU_DAMPED) : tau);
#else
    const float omega = 1.0f / tau;
    (void)own;
#endif
    const float h = lbm_collide(fa, p, omega, clamped, &dh, &fr2, p.quantum);
#if LBM_GUARD
    if (*clamped && count) {
        atomic_inc(&guard->clamped);
        lbm_account(guard, dh);
        if (fr2 > 0.0f) atomic_max((volatile __global uint*)&guard->peak_acc, as_uint(fr2));
    }
#else
    (void)guard;
    (void)count;
#endif
    return h;
}

__kernel void lbm_step(__global const LBM_FT* restrict f_src, __global LBM_FT* restrict f_dst,
                       __global const float* restrict h_src, __global float* restrict h_dst,
                       __global const float* restrict bed,
                       __global const uchar* restrict mark_src, __global uchar* restrict mark_dst,
                       const LbmParams p, __global LbmGuard* guard)
{
    const int i = get_global_id(0), j = get_global_id(1);
    if (i >= p.nx || j >= p.ny) return;
    const LbmWindow grid = lbm_window(0, 0, p.nx, p.n_cells);
    const int n = LBM_CELL(p, i, j);
    float f[9];
    lbm_stream(f_src, h_src, bed, grid, p, i, j, f);
    const int own = LBM_GUARD ? mark_src[n] : 0;
    int clamped;
    const float h = lbm_relax(f, p, guard->tau, own, guard, 1, &clamped);
#if LBM_GUARD
    mark_dst[n] = (uchar)lbm_mark_next(clamped, own,
                                       clamped ? 0 : lbm_mark_neighbours(mark_src, grid, p, i, j));
#else
    (void)mark_dst;
#endif
    for (int a = 0; a < 9; ++a) lbm_store(f_dst, a, n, p, f[a]);
    if (LBM_BED) h_dst[n] = h;
}

/* Two steps in one launch (temporal blocking): a work-group of LBM_TILE_X x LBM_TILE_Y cells
 * loads its tile with a halo of two cells into local memory, takes the first step on the tile
 * and a halo of one (the halo cells are computed again, the same bits, by the groups that own
 * them, which alone count them in the guard), then the second step on the tile, and writes only
 * that: the state of two lbm_step launches, bit for bit, with one read and one write of the
 * grid instead of two. Launch: 2D over (nx, ny) rounded up to the tile, local size the tile. */
#ifndef LBM_TILE_X
#define LBM_TILE_X 32
#endif
#ifndef LBM_TILE_Y
#define LBM_TILE_Y 8
#endif
#define LBM_TILE_CELLS (LBM_TILE_X * LBM_TILE_Y)
#define LBM_W0 (LBM_TILE_X + 4)   /* the loaded window: the tile and two cells around */
#define LBM_N0 (LBM_W0 * (LBM_TILE_Y + 4))
#define LBM_W1 (LBM_TILE_X + 2)   /* the first step's window: the tile and one cell around */
#define LBM_N1 (LBM_W1 * (LBM_TILE_Y + 2))
/* Local storage of a population: the buffer's bits (half is no array type in OpenCL C). */
#if LBM_FP16S
#define LBM_LOCAL_FT ushort
#else
#define LBM_LOCAL_FT float
#endif

__kernel __attribute__((reqd_work_group_size(LBM_TILE_X, LBM_TILE_Y, 1)))
void lbm_step2(__global const LBM_FT* restrict f_src, __global LBM_FT* restrict f_dst,
               __global const float* restrict h_src, __global float* restrict h_dst,
               __global const float* restrict bed,
               __global const uchar* restrict mark_src, __global uchar* restrict mark_dst,
               const LbmParams p, __global LbmGuard* guard)
{
    __local LBM_LOCAL_FT f0[9 * LBM_N0], f1[9 * LBM_N1];
    __local float h0[LBM_BED ? LBM_N0 : 1], z0[LBM_BED ? LBM_N0 : 1];
    __local float h1[LBM_BED ? LBM_N1 : 1], z1[LBM_BED ? LBM_N1 : 1];
    __local uchar m0[LBM_GUARD ? LBM_N0 : 1], m1[LBM_GUARD ? LBM_N1 : 1];
    __local const LBM_FT* lf0 = (__local const LBM_FT*)f0;
    __local LBM_FT* lf1 = (__local LBM_FT*)f1;
    const int lx = get_local_id(0), ly = get_local_id(1);
    const int x0 = get_group_id(0) * LBM_TILE_X, y0 = get_group_id(1) * LBM_TILE_Y;
    const LbmWindow w0 = lbm_window(x0 - 2, y0 - 2, LBM_W0, LBM_N0);
    const LbmWindow w1 = lbm_window(x0 - 1, y0 - 1, LBM_W1, LBM_N1);
    const float tau = guard->tau;

    /* the grid's cells of window 0, as stored */
    for (int r = ly * LBM_TILE_X + lx; r < LBM_N0; r += LBM_TILE_CELLS) {
        const int i = w0.ox + r % LBM_W0, j = w0.oy + r / LBM_W0;
        if (i < 0 || i >= p.nx || j < 0 || j >= p.ny) continue;
        const int n = LBM_CELL(p, i, j);
        for (int a = 0; a < 9; ++a)
            f0[a * LBM_N0 + r] = ((__global const LBM_LOCAL_FT*)f_src)[a * p.n_cells + n];
        if (LBM_BED) {
            h0[r] = h_src[n];
            z0[r] = bed[n];
        }
        if (LBM_GUARD) m0[r] = mark_src[n];
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    /* the first step on window 1 */
    for (int r = ly * LBM_TILE_X + lx; r < LBM_N1; r += LBM_TILE_CELLS) {
        const int ri = r % LBM_W1, rj = r / LBM_W1;
        const int i = w1.ox + ri, j = w1.oy + rj;
        if (i < 0 || i >= p.nx || j < 0 || j >= p.ny) continue;
        const int own_tile = ri >= 1 && ri <= LBM_TILE_X && rj >= 1 && rj <= LBM_TILE_Y;
        float f[9];
        lbm_stream_local(lf0, h0, z0, w0, p, i, j, f);
        const int own = LBM_GUARD ? m0[LBM_AT(w0, i, j)] : 0;
        int clamped;
        const float h = lbm_relax(f, p, tau, own, guard, own_tile, &clamped);
        if (LBM_GUARD)
            m1[r] = (uchar)lbm_mark_next(clamped, own,
                                         clamped ? 0 : lbm_mark_neighbours_local(m0, w0, p, i, j));
        for (int a = 0; a < 9; ++a) LBM_STORE_AT(lf1, a, r, w1.rn, p, f[a]);
        if (LBM_BED) {
            h1[r] = h;
            z1[r] = z0[LBM_AT(w0, i, j)];
        }
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    /* the second step on the tile */
    const int i = x0 + lx, j = y0 + ly;
    if (i >= p.nx || j >= p.ny) return;
    const int n = LBM_CELL(p, i, j);
    float f[9];
    lbm_stream_local(lf1, h1, z1, w1, p, i, j, f);
    const int own = LBM_GUARD ? m1[LBM_AT(w1, i, j)] : 0;
    int clamped;
    const float h = lbm_relax(f, p, tau, own, guard, 1, &clamped);
    if (LBM_GUARD) {
        const int nb = clamped ? 0 : lbm_mark_neighbours_local(m1, w1, p, i, j);
        mark_dst[n] = (uchar)lbm_mark_next(clamped, own, nb);
    }
    for (int a = 0; a < 9; ++a) lbm_store(f_dst, a, n, p, f[a]);
    if (LBM_BED) h_dst[n] = h;
}
