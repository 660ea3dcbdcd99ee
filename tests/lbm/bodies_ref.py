"""Float64 NumPy references of the bodies kernels (kernels/lbm_bodies.cl) and the hulls and
pools the body tests share. The formulas are written from docs/lbm.md, "Floating bodies"."""

from pathlib import Path

import numpy as np

import lbm
from lbm.bodies import matrix_from_quat


def box(lx, ly, lz):
    """A closed box [-lx/2, lx/2] x [0, ly] x [-lz/2, lz/2], outward triangles."""
    V = np.array([[x, y, z] for x in (-lx / 2, lx / 2) for y in (0, ly) for z in (-lz / 2, lz / 2)])
    F = np.array([(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7),
                  (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)])
    return V, F


def icosphere(r, levels=2):
    t = (1 + 5**0.5) / 2
    V = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    V = [np.array(v, float) / np.linalg.norm(v) for v in V]
    for _ in range(levels):
        mid, F2 = {}, []

        def m(a, b, mid=mid):
            key = (min(a, b), max(a, b))
            if key not in mid:
                v = V[a] + V[b]
                V.append(v / np.linalg.norm(v))
                mid[key] = len(V) - 1
            return mid[key]
        for a, b, c in F:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            F2 += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        F = F2
    return r * np.array(V), np.array(F)


def read_obj(path):
    V, F = [], []
    for line in Path(path).read_text().splitlines():
        if line.startswith("v "):
            V.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            F.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    return np.array(V), np.array(F)


def pool(rt, dx=0.1, size=(3.0, 2.0), depth=0.5, drag=1.0, **kw):
    nx, ny = round(size[0] / dx), round(size[1] / dx)
    return lbm.ShallowWater(nx, ny, dx, device=rt, depth=depth, viscosity=1e-3, drag=drag, **kw)


def uneven_water(rt, n=16, dx=0.1):
    """An n x n pool of 0.5 m water with a smooth bump and a swirl (uneven and moving)."""
    jj, ii = np.mgrid[0:n, 0:n]
    x, z = (ii + 0.5) * dx, (jj + 0.5) * dx
    sim = lbm.ShallowWater(n, n, dx, device=rt, depth=0.5, viscosity=1e-3)
    sim.set_state(0.5 + 0.03 * np.sin(3 * x) * np.cos(2 * z), 0.2 * np.cos(2 * z),
                  0.1 * np.sin(3 * x))
    return sim


def run(sim, boats, seconds, k=4, every=None):
    """Frames of k water steps (the coupled boats follow through their hook); yields (time,
    positions, speeds)."""
    frames = int(round(seconds / (k * sim.dt)))
    for i in range(frames):
        sim.step(k)
        if every and (i + 1) % every == 0:
            v, w = boats.velocities()
            yield sim.time, boats.poses()[0], np.abs(v).max(1)


def body64(rec) -> dict:
    """A body record (``BODY_DTYPE``) as float64 arrays."""
    return {k: np.asarray(rec[k], np.float64).copy() for k in rec.dtype.names}


def water_sampler(sim, zforce, f_pop, origin):
    """``sample(X, Z) -> (H, u, v)``: bilinear head (world y) and velocity between cell centres,
    clamped to the grid, as ``lbm_water_at``."""
    from lbm import reference as ref

    h, u, v = ref.macro(f_pop.astype(np.float64), sim.e)
    H = zforce.astype(np.float64) + h
    nx, ny, dx = sim.nx, sim.ny, sim.dx

    def sample(X, Z):
        gx = np.clip((X - origin[0]) / dx - 0.5, 0, nx - 1)
        gz = np.clip((Z - origin[2]) / dx - 0.5, 0, ny - 1)
        i0, j0 = np.minimum(gx.astype(int), nx - 1), np.minimum(gz.astype(int), ny - 1)
        i1, j1 = np.minimum(i0 + 1, nx - 1), np.minimum(j0 + 1, ny - 1)
        fx, fz = gx - i0, gz - j0
        out = []
        for a in (H, u, v):
            out.append((1 - fx) * (1 - fz) * a[j0, i0] + fx * (1 - fz) * a[j0, i1]
                       + (1 - fx) * fz * a[j1, i0] + fx * fz * a[j1, i1])
        out[0] = out[0] + origin[1]
        return out

    return sample


def forces(body, hull, sample, rho=1000.0, g=9.81):
    """Force, torque (about the centre of mass) and submerged volume of ``body`` (body64) over
    the hull's columns in the water ``sample`` gives."""
    R = matrix_from_quat(body["quat"])
    pos, vel, om = body["pos"][:3], body["vel"][:3], body["omega"][:3]
    damp = body["damping"]
    fp = hull.footprint.astype(np.float64)
    nfz, nfx = fp.shape[:2]
    zz, xx = np.mgrid[0:nfz, 0:nfx]
    xb, zb = hull.x0 + xx * hull.dfx, hull.z0 + zz * hull.dfz
    full = fp[..., 1] >= fp[..., 0]
    pb = np.stack([xb, fp[..., 0], zb], -1)[full] @ R.T + pos
    pt = np.stack([xb, fp[..., 1], zb], -1)[full] @ R.T + pos
    Hs, us, vs = sample(pb[:, 0], pb[:, 2])
    lo, hi = np.minimum(pb[:, 1], pt[:, 1]), np.maximum(pb[:, 1], pt[:, 1])
    sub = np.clip(Hs - lo, 0, hi - lo)
    vc = sub * hull.dfx * hull.dfz * abs(R[1, 1])
    rel = np.stack([pb[:, 0], lo + 0.5 * sub, pb[:, 2]], -1) - pos
    vp = vel + np.cross(om, rel)
    mw = rho * vc
    Fc = np.stack([mw * damp[1] * (us - vp[:, 0]), mw * (g - damp[0] * vp[:, 1]),
                   mw * damp[1] * (vs - vp[:, 2])], -1)
    return Fc.sum(0), np.cross(rel, Fc).sum(0), vc.sum()


def quat_mul(a, b):
    """Hamilton product of quaternions (w, x, y, z)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                     w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def substep(body, F, T, vol, dt, rho=1000.0, g=9.81, max_speed=np.inf) -> dict:
    """One semi-implicit Euler substep with added mass and rotation damping (no wall or bed
    contact), the horizontal speed at most ``max_speed``: the new body64."""
    out = {k: v.copy() for k, v in body.items()}
    m, q = body["pos"][3], body["quat"]
    added = 1.0 + body["inertia"][3] * min(1.0, vol * rho / m)
    v2 = body["vel"][:3] + dt * (F / (m * added) - np.array([0.0, g / added, 0.0]))
    speed = np.hypot(v2[0], v2[2])
    if speed > max_speed:
        v2[[0, 2]] *= max_speed / speed
    R = matrix_from_quat(q)
    inertia = body["inertia"][:3]
    wb = R.T @ body["omega"][:3]
    tb = R.T @ T - np.cross(wb, inertia * wb)
    wb = (wb + dt * tb / (inertia * added)) / (1.0 + dt * body["damping"][2])
    w2 = R @ wb
    q2 = q + 0.5 * dt * quat_mul(np.array([0.0, *w2]), q)
    out["pos"][:3] = body["pos"][:3] + dt * v2
    out["vel"][:3] = v2
    out["omega"][:3] = w2
    out["quat"] = q2 / np.linalg.norm(q2)
    out["force"] = np.array([*F, vol])
    out["torque"][:3] = T
    return out


def pressure_head(sim, bodies, hulls, origin):
    """The hulls' pressure head (ny, nx) of ``lbm_bodies_press_all`` in float64 from body64
    records, and a mask of cells where float32 rounding may pick another footprint column or
    another side of a bounding circle (left out of comparisons)."""
    nx, ny, dx = sim.nx, sim.ny, sim.dx
    jj, ii = np.mgrid[0:ny, 0:nx]
    X, Z = origin[0] + (ii + 0.5) * dx, origin[2] + (jj + 0.5) * dx
    d = np.zeros((ny, nx))
    unsure = np.zeros((ny, nx), bool)
    for body, hull in zip(bodies, hulls, strict=True):
        pos, r, L = body["pos"][:3], body["damping"][3], body["torque"][3]
        R = matrix_from_quat(body["quat"])
        dxw, dzw = X - pos[0], Z - pos[2]
        d2 = dxw * dxw + dzw * dzw
        unsure |= np.abs(d2 - r * r) < 1e-4 * r * r
        loc = np.stack([dxw, np.full_like(dxw, L - pos[1]), dzw], -1) @ R   # R^T v per cell
        gx, gz = (loc[..., 0] - hull.x0) / hull.dfx, (loc[..., 2] - hull.z0) / hull.dfz
        unsure |= (np.abs(gx - np.floor(gx) - 0.5) < 1e-3) | (np.abs(gz - np.floor(gz) - 0.5)
                                                             < 1e-3)
        ix, iz = np.floor(gx + 0.5).astype(int), np.floor(gz + 0.5).astype(int)
        nfz, nfx = hull.footprint.shape[:2]
        ok = (d2 <= r * r) & (ix >= 0) & (iz >= 0) & (ix < nfx) & (iz < nfz)
        ixc, izc = np.clip(ix, 0, nfx - 1), np.clip(iz, 0, nfz - 1)
        col = hull.footprint[izc, ixc].astype(np.float64)
        ok &= col[..., 1] >= col[..., 0]
        xc, zc = hull.x0 + ixc * hull.dfx, hull.z0 + izc * hull.dfz
        yb = pos[1] + R[1, 0] * xc + R[1, 1] * col[..., 0] + R[1, 2] * zc
        yt = pos[1] + R[1, 0] * xc + R[1, 1] * col[..., 1] + R[1, 2] * zc
        lo, hi = np.minimum(yb, yt), np.maximum(yb, yt)
        d += np.where(ok, np.clip(L - lo, 0.0, hi - lo), 0.0)
    return d, unsure
