/* Floating rigid bodies coupled both ways with the shallow water (lbm/bodies.py, docs/lbm.md).
 * One bodies update is one launch for all bodies, no host copy:
 *
 *   lbm_bodies_update     G work-groups per body (G from the launch's size), all substeps in
 *                         the launch: sample the water under every footprint column (bilinear
 *                         head H = bed + hull pressure + h and velocity), reduce buoyancy, drag,
 *                         force and torque in local memory, then work-item 0 integrates the rigid
 *                         body (semi-implicit Euler with added mass) and stops it at the walls;
 *                         after the last substep the body's first group writes the pose, its row
 *                         of the transform buffer (world_from_mesh) and the cell box its pressure
 *                         head covers (box; the previous one: box_old); then each group presses
 *                         its tile (LBM_BODY_WG consecutive cells in turn) of the rectangle
 *                         holding box and box_old (the box: where the footprint meets the
 *                         still-water plane, within the bounding circle's box): zforce = bed + the
 *                         hulls' pressure head, the "bed" the water's force sees, so a hull pushes
 *                         water away (a wake, waves) and conserves its volume exactly; cells of
 *                         box_old that left the hull get the bed back. Every group of a body
 *                         computes the same update (same inputs, code and order: the same bits),
 *                         so the pass needs no global synchronisation; the water it reads is the
 *                         populations and the bed plus the pressure head of the poses at the start
 *                         (recomputed: the zforce cells under a hull are rewritten by the other
 *                         groups during the launch), none of which the launch writes. Bodies whose
 *                         cells can meet during the update (what the water they read, what they
 *                         press: known from the start with the speed limit LBM_BODY_MAX_SPEED)
 *                         form a cluster: every group of each of them updates the whole cluster
 *                         body after body, then presses its tile of its own body (a cell in
 *                         several bodies' rectangles: the lowest body's), with the cluster's
 *                         heads. So no cell is written twice and the result is deterministic.
 *                         The records are read from ``bodies`` and written to ``out`` (the host
 *                         swaps them every update).
 *   lbm_bodies_press_all  the pressure head over every cell (when boats are added or dropped)
 *
 * Hydrostatics: the pressure under a hull column whose bottom is at Y_b is rho g (H - Y_b), H the
 * water's head there; the hull presses on the water with the head d = clamp(L - Y_b, 0, Y_t - Y_b),
 * L the water level around the hull (the mean head over the footprint's ring of empty columns),
 * so a hull at rest sits in a depression of its own draft. Defines: LBM_FP16S (lbm.h).
 */
#include "lbm.h"
#include "lbm_bodies.h"

/* The rotation matrix rows of a unit quaternion (w, x, y, z) stored in (x, y, z, w). */
void lbm_quat_rows(const float4 q, float3* r0, float3* r1, float3* r2)
{
    const float w = q.x, x = q.y, y = q.z, z = q.w;
    *r0 = (float3)(1.0f - 2.0f * (y * y + z * z), 2.0f * (x * y - w * z), 2.0f * (x * z + w * y));
    *r1 = (float3)(2.0f * (x * y + w * z), 1.0f - 2.0f * (x * x + z * z), 2.0f * (y * z - w * x));
    *r2 = (float3)(2.0f * (x * z - w * y), 2.0f * (y * z + w * x), 1.0f - 2.0f * (x * x + y * y));
}

/* Hamilton product of quaternions stored (w, x, y, z) in (x, y, z, w). */
float4 lbm_quat_mul(const float4 a, const float4 b)
{
    return (float4)(a.x * b.x - a.y * b.y - a.z * b.z - a.w * b.w,
                     a.x * b.y + a.y * b.x + a.z * b.w - a.w * b.z,
                     a.x * b.z - a.y * b.w + a.z * b.x + a.w * b.y,
                     a.x * b.w + a.y * b.z - a.z * b.y + a.w * b.x);
}

float3 lbm_rot(const float3 r0, const float3 r1, const float3 r2, const float3 v)
{
    return (float3)(dot(r0, v), dot(r1, v), dot(r2, v));
}

float3 lbm_rot_t(const float3 r0, const float3 r1, const float3 r2, const float3 v)
{
    return r0 * v.x + r1 * v.y + r2 * v.z;
}

/* What the pressure kernels need of a body, staged in local memory once per work-group. */
typedef struct {
    float4 pos;        /* centre of mass, m; w: bounding radius, m */
    float4 r0, r1, r2; /* world_from_body rows; r0.w: the still-water level L, m */
    float4 foot;       /* x0, z0, dfx, dfz */
    int4 n;            /* nfx, nfz, footprint offset, active */
} LbmPressBody;

/* Stage body *src in *dst (built in private memory, then copied). */
void lbm_press_body(__local LbmPressBody* dst, const LbmBody* src)
{
    const LbmBody B = *src;
    float3 r0, r1, r2;
    lbm_quat_rows(B.quat, &r0, &r1, &r2);
    LbmPressBody o;
    o.pos = (float4)(B.pos.xyz, B.damping.w);
    o.r0 = (float4)(r0, B.torque.w);
    o.r1 = (float4)(r1, 0.0f);
    o.r2 = (float4)(r2, 0.0f);
    o.foot = B.foot;
    o.n = (int4)(B.foot_n.x, B.foot_n.y, B.foot_n.z, B.flags.x);
    *dst = o;
}

/* The cells a body's pressure pass covers: the bounding rectangle of box and box_old. */
int4 lbm_press_cells(const int4 box, const int4 box_old)
{
    return (int4)(min(box.x, box_old.x), min(box.y, box_old.y), max(box.z, box_old.z),
                  max(box.w, box_old.w));
}

int lbm_boxes_meet(const int4 a, const int4 b)
{
    return a.x <= b.z && b.x <= a.z && a.y <= b.w && b.y <= a.w;
}

/* The footprint column of hull ``pb`` under world (X, Z): its index in ``foot``, and its grid
 * position in *ixz (-1: none, the point is off the hull's bounding circle or footprint grid). */
int lbm_hull_column(__local const LbmPressBody* pb, const float X, const float Z, int2* ixz)
{
    *ixz = (int2)(-1);
    if (pb->n.w == 0) return -1;
    const float4 pos = pb->pos;
    const float dxw = X - pos.x, dzw = Z - pos.z;
    if (dxw * dxw + dzw * dzw > pos.w * pos.w) return -1;
    const float3 loc = lbm_rot_t(pb->r0.xyz, pb->r1.xyz, pb->r2.xyz,
                                 (float3)(dxw, pb->r0.w - pos.y, dzw));
    const float4 fp = pb->foot;
    const int4 fn = pb->n;
    const int ix = (int)round((loc.x - fp.x) / fp.z);
    const int iz = (int)round((loc.z - fp.y) / fp.w);
    if (ix < 0 || iz < 0 || ix >= fn.x || iz >= fn.y) return -1;
    *ixz = (int2)(ix, iz);
    return fn.z + iz * fn.x + ix;
}

/* Hull ``pb``'s pressure head clamp(L - Y_b, 0, Y_t - Y_b) over its footprint column at grid
 * position ``ixz`` (lbm_hull_column) holding (bottom, top) ``col``. */
float lbm_hull_column_head(__local const LbmPressBody* pb, const int2 ixz, const float2 col)
{
    if (col.y < col.x) return 0.0f;
    const float xc = pb->foot.x + (float)ixz.x * pb->foot.z;
    const float zc = pb->foot.y + (float)ixz.y * pb->foot.w;
    const float3 r1 = pb->r1.xyz;
    const float yb = pb->pos.y + dot(r1, (float3)(xc, col.x, zc));
    const float yt = pb->pos.y + dot(r1, (float3)(xc, col.y, zc));
    const float lo = fmin(yb, yt), hi = fmax(yb, yt);
    return clamp(pb->r0.w - lo, 0.0f, hi - lo);
}

/* The hulls' pressure head (m) at world (X, Z): over the bodies in ``mask`` (bit b: body b, in
 * increasing b), per hull over it, clamp(L - Y_b, 0, Y_t - Y_b) of its nearest footprint column. */
float lbm_hull_head(__local const LbmPressBody* l_b, const int mask,
                    __global const float2* restrict foot, const float X, const float Z)
{
    float d = 0.0f;
    for (int m = mask; m != 0; m &= m - 1) {
        const int b = 31 - clz(m & -m);
        int2 ixz;
        const int k = lbm_hull_column(&l_b[b], X, Z, &ixz);
        if (k >= 0) d += lbm_hull_column_head(&l_b[b], ixz, foot[k]);
    }
    return d;
}

/* The water at world (X, Z): bilinear between cell centres, clamped to the grid. Head (m, world
 * y) = origin.y + the bed the water's force sees (bed + the pressure head of the hulls in ``mask``
 * as the pressure pass writes it into zforce, here from the records at the start of the update,
 * l_b0) + the depth; velocity (m/s, world x and z). With one hull in ``mask`` (the usual case) the
 * four cells' footprint columns are found first and all their reads are in flight together. */
void lbm_water_at(__global const LBM_FT* f, __global const float* bed,
                  __local const LbmPressBody* l_b0, const int mask,
                  __global const float2* foot, const LbmParams p, const float4 origin,
                  const float X, const float Z, float* H, float* u, float* v)
{
    const float gx = clamp((X - origin.x) / p.dx - 0.5f, 0.0f, (float)(p.nx - 1));
    const float gz = clamp((Z - origin.z) / p.dx - 0.5f, 0.0f, (float)(p.ny - 1));
    const int i0 = min((int)gx, p.nx - 1), j0 = min((int)gz, p.ny - 1);
    const int i1 = min(i0 + 1, p.nx - 1), j1 = min(j0 + 1, p.ny - 1);
    const float fx = gx - (float)i0, fz = gz - (float)j0;
    const int one = (mask != 0 && (mask & (mask - 1)) == 0) ? 31 - clz(mask) : -1;
    int n[4], k[4];
    int2 ixz[4];
    float Xc[4], Zc[4], bz[4], fl[4][9];
    float2 col[4];
    for (int q = 0; q < 4; ++q) {
        const int i = (q & 1) ? i1 : i0, j = (q & 2) ? j1 : j0;
        n[q] = LBM_CELL(p, i, j);
        Xc[q] = origin.x + ((float)i + 0.5f) * p.dx;
        Zc[q] = origin.z + ((float)j + 0.5f) * p.dx;
        k[q] = one >= 0 ? lbm_hull_column(&l_b0[one], Xc[q], Zc[q], &ixz[q]) : -1;
    }
    for (int q = 0; q < 4; ++q) {
        bz[q] = bed[n[q]];
        col[q] = k[q] >= 0 ? foot[k[q]] : (float2)(0.0f);
        for (int a = 0; a < 9; ++a) fl[q][a] = lbm_load(f, a, n[q], p);
    }
    float Hq[4], uq[4], vq[4];
    for (int q = 0; q < 4; ++q) {
        float h, mx, my;
        lbm_moments(fl[q], &h, &mx, &my);
        const float d = one >= 0 ? (k[q] >= 0 ? lbm_hull_column_head(&l_b0[one], ixz[q], col[q])
                                              : 0.0f)
                                 : lbm_hull_head(l_b0, mask, foot, Xc[q], Zc[q]);
        Hq[q] = (bz[q] + d) + h;
        uq[q] = p.e * mx / h;
        vq[q] = p.e * my / h;
    }
    const float w00 = (1.0f - fx) * (1.0f - fz), w10 = fx * (1.0f - fz);
    const float w01 = (1.0f - fx) * fz, w11 = fx * fz;
    *H = origin.y + w00 * Hq[0] + w10 * Hq[1] + w01 * Hq[2] + w11 * Hq[3];
    *u = w00 * uq[0] + w10 * uq[1] + w01 * uq[2] + w11 * uq[3];
    *v = w00 * vq[0] + w10 * vq[1] + w01 * vq[2] + w11 * vq[3];
}

#define LBM_BODY_ACC 9   /* force (3), torque (3), submerged volume, ring head sum, ring count */

/* Cells whose centres may lie within r of (X, Z), one cell of margin, clamped to the grid
 * (never empty): (i0, j0, i1, j1) inclusive. */
int4 lbm_body_box(const LbmParams p, const float4 origin, const float X, const float Z,
                  const float r)
{
    const float gx0 = (X - r - origin.x) / p.dx - 0.5f, gx1 = (X + r - origin.x) / p.dx - 0.5f;
    const float gz0 = (Z - r - origin.z) / p.dx - 0.5f, gz1 = (Z + r - origin.z) / p.dx - 0.5f;
    const int4 b = (int4)((int)floor(gx0) - 1, (int)floor(gz0) - 1, (int)ceil(gx1) + 1,
                          (int)ceil(gz1) + 1);
    return clamp(b, (int4)(0), (int4)(p.nx - 1, p.ny - 1, p.nx - 1, p.ny - 1));
}

/* The cells the pressure head of ``body`` may cover, a subset of its bounding circle's box: the
 * world rectangle around the parallelogram where the still-water plane Y = L meets the prism of
 * the footprint grid's hull columns (the grid less its empty borders), one cell of margin. A hull tilted
 * past 75 degrees (|r1.y| < 0.25) keeps the circle's box. */
int4 lbm_body_press_box(const LbmParams p, const float4 origin, const LbmBody* body)
{
    const int4 circle = lbm_body_box(p, origin, body->pos.x, body->pos.z, body->damping.w);
    float3 r0, r1, r2;
    lbm_quat_rows(body->quat, &r0, &r1, &r2);
    /* loc.x = r0.x dX + r1.x h + r2.x dZ, loc.z = r0.z dX + r1.z h + r2.z dZ (loc = R^T d) */
    const float det = r0.x * r2.z - r2.x * r0.z;
    if (!(fabs(det) >= 0.25f)) return circle;
    const float h = body->torque.w - body->pos.y;
    const float4 fp = body->foot;
    const float ex = (float)body->flags.z, ez = (float)body->flags.w;   /* empty borders */
    const float xa = fp.x + (ex - 0.5f) * fp.z;
    const float xb = fp.x + ((float)body->foot_n.x - ex - 0.5f) * fp.z;
    const float za = fp.y + (ez - 0.5f) * fp.w;
    const float zb = fp.y + ((float)body->foot_n.y - ez - 0.5f) * fp.w;
    float lo_x = INFINITY, hi_x = -INFINITY, lo_z = INFINITY, hi_z = -INFINITY;
    for (int k = 0; k < 4; ++k) {
        const float a = ((k & 1) ? xb : xa) - r1.x * h, c = ((k & 2) ? zb : za) - r1.z * h;
        const float dX = (r2.z * a - r2.x * c) / det, dZ = (r0.x * c - r0.z * a) / det;
        lo_x = fmin(lo_x, dX);
        hi_x = fmax(hi_x, dX);
        lo_z = fmin(lo_z, dZ);
        hi_z = fmax(hi_z, dZ);
    }
    const float gx0 = (body->pos.x + lo_x - origin.x) / p.dx - 0.5f;
    const float gx1 = (body->pos.x + hi_x - origin.x) / p.dx - 0.5f;
    const float gz0 = (body->pos.z + lo_z - origin.z) / p.dx - 0.5f;
    const float gz1 = (body->pos.z + hi_z - origin.z) / p.dx - 0.5f;
    if (!(isfinite(gx0) && isfinite(gx1) && isfinite(gz0) && isfinite(gz1))) return circle;
    const float4 g = clamp((float4)(floor(gx0) - 1.0f, floor(gz0) - 1.0f, ceil(gx1) + 1.0f,
                                    ceil(gz1) + 1.0f), -1.0f, (float)(max(p.nx, p.ny) + 1));
    const int4 t = convert_int4(g);
    const int4 b = (int4)(max(t.x, circle.x), max(t.y, circle.y), min(t.z, circle.z),
                          min(t.w, circle.w));
    /* never empty: a hull off every cell keeps one cell of its circle's box */
    return (b.x <= b.z && b.y <= b.w) ? b : circle.xyxy;
}

/* One work-item's share of the columns of ``body`` at its current pose: force, torque,
 * submerged volume, ring head sum and count added to acc. The water's head: bed + the pressure
 * head of the hulls in ``mask`` at the start of the update (l_b0) + depth. */
void lbm_body_columns(__global const LBM_FT* f, __global const float* bed,
                      __local const LbmPressBody* l_b0, const int mask, const LbmParams p,
                      __global const float2* foot, const LbmBody* body, const LbmBodyStep s,
                      const int lid, float* acc)
{
    float3 r0, r1, r2;
    lbm_quat_rows(body->quat, &r0, &r1, &r2);
    const float3 pos = body->pos.xyz, vel = body->vel.xyz, omega = body->omega.xyz;
    const int nfx = body->foot_n.x, n_s = body->foot_n.x * body->foot_n.y;
    const float dA = body->foot.z * body->foot.w * fabs(r1.y);  /* column area seen from above */
    for (int k = lid; k < n_s; k += LBM_BODY_WG) {
        const float2 col = foot[body->foot_n.z + k];
        const float xb = body->foot.x + (float)(k % nfx) * body->foot.z;
        const float zb = body->foot.y + (float)(k / nfx) * body->foot.w;
        float H, uw, vw;
        if (col.y < col.x) {   /* a ring column: the water level around the hull */
            const float3 P = pos + lbm_rot(r0, r1, r2, (float3)(xb, 0.0f, zb));
            lbm_water_at(f, bed, l_b0, mask, foot, p, s.origin, P.x, P.z, &H, &uw, &vw);
            acc[7] += H;
            acc[8] += 1.0f;
            continue;
        }
        const float3 Pb = pos + lbm_rot(r0, r1, r2, (float3)(xb, col.x, zb));
        const float3 Pt = pos + lbm_rot(r0, r1, r2, (float3)(xb, col.y, zb));
        lbm_water_at(f, bed, l_b0, mask, foot, p, s.origin, Pb.x, Pb.z, &H, &uw, &vw);
        const float lo = fmin(Pb.y, Pt.y), hi = fmax(Pb.y, Pt.y);
        const float sub = clamp(H - lo, 0.0f, hi - lo);
        if (!(sub > 0.0f)) continue;
        const float vc = sub * dA;
        const float3 rel = (float3)(Pb.x, lo + 0.5f * sub, Pb.z) - pos;
        const float3 vp = vel + cross(omega, rel);
        const float m_w = s.rho * vc;   /* displaced water, kg */
        const float3 F = (float3)(m_w * body->damping.y * (uw - vp.x),
                                  m_w * (s.gravity - body->damping.x * vp.y),
                                  m_w * body->damping.y * (vw - vp.z));
        const float3 T = cross(rel, F);
        acc[0] += F.x;
        acc[1] += F.y;
        acc[2] += F.z;
        acc[3] += T.x;
        acc[4] += T.y;
        acc[5] += T.z;
        acc[6] += vc;
    }
}

/* One substep of dt for ``body`` under hydrodynamic force Fh, torque Th (about the centre of
 * mass) and submerged volume vol: semi-implicit Euler with added mass, the walls, the bed. */
void lbm_body_integrate(LbmBody* body, const float3 Fh, const float3 Th, const float vol,
                        const LbmBodyStep s)
{
    float3 r0, r1, r2;
    lbm_quat_rows(body->quat, &r0, &r1, &r2);
    const float3 pos = body->pos.xyz, vel = body->vel.xyz, omega = body->omega.xyz;
    /* added mass in proportion to the part of the rest displacement under water (none in air) */
    const float m = body->pos.w, dt = s.dt;
    const float added = 1.0f + body->inertia.w * fmin(1.0f, vol * s.rho / m);
    float3 v2 = vel + dt * (Fh / (m * added) - (float3)(0.0f, s.gravity / added, 0.0f));
    /* the speed limit (horizontal): the update's clusters rely on it */
    const float vmax = (float)LBM_BODY_MAX_SPEED, speed = hypot(v2.x, v2.z);
    if (speed > vmax) {
        v2.x *= vmax / speed;
        v2.z *= vmax / speed;
    }
    const float3 I = body->inertia.xyz;
    float3 wb = lbm_rot_t(r0, r1, r2, omega);
    const float3 tb = lbm_rot_t(r0, r1, r2, Th) - cross(wb, I * wb);
    wb = (wb + dt * tb / (I * added)) / (1.0f + dt * body->damping.z);
    const float3 w2 = lbm_rot(r0, r1, r2, wb);
    float3 p2 = pos + dt * v2;
    float4 q2 = body->quat + 0.5f * dt * lbm_quat_mul((float4)(0.0f, w2.x, w2.y, w2.z),
                                                      body->quat);
    q2 = normalize(q2);
    /* walls: the hull's bounding radius stays inside the box */
    const float r = body->damping.w;
    const float lo_x = s.origin.x + r, hi_x = s.origin.x + s.size_x - r;
    const float lo_z = s.origin.z + r, hi_z = s.origin.z + s.size_z - r;
    if (p2.x < lo_x) { p2.x = lo_x; v2.x = fmax(v2.x, 0.0f); }
    if (p2.x > hi_x) { p2.x = hi_x; v2.x = fmin(v2.x, 0.0f); }
    if (p2.z < lo_z) { p2.z = lo_z; v2.z = fmax(v2.z, 0.0f); }
    if (p2.z > hi_z) { p2.z = hi_z; v2.z = fmin(v2.z, 0.0f); }
    /* the bed: the hull's lowest point stays above the lowest bed (a grounded boat) */
    const float floor_y = s.origin.y + s.floor + body->vel.w;
    if (p2.y < floor_y) { p2.y = floor_y; v2.y = fmax(v2.y, 0.0f); }
    if (lo_x > hi_x) p2.x = s.origin.x + 0.5f * s.size_x;
    if (lo_z > hi_z) p2.z = s.origin.z + 0.5f * s.size_z;
    /* a wall's push too moves it at most vmax dt (one placed outside comes in over updates) */
    const float moved = hypot(p2.x - pos.x, p2.z - pos.z);
    if (moved > vmax * dt) {
        p2.x = pos.x + (p2.x - pos.x) * (vmax * dt / moved);
        p2.z = pos.z + (p2.z - pos.z) * (vmax * dt / moved);
    }
    const int finite = all(isfinite(p2)) && all(isfinite(v2)) && all(isfinite(w2))
                       && all(isfinite(q2));
    if (body->flags.y != 0) {   /* held: the pose stays, at rest */
        body->vel.xyz = (float3)(0.0f);
        body->omega.xyz = (float3)(0.0f);
    } else if (finite) {
        body->pos.xyz = p2;
        body->vel.xyz = v2;   /* vel.w: the keel depth, kept */
        body->omega.xyz = w2;
        body->quat = q2;
    } else {   /* keep the pose, stop the body: never a NaN in a transform */
        body->vel.xyz = (float3)(0.0f);
        body->omega.xyz = (float3)(0.0f);
    }
    body->force = (float4)(Fh, vol);
    body->torque.xyz = Th;   /* torque.w: the still-water level, set by the host */
}

/* Cells whose centres may lie in world [X0, X1] x [Z0, Z1], one cell of margin, clamped. */
int4 lbm_cells_of(const LbmParams p, const float4 origin, const float X0, const float X1,
                  const float Z0, const float Z1)
{
    const float gx0 = (X0 - origin.x) / p.dx - 0.5f, gx1 = (X1 - origin.x) / p.dx - 0.5f;
    const float gz0 = (Z0 - origin.z) / p.dx - 0.5f, gz1 = (Z1 - origin.z) / p.dx - 0.5f;
    const float4 g = clamp((float4)(floor(gx0) - 1.0f, floor(gz0) - 1.0f, ceil(gx1) + 1.0f,
                                    ceil(gz1) + 1.0f), -1.0f, (float)(max(p.nx, p.ny) + 1));
    return clamp(convert_int4(g), (int4)(0), (int4)(p.nx - 1, p.ny - 1, p.nx - 1, p.ny - 1));
}

/* The cells the water a body's update reads can lie in (its footprint's samples, bilinear) and
 * the cells it can press (its box, where the last pressure lies, and the bounding circle's box of
 * any pose it can reach at the speed limit), from its record at the start of an update of n_sub
 * substeps of dt. One substep samples at the pose of the start: the rectangle around the
 * footprint grid (samples at heights within the sample radius); more: the sample radius's
 * circle, widened by the reach. */
void lbm_body_reach(const LbmParams p, const float4 origin, const LbmBody* B, const float dt,
                    const int n_sub, int4* read, int4* write)
{
    const float d = (float)LBM_BODY_MAX_SPEED * dt * (float)n_sub * 1.001f;
    if (n_sub == 1) {
        float3 r0, r1, r2;
        lbm_quat_rows(B->quat, &r0, &r1, &r2);
        const float4 fp = B->foot;
        const float3 c = (float3)(fp.x + 0.5f * (float)(B->foot_n.x - 1) * fp.z, 0.0f,
                                  fp.y + 0.5f * (float)(B->foot_n.y - 1) * fp.w);
        const float3 e = (float3)(0.5f * (float)(B->foot_n.x - 1) * fp.z, B->omega.w,
                                  0.5f * (float)(B->foot_n.y - 1) * fp.w);
        const float cx = B->pos.x + dot(r0, c), ex = dot(fabs(r0), e) * 1.001f + 1e-6f;
        const float cz = B->pos.z + dot(r2, c), ez = dot(fabs(r2), e) * 1.001f + 1e-6f;
        *read = lbm_cells_of(p, origin, cx - ex, cx + ex, cz - ez, cz + ez);
    } else {
        *read = lbm_body_box(p, origin, B->pos.x, B->pos.z, B->omega.w + d);
    }
    const int4 c = lbm_body_box(p, origin, B->pos.x, B->pos.z, B->damping.w + d);
    *write = (int4)(min(c.x, B->box.x), min(c.y, B->box.y), max(c.z, B->box.z),
                    max(c.w, B->box.w));
}

/* world_from_mesh = [R | pos] . body_from_mesh of ``body`` into transform row foot_n.w. */
void lbm_body_transform(const LbmBody* body, __global Transform* transforms)
{
    float3 r0, r1, r2;
    lbm_quat_rows(body->quat, &r0, &r1, &r2);
    const float3 c0 = (float3)(body->base_r0.x, body->base_r1.x, body->base_r2.x);
    const float3 c1 = (float3)(body->base_r0.y, body->base_r1.y, body->base_r2.y);
    const float3 c2 = (float3)(body->base_r0.z, body->base_r1.z, body->base_r2.z);
    const float3 c3 = (float3)(body->base_r0.w, body->base_r1.w, body->base_r2.w);
    Transform t;
    t.r0 = (float4)(dot(r0, c0), dot(r0, c1), dot(r0, c2), dot(r0, c3) + body->pos.x);
    t.r1 = (float4)(dot(r1, c0), dot(r1, c1), dot(r1, c2), dot(r1, c3) + body->pos.y);
    t.r2 = (float4)(dot(r2, c0), dot(r2, c1), dot(r2, c2), dot(r2, c3) + body->pos.z);
    transforms[body->foot_n.w] = t;
}

/* One bodies update: s.n_sub substeps of s.dt for every body, then its pressure head.
 * G work-groups per body (slot), G = the launch's groups / s.n_bodies: group g is body g / G's
 * tile g % G.
 * The water does not change between substeps (it is the water of this moment), the pose does.
 * Records are read from ``bodies``, written to ``out`` (every slot up to LBM_MAX_BODIES). A
 * group first finds its body's cluster (the bodies whose reach meets, transitively, all from the
 * records at the start), updates the whole cluster (every group of every body of the cluster the
 * same: the same inputs, code and order, so the same bits), then presses its tile of its own
 * body's cells; tile 0 writes the body's record and transform row. */
__kernel __attribute__((reqd_work_group_size(LBM_BODY_WG, 1, 1)))
void lbm_bodies_update(__global const LBM_FT* restrict f, __global float* zforce,
                       __global const float* restrict bed, const LbmParams p,
                       __global const float2* restrict foot,
                       __global const LbmBody* restrict bodies, __global LbmBody* restrict out,
                       __global Transform* transforms, const LbmBodyStep s)
{
    __local float l_acc[LBM_BODY_ACC][LBM_BODY_WG];
    __local float l_part[LBM_BODY_ACC][LBM_BODY_PARTS];
    __local LbmBody l_body[LBM_MAX_BODIES];
    __local LbmPressBody l_b0[LBM_MAX_BODIES];   /* the hulls at the start: the water read */
    __local LbmPressBody l_b[LBM_MAX_BODIES];    /* the hulls at the end: the press */
    __local int4 l_read[LBM_MAX_BODIES], l_write[LBM_MAX_BODIES];
    __local int l_adj[LBM_MAX_BODIES];
    __local int l_cluster;
    const int n = min(s.n_bodies, LBM_MAX_BODIES);
    const int groups = max((int)get_num_groups(0) / max(n, 1), 1);   /* per body */
    const int b = get_group_id(0) / groups, tile = get_group_id(0) - b * groups;
    const int lid = get_local_id(0);
    if (b >= n) return;   /* uniform over the work-group */
    if (get_group_id(0) == 0 && lid >= n && lid < LBM_MAX_BODIES)
        out[lid] = bodies[lid];   /* unused slots */
    if (lid < n) {
        const LbmBody B = bodies[lid];
        l_body[lid] = B;
        l_adj[lid] = 0;
        int4 r, w;
        lbm_body_reach(p, s.origin, &B, s.dt, s.n_sub, &r, &w);
        l_read[lid] = r;
        l_write[lid] = w;
        lbm_press_body(&l_b0[lid], &B);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (l_body[b].flags.x == 0) {   /* uniform: an empty slot is copied */
        if (tile == 0 && lid == 0) out[b] = l_body[b];
        return;
    }
    /* pairs (a, c) of active bodies whose reads and presses can meet */
    if (lid < n * n) {
        const int a = lid / n, c = lid - a * n;
        if (a != c && l_body[a].flags.x != 0 && l_body[c].flags.x != 0
            && (lbm_boxes_meet(l_write[a], l_write[c]) || lbm_boxes_meet(l_read[a], l_write[c])
                || lbm_boxes_meet(l_write[a], l_read[c])))
            atomic_or(&l_adj[a], 1 << c);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0) {
        int cluster = 1 << b, grown = cluster;
        do {
            cluster = grown;
            for (int m = cluster; m != 0; m &= m - 1) grown |= l_adj[31 - clz(m & -m)];
        } while (grown != cluster);
        l_cluster = cluster;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    const int cluster = l_cluster;

    /* the water under a footprint: bed + the cluster's pressure head at the start (what the last
     * pressure pass wrote into zforce, which other groups of the cluster rewrite meanwhile) */
    for (int mm = cluster; mm != 0; mm &= mm - 1) {
        const int m = 31 - clz(mm & -mm);
        for (int sub = 0; sub < s.n_sub; ++sub) {
            const LbmBody body = l_body[m];
            float acc[LBM_BODY_ACC];
            for (int k = 0; k < LBM_BODY_ACC; ++k) acc[k] = 0.0f;
            lbm_body_columns(f, bed, l_b0, cluster, p, foot, &body, s, lid, acc);
            for (int k = 0; k < LBM_BODY_ACC; ++k) l_acc[k][lid] = acc[k];
            barrier(CLK_LOCAL_MEM_FENCE);
            /* LBM_BODY_PARTS partial sums per accumulator, each over a fixed stride */
            if (lid < LBM_BODY_ACC * LBM_BODY_PARTS) {
                const int k = lid / LBM_BODY_PARTS, g = lid - k * LBM_BODY_PARTS;
                float sum = 0.0f;
                for (int i = g; i < LBM_BODY_WG; i += LBM_BODY_PARTS) sum += l_acc[k][i];
                l_part[k][g] = sum;
            }
            barrier(CLK_LOCAL_MEM_FENCE);
            if (lid == 0) {
                float tot[LBM_BODY_ACC];
                for (int k = 0; k < LBM_BODY_ACC; ++k) {
                    tot[k] = 0.0f;
                    for (int g = 0; g < LBM_BODY_PARTS; ++g) tot[k] += l_part[k][g];
                }
                LbmBody next = body;
                lbm_body_integrate(&next, (float3)(tot[0], tot[1], tot[2]),
                                   (float3)(tot[3], tot[4], tot[5]), tot[6], s);
                l_body[m] = next;
            }
            barrier(CLK_LOCAL_MEM_FENCE);
        }
    }
    /* the cluster's new boxes, its hulls staged for the press; tile 0 writes its body's record
     * and transform row */
    if (lid < n && ((cluster >> lid) & 1)) {
        LbmBody body = l_body[lid];
        body.box_old = body.box;
        body.box = lbm_body_press_box(p, s.origin, &body);
        l_body[lid] = body;
        if (lid == b && tile == 0) {
            out[b] = body;
            lbm_body_transform(&body, transforms);
        }
        lbm_press_body(&l_b[lid], &body);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    /* zforce = bed + the cluster's pressure head over this tile of the rectangle holding body
     * b's box and box_old (cells groups * LBM_BODY_WG apart in row order: cell c is tile
     * (c / LBM_BODY_WG) % groups's); a cell in several bodies' rectangles is the lowest body's */
    const int4 box = lbm_press_cells(l_body[b].box, l_body[b].box_old);
    const int lower = cluster & ((1 << b) - 1);
    const int w = box.z - box.x + 1, area = w * (box.w - box.y + 1);
    const int stride = groups * LBM_BODY_WG;
    /* a body alone in its cluster (the usual case): its one hull, each cell's footprint column
     * found first, so the batch's reads are in flight together */
    const int alone = cluster == (1 << b);
    for (int c0 = tile * LBM_BODY_WG; c0 < area; c0 += LBM_PRESS_BATCH * stride) {
        /* (a loop uniform over the group: PoCL miscompiled the other) */
        int cell[LBM_PRESS_BATCH], k[LBM_PRESS_BATCH];
        int2 ixz[LBM_PRESS_BATCH];
        float X[LBM_PRESS_BATCH], Z[LBM_PRESS_BATCH], bz[LBM_PRESS_BATCH];
        float2 col[LBM_PRESS_BATCH];
        for (int u = 0; u < LBM_PRESS_BATCH; ++u) {
            const int c = c0 + u * stride + lid;
            const int i = box.x + c % w, j = box.y + c / w;
            int mine = c < area;
            for (int o = lower; o != 0; o &= o - 1) {
                const int4 oc = lbm_press_cells(l_body[31 - clz(o & -o)].box,
                                                l_body[31 - clz(o & -o)].box_old);
                if (i >= oc.x && i <= oc.z && j >= oc.y && j <= oc.w) mine = 0;
            }
            X[u] = s.origin.x + ((float)i + 0.5f) * p.dx;
            Z[u] = s.origin.z + ((float)j + 0.5f) * p.dx;
            cell[u] = mine ? LBM_CELL(p, i, j) : -1;
            k[u] = (mine && alone) ? lbm_hull_column(&l_b[b], X[u], Z[u], &ixz[u]) : -1;
        }
        for (int u = 0; u < LBM_PRESS_BATCH; ++u) {
            bz[u] = cell[u] >= 0 ? bed[cell[u]] : 0.0f;
            col[u] = k[u] >= 0 ? foot[k[u]] : (float2)(0.0f);
        }
        for (int u = 0; u < LBM_PRESS_BATCH; ++u) {
            if (cell[u] < 0) continue;
            const float d = !alone ? lbm_hull_head(l_b, cluster, foot, X[u], Z[u])
                            : (k[u] >= 0 ? lbm_hull_column_head(&l_b[b], ixz[u], col[u]) : 0.0f);
            zforce[cell[u]] = bz[u] + d;
        }
    }
}

/* zforce = bed + the hulls' pressure head on every cell. Launch: 2D over (nx, ny). */
__kernel void lbm_bodies_press_all(__global const float* restrict bed, __global float* zforce,
                                   const LbmParams p, __global const float2* restrict foot,
                                   __global const LbmBody* restrict bodies, const LbmBodyStep s)
{
    __local LbmPressBody l_b[LBM_MAX_BODIES];
    const int n = min(s.n_bodies, LBM_MAX_BODIES);
    const int lid = get_local_id(0) + get_local_id(1) * get_local_size(0);
    const int ls = get_local_size(0) * get_local_size(1);
    for (int b = lid; b < n; b += ls) {
        const LbmBody B = bodies[b];
        lbm_press_body(&l_b[b], &B);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    const int i = get_global_id(0), j = get_global_id(1);
    if (i >= p.nx || j >= p.ny) return;
    const float X = s.origin.x + ((float)i + 0.5f) * p.dx;
    const float Z = s.origin.z + ((float)j + 0.5f) * p.dx;
    const int cell = LBM_CELL(p, i, j);
    zforce[cell] = bed[cell] + lbm_hull_head(l_b, (1 << n) - 1, foot, X, Z);
}
