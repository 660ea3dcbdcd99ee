"""An independent float64 NumPy LABSWE (Zhou 2004) to check the OpenCL kernels against.

Written from the formulas in SI units (e_a in m/s, u in m/s, g in m/s^2), with *push* streaming
(each population travels from its cell and is reflected by the walls), where the kernels work in
lattice units with pull streaming. Only the conventions are shared: Zhou's direction numbering,
populations as depths (m), the limiter's rules and the source shapes (docs/lbm.md).
"""

from __future__ import annotations

import numpy as np

# Zhou's D2Q9: 0 rest, odd axes, even diagonals, counter-clockwise from +x.
C = np.array([(0, 0), (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)])
F0_LIMIT = 0.98
GH_LIMIT = 0.6


def direction(cx: int, cy: int) -> int:
    return int(np.flatnonzero((C[:, 0] == cx) & (C[:, 1] == cy))[0])


def weight(a: int) -> float:
    """1/3 on axes, 1/12 on diagonals (the equilibrium's weights; REFERENCES.md sec. 1)."""
    return 0.0 if a == 0 else (1 / 3 if abs(C[a]).sum() == 1 else 1 / 12)


def feq_si(h, u, v, g, e):
    """Zhou's equilibria, verbatim: f0 = h - 5gh^2/(6e^2) - 2h u.u/(3e^2); axes
    gh^2/(6e^2) + h e_a.u/(3e^2) + h (e_a.u)^2/(2e^4) - h u.u/(6e^2); diagonals with
    24, 12, 8, 24 in place of 6, 3, 2, 6."""
    h, u, v = (np.asarray(x, np.float64) for x in (h, u, v))
    uu = u * u + v * v
    out = np.empty((9,) + h.shape)
    out[0] = h - 5 * g * h * h / (6 * e * e) - 2 * h * uu / (3 * e * e)
    for a in range(1, 9):
        eu = e * (C[a, 0] * u + C[a, 1] * v)
        if abs(C[a]).sum() == 1:
            out[a] = (g * h * h / (6 * e**2) + h * eu / (3 * e**2) + h * eu**2 / (2 * e**4)
                      - h * uu / (6 * e**2))
        else:
            out[a] = (g * h * h / (24 * e**2) + h * eu / (12 * e**2) + h * eu**2 / (8 * e**4)
                      - h * uu / (24 * e**2))
    return out


def macro(f, e):
    """Depth (m) and velocity (m/s) of populations (9, ny, nx)."""
    f = np.asarray(f, np.float64)
    h = f.sum(0)
    hu = e * np.tensordot(C[:, 0].astype(float), f, 1)
    hv = e * np.tensordot(C[:, 1].astype(float), f, 1)
    return h, hu / h, hv / h


def limit(h, u, v, *, g, e, h_min, u_ratio_max, froude_max):
    """The limiter's rules (docs/lbm.md): depth in [h_min, 0.6 e^2/g], speed cap (|u|/e and
    Froude), then lower h until 5gh/(6e^2) + 2|u|^2/(3e^2) <= 0.98. Returns h, u, v and the mask
    of changed cells."""
    h, u, v = h.copy(), u.copy(), v.copy()
    hit = h < h_min
    h[hit] = h_min
    deep = g * h / e**2 > GH_LIMIT
    h[deep] = GH_LIMIT * e**2 / g
    hit |= deep
    s2 = u * u + v * v
    cap = np.minimum((u_ratio_max * e) ** 2, froude_max**2 * g * h)
    fast = s2 > cap
    scale = np.where(fast, np.sqrt(cap / np.where(fast, s2, 1.0)), 1.0)
    u, v = u * scale, v * scale
    hit |= fast
    s2 = u * u + v * v
    deep = 5 * g * h / (6 * e * e) + 2 * s2 / (3 * e * e) > F0_LIMIT
    h = np.where(deep, (F0_LIMIT - 2 * s2 / (3 * e * e)) * 6 * e * e / (5 * g), h)
    return h, u, v, hit | deep


def stream(f_post, h, bed, boundary: str, g, e, with_bed: bool):
    """Push every post-collision population one cell along e_a; walls reflect (slip: the crossing
    velocity component flips and the population stays in its row/column; noslip: it returns to
    its cell reversed). The bed force of the travelled link, -w g (h_from + h_to)/2 (z_to -
    z_from)/e^2, joins it on arrival."""
    _, ny, nx = f_post.shape
    out = np.zeros_like(f_post, dtype=np.float64)
    jj, ii = np.mgrid[0:ny, 0:nx]
    for a in range(9):
        cx, cy = C[a]
        ti, tj = ii + cx, jj + cy
        out_x = (ti < 0) | (ti >= nx)
        out_y = (tj < 0) | (tj >= ny)
        if boundary == "noslip":
            wall = out_x | out_y
            ti, tj = np.where(wall, ii, ti), np.where(wall, jj, tj)
            dirs = np.where(wall, direction(-cx, -cy), a)
        else:
            ti, tj = np.where(out_x, ii, ti), np.where(out_y, jj, tj)
            dirs = np.full(ii.shape, a)
            for mx in (False, True):
                for my in (False, True):
                    sel = (out_x == mx) & (out_y == my)
                    dirs[sel] = direction(-cx if mx else cx, -cy if my else cy)
        force = 0.0
        if with_bed:
            force = (-weight(a) * g * 0.5 * (h[tj, ti] + h) * (bed[tj, ti] - bed)) / e**2
        np.add.at(out, (dirs, tj, ti), f_post[a] + force)
    return out


def step(f_post, h_prev, bed, *, boundary, g, e, tau, drag_dt, h_min, u_ratio_max,
         froude_max, with_bed=True):
    """One step from stored post-collision populations and the depth they came from: stream
    (with the bed force), then moments, limiter, BGK collision with linear drag (momentum change
    -drag_dt * h u, split as w_a e_a.dM / e^2). Returns (post-collision f, depth, clamped mask)."""
    f = stream(np.asarray(f_post, np.float64), h_prev, bed, boundary, g, e, with_bed)
    h, u, v = macro(f, e)
    h2, u2, v2, hit = limit(h, u, v, g=g, e=e, h_min=h_min, u_ratio_max=u_ratio_max,
                            froude_max=froude_max)
    feq = feq_si(h2, u2, v2, g, e)
    out = f - (f - feq) / tau
    dmx, dmy = -drag_dt * h * u, -drag_dt * h * v
    for a in range(1, 9):
        out[a] += weight(a) * (C[a, 0] * dmx + C[a, 1] * dmy) / e
    out[:, hit] = feq[:, hit]
    return out, np.where(hit, h2, h), hit


def cell_centres(nx, ny, dx):
    jj, ii = np.mgrid[0:ny, 0:nx]
    return (ii + 0.5) * dx, (jj + 0.5) * dx


def drop(f_post, *, x, y, radius, height, dx, g, e, limits):
    """Raised-cosine drop added at constant velocity, keeping the non-equilibrium part."""
    _, ny, nx = f_post.shape
    px, py = cell_centres(nx, ny, dx)
    r = np.hypot(px - x, py - y)
    dh = np.where(r < radius, height * 0.5 * (1 + np.cos(np.pi * r / np.maximum(radius, 1e-300))),
                  0.0)
    inside = r < radius
    return _replace_eq(f_post, inside, dh, 0.0, 0.0, g=g, e=e, limits=limits)


def push(f_post, *, x, y, ddx, ddy, strength, radius, dx, g, e, limits):
    """Velocity strength * (1 - (d/radius)^2)^2 along the drag (d: distance to the segment)."""
    _, ny, nx = f_post.shape
    px, py = cell_centres(nx, ny, dx)
    L2 = ddx * ddx + ddy * ddy
    t = np.clip(((px - x) * ddx + (py - y) * ddy) / L2, 0, 1)
    d2 = ((px - x - t * ddx) ** 2 + (py - y - t * ddy) ** 2) / radius**2
    inside = d2 < 1
    k = np.where(inside, (1 - d2) ** 2 * strength, 0.0) / np.sqrt(L2)
    return _replace_eq(f_post, inside, 0.0, k * ddx, k * ddy, g=g, e=e, limits=limits)


def _replace_eq(f_post, inside, dh, du, dv, *, g, e, limits):
    f = np.asarray(f_post, np.float64)
    h, u, v = macro(f, e)
    h2, u2, v2, hit = limit(h + dh, u + du, v + dv, g=g, e=e, **limits)
    new = f + feq_si(h2, u2, v2, g, e) - feq_si(h, u, v, g, e)
    out = np.where(inside, new, f)
    return out, np.where(inside, h2, h), hit & inside


def surface(h, bed, dx, origin):
    """Vertices (ny, nx, 4) and unit normals (ny, nx, 4) of the surface eta = bed + h, Y up."""
    ny, nx = h.shape
    eta = np.asarray(bed, np.float64) + h
    px, pz = cell_centres(nx, ny, dx)
    verts = np.stack([origin[0] + px, origin[1] + eta, origin[2] + pz, np.zeros_like(px)], -1)
    pad = np.pad(eta, 1, mode="edge")  # the wall mirrors the height
    gx = (pad[1:-1, 2:] - pad[1:-1, :-2]) / (2 * dx)
    gz = (pad[2:, 1:-1] - pad[:-2, 1:-1]) / (2 * dx)
    n = np.stack([-gx, np.ones_like(gx), -gz], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return verts, np.concatenate([n, np.zeros_like(gx)[..., None]], -1)
