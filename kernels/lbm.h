/* Shallow-water LBM (D2Q9 LABSWE, Zhou 2004): lattice constants, device structs, and the device
 * functions shared by every lbm_*.cl stage (equilibrium, moments, limiter).
 *
 * Units inside the kernels: lattice units for space and time (dx = dt = 1, so velocities are
 * fractions of the lattice speed e), metres for depth h and bed z. Hence g enters as
 * G = g / e^2 (1/m) and a population f_a is a depth in metres.
 *
 * Directions (Zhou's numbering): 0 rest; odd a are the axes, even a the diagonals, counter-
 * clockwise from +x: 1 (1,0) 2 (1,1) 3 (0,1) 4 (-1,1) 5 (-1,0) 6 (-1,-1) 7 (0,-1) 8 (1,-1).
 * Populations are stored structure-of-arrays: f[a * n_cells + j * nx + i].
 */
#ifndef LBWATER_LBM_H
#define LBWATER_LBM_H

#include "common.h"

/* No fused multiply-adds in the lbm kernels: lbm_quantize's rounding must not depend on the
 * compiler, and lbm.lattice.equilibrium_f32 mirrors lbm_equilibrium bit for bit. */
#pragma OPENCL FP_CONTRACT OFF

/* Wall kinds; equal to lbm.Boundary. */
#define LBM_SLIP 0
#define LBM_NOSLIP 1

/* Guard actions, equal to lbm.solver.GuardAction. */
#define LBM_GUARD_NONE 0
#define LBM_GUARD_SAVE 1
#define LBM_GUARD_RESTORE 2

/* Save requests of lbm_reduce_final: none, if the interval was clean, always. */
#define LBM_SAVE_NO 0
#define LBM_SAVE_IF_CLEAN 1
#define LBM_SAVE_FORCE 2

/* Local damping by the guard (never a global change of tau): a cell the limiter clipped is
 * marked LBM_DAMP_STEPS in the uchar damping mark; every step a mark decays by one and spreads
 * to the 8 neighbours as (mark - LBM_DAMP_SPREAD), so the clipped cell and its neighbours relax
 * with tau = max(tau, LBM_TAU_DAMPED) for a few steps. Cells found non-finite (restored from the
 * checkpoint) are marked LBM_DAMP_NAN_STEPS, a longer and wider damping. */
#define LBM_DAMP_STEPS 8
#define LBM_DAMP_SPREAD 4
#define LBM_DAMP_NAN_STEPS 32
#define LBM_TAU_DAMPED 1.0f

/* Storage of the populations (a build define, LBM_FP16S): 0 float32; 1 IEEE float16 holding the
 * deviation f_a - rest_a from the lake at rest at the reference depth (FluidX3D's FP16S idea:
 * half storage, float32 arithmetic). The buffers are typed LBM_FT; every access goes through
 * lbm_load / lbm_store. */
#ifndef LBM_FP16S
#define LBM_FP16S 0
#endif
#if LBM_FP16S
#define LBM_FT half
#define LBM_RAW ushort
#else
#define LBM_FT float
#define LBM_RAW uint
#endif

/* Guard modes (a build define, LBM_GUARD): 1 limiter + local damping + NaN restore; 0 the plain
 * solver (NaN counted and reported only; no limiting, no restore). */
#ifndef LBM_GUARD
#define LBM_GUARD 1
#endif

/* Work-group size of the two-stage reduction (a power of two). */
#define LBM_REDUCE_WG 256

/* f0_eq >= 0 <=> 5Gh/6 + 2U^2/3 <= 1; the limiter keeps that sum below this. */
#define LBM_F0_LIMIT 0.98f

/* BGK LABSWE on D2Q9 is unstable once the water moves where G h = g h / e^2 exceeds about 0.6
 * (measured, docs/lbm.md: the boundary is 0.60 at tau = 0.505 and above 0.64 at tau = 0.8); the
 * limiter caps G h here and the lattice is designed for G h <= 0.5 (lbm/lattice.py). */
#define LBM_GH_LIMIT 0.6f

/* 56 bytes: the constants of one solver, passed by value to every lbm kernel. */
typedef struct {
    int nx, ny;       /* cells along x (i) and y (j) */
    int n_cells;      /* nx * ny: the stride between direction planes of f */
    float dx;         /* cell size, m */
    float e;          /* lattice speed dx/dt, m/s */
    float g_lat;      /* G = g / e^2, 1/m */
    float drag;       /* linear drag times dt: the momentum fraction removed per step */
    float h_min;      /* limiter: depth floor, m */
    float u2_max;     /* limiter: largest (|u|/e)^2 */
    float fr2_max;    /* limiter: largest Froude number squared */
    float rest0;      /* LBM_FP16S: stored f_a = f_a - rest_a; rest of direction 0, m */
    float rest_axis;  /* ... of the axes (1, 3, 5, 7), m */
    float rest_diag;  /* ... of the diagonals (2, 4, 6, 8), m; all 0 for float32 storage */
    float quantum;    /* float32 storage: populations are multiples of this power of two, m
                         (lbm_quantize); 0 for LBM_FP16S */
} LbmParams;

/* 112 bytes: the guard's device-side record (one per solver). The step kernels count and
 * account what the limiter did; the reduction fills the statistics and decides the action; the
 * host reads the whole record once per frame. Counters and volumes are cumulative; volumes are
 * sums of depth over cells in m (x dx^2 = m^3). */
typedef struct {
    float tau;             /* relaxation time (tau_user; the guard never changes it globally) */
    float tau_user;        /* relaxation time from the viscosity */
    float mass;            /* sum of h over cells at the last check, m (x dx^2 = volume) */
    float max_u2;          /* max (|u|/e)^2 at the last check */
    float max_fr2;         /* max Froude^2 at the last check */
    float min_h;           /* min depth at the last check, m */
    float ckpt_mass;       /* the same four statistics of the checkpoint */
    float ckpt_max_u2;
    float ckpt_max_fr2;
    float ckpt_min_h;
    float mass0;           /* sum of h at the first check after set_state, m */
    float sources;         /* depth asked for by drops (sum over cells), m */
    float clipped;         /* depth removed by the limiter (and by restores), m */
    float created;         /* depth added by the limiter (and by restores), m */
    float peak_fr2;        /* largest Froude^2 the limiter saw before clipping, over the run of
                              intervals with clips that ended at the last check (0 if clean) */
    float peak_acc;        /* the same, accumulated by the steps since the last check */
    uint nan_cells;        /* non-finite cells found at the last check (before any restore) */
    uint action;           /* LBM_GUARD_*: what lbm_guard_apply does next */
    uint clamped;          /* cells clamped by the limiter or a source */
    uint clamped_checked;  /* value of clamped at the last check */
    uint restored;         /* checkpoint restores */
    uint damped;           /* checks whose interval had locally damped cells */
    uint saved;            /* checkpoints saved */
    uint checks;           /* checks run */
    uint damped_cells;     /* cells with a damping mark at the last check */
    uint pad0, pad1;
} LbmGuard;

/* 32 bytes: one work-group's partial reduction. The depth sum is a float pair: mass + mass_lo
 * (compensated summation, lbm_reduce.cl), so the total is right to float32 rounding. */
typedef struct {
    float mass, max_u2, max_fr2, min_h;
    uint nan_cells, damped_cells;
    float mass_lo;
    uint pad1;
} LbmPartial;

/* 48 bytes: a drop or a push, applied over the cell box [i0, i0+w) x [j0, j0+h) (the launch). */
typedef struct {
    float x, y;         /* drop centre or drag start, m */
    float dx, dy;       /* drag vector, m (push only) */
    float radius;       /* m */
    float amount;       /* drop: height, m; push: velocity change at the centre line, m/s */
    int i0, j0;         /* first cell of the launch box */
    float volume;       /* depth asked for (sum over the box's cells), m: the budget's source */
    float pad0, pad1, pad2;
} LbmSource;

/* Weights w_a of the LABSWE equilibrium: 1/3 on the axes, 1/12 on the diagonals. */
#define LBM_W_AXIS (1.0f / 3.0f)
#define LBM_W_DIAG (1.0f / 12.0f)

/* Equilibrium of Zhou (2004) in lattice units (U = u/e), written with the weights:
 *   fa = w_a (G h^2/2 + h c.U + 3/2 h (c.U)^2 - 1/2 h U.U),  a = 1..8
 *   f0 = h - 5Gh^2/6 - 2hU.U/3, computed as h - (f1 + ... + f8): equal in exact arithmetic, and
 *   in float32 the nine sum to h without the bias that the rounded weights 1/3, 1/12 and 5/6
 *   would leave (about 4e-8 G h^2 per step, a mass drift of 1e-4 per 10^4 steps). */
void lbm_equilibrium(const float h, const float ux, const float uy, const float G,
                     float* feq)
{
    const float u2 = ux * ux + uy * uy;
    const float base = 0.5f * G * h * h - 0.5f * h * u2;
    const float a = ux + uy, b = uy - ux;  /* c.U of directions 2 and 4 */
    feq[1] = LBM_W_AXIS * (base + h * ux + 1.5f * h * ux * ux);
    feq[5] = LBM_W_AXIS * (base - h * ux + 1.5f * h * ux * ux);
    feq[3] = LBM_W_AXIS * (base + h * uy + 1.5f * h * uy * uy);
    feq[7] = LBM_W_AXIS * (base - h * uy + 1.5f * h * uy * uy);
    feq[2] = LBM_W_DIAG * (base + h * a + 1.5f * h * a * a);
    feq[6] = LBM_W_DIAG * (base - h * a + 1.5f * h * a * a);
    feq[4] = LBM_W_DIAG * (base + h * b + 1.5f * h * b * b);
    feq[8] = LBM_W_DIAG * (base - h * b + 1.5f * h * b * b);
    feq[0] = h - (((feq[1] + feq[5]) + (feq[3] + feq[7])) + ((feq[2] + feq[6]) + (feq[4] + feq[8])));
}

/* Depth and momentum (lattice units) of nine populations. */
void lbm_moments(const float* f, float* h, float* mx, float* my)
{
    *h = f[0] + f[1] + f[2] + f[3] + f[4] + f[5] + f[6] + f[7] + f[8];
    *mx = (f[1] - f[5]) + (f[2] - f[4]) + (f[8] - f[6]);
    *my = (f[3] - f[7]) + (f[2] - f[8]) + (f[4] - f[6]);
}

/* The limiter: depth in [h_min, LBM_GH_LIMIT / G]; |U|^2 at most min(u2_max, fr2_max G h); then
 * 5Gh/6 + 2U^2/3 <= LBM_F0_LIMIT (so f0_eq >= 0) by lowering h (with the default limits the
 * depth cap already implies it). Returns 1 when it changed anything. NaN passes through
 * unchanged (the guard restores a checkpoint for that). */
int lbm_limit(float* h, float* ux, float* uy, const LbmParams p)
{
    int hit = 0;
    float hh = *h, vx = *ux, vy = *uy;
    if (hh < p.h_min) {
        hh = p.h_min;
        hit = 1;
    }
    if (p.g_lat * hh > LBM_GH_LIMIT) {
        hh = LBM_GH_LIMIT / p.g_lat;
        hit = 1;
    }
    float u2 = vx * vx + vy * vy;
    const float lim = fmin(p.u2_max, p.fr2_max * p.g_lat * hh);
    if (u2 > lim) {
        const float s = sqrt(lim / u2);
        vx *= s;
        vy *= s;
        u2 = vx * vx + vy * vy;
        hit = 1;
    }
    if ((5.0f / 6.0f) * p.g_lat * hh + (2.0f / 3.0f) * u2 > LBM_F0_LIMIT) {
        hh = (6.0f / 5.0f) * (LBM_F0_LIMIT - (2.0f / 3.0f) * u2) / p.g_lat;
        hit = 1;
    }
    *h = hh;
    *ux = vx;
    *uy = vy;
    return hit;
}

/* LBM_FP16S: population a of the lake at rest, which the storage subtracts (0 for float32). */
float lbm_rest(const int a, const LbmParams p)
{
    return a == 0 ? p.rest0 : ((a & 1) ? p.rest_axis : p.rest_diag);
}

/* Population a of index n of populations stored in planes rn apart (any address space), as
 * float32; and its store. */
#if LBM_FP16S
#define LBM_LOAD_AT(f, a, n, rn, p) (vload_half((a) * (rn) + (n), (f)) + lbm_rest((a), (p)))
#define LBM_STORE_AT(f, a, n, rn, p, v) \
    vstore_half_rte((v) - lbm_rest((a), (p)), (a) * (rn) + (n), (f))
#else
#define LBM_LOAD_AT(f, a, n, rn, p) ((f)[(a) * (rn) + (n)])
#define LBM_STORE_AT(f, a, n, rn, p, v) ((f)[(a) * (rn) + (n)] = (v))
#endif

float lbm_load(__global const LBM_FT* f, const int a, const int n, const LbmParams p)
{
    return LBM_LOAD_AT(f, a, n, p.n_cells, p);
}

void lbm_store(__global LBM_FT* f, const int a, const int n, const LbmParams p, const float v)
{
    LBM_STORE_AT(f, a, n, p.n_cells, p, v);
}

/* *addr += v for a float in global memory (OpenCL 1.2 has no float atomics): a compare-exchange
 * loop, used only where the limiter acted (rare). */
void lbm_atomic_add(volatile __global float* addr, const float v)
{
    union { uint u; float f; } old, new_;
    do {
        old.f = *addr;
        new_.f = old.f + v;
    } while (atomic_cmpxchg((volatile __global uint*)addr, old.u, new_.u) != old.u);
}

/* The limiter's volume account: depth dh added (> 0) or removed (< 0) in one cell. */
void lbm_account(__global LbmGuard* g, const float dh)
{
    if (dh > 0.0f) lbm_atomic_add(&g->created, dh);
    else if (dh < 0.0f) lbm_atomic_add(&g->clipped, -dh);
}

/* Exact volume with float32 storage. Every population is kept a multiple of the quantum
 * q = p.quantum = 2^-24 P, P the smallest power of two above the depth cap (lbm.solver), and
 * every change the step or a source makes to one is rounded to a multiple of q before it is
 * added. Sums and differences of such numbers below 2^24 q = P are exact in float32, so
 * streaming (a permutation), the walls, the delta-form collision (what the moving populations
 * gain the rest population loses), the bed force (antisymmetric per link; the rounding is odd)
 * and pushes move volume between populations without rounding: the total is conserved to the
 * last bit. Without it the rest population's rounding (its ulp is ~1e-8 m) lost the small
 * collision updates of calm, dissipating water with a biased sign: 2e-6 of the volume in 1e5
 * steps (bench/long_runs.py).
 * The rounding is (x + C) - C with C = 1.5 * 2^23 q = 3P/4: for |x| < P/4, x + C lies in
 * [P/2, P), where floats are spaced q apart (round to nearest even); x >= P/4 rounds to a
 * multiple of 2q, still exact. Only x < -P/4 (a change larger than any population of water
 * inside the limiter's bounds: a blow-up of the plain solver) would round off the grid. Two
 * adds: rint() is a library call on some CPUs and halved the step's speed on PoCL. FP_CONTRACT
 * is off above, so x + C is never fused with the product that made x.
 * LBM_FP16S: the half rounding dominates and nothing is quantized. */
float lbm_quantize(const float x, const float q)
{
#if LBM_FP16S
    (void)q;
    return x;
#else
    const float c = 12582912.0f * q;   /* 1.5 * 2^23 q, exact */
    return (x + c) - c;
#endif
}

/* Index of cell (i, j). */
#define LBM_CELL(p, i, j) ((j) * (p).nx + (i))

#endif
