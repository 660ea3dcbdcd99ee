"""float64 NumPy reference of the caustics photons (kernels/caustics.cl): the same jittered
grid, brute-force closest hits (raytrace.render_reference.World), Snell with the interpolated
shading normal, Fresnel, Beer-Lambert, and the texel each photon lands in. Test use: tiny
scenes (a loop over triangles)."""

from __future__ import annotations

import numpy as np

from raytrace import render_reference as ref


def photon_origins(cp) -> tuple[np.ndarray, np.ndarray]:
    """Origins (n, 3) and the unit direction of a directional launch's photons (for a spot
    launch: its grid points on the water plane and the axis)."""
    gx, gz = int(cp["grid_x"]), int(cp["grid_z"])
    i = np.arange(gx * gz, dtype=np.uint64)
    key = ref.hash_u32((i * 0x9E3779B9 & 0xFFFFFFFF).astype(np.uint32)
                       ^ ref.hash_u32(np.uint32(cp["seed"])))
    jx, jz = ref.hash_unit(key), ref.hash_unit(key ^ np.uint32(0x68E31DA4))
    ex0, ez0, ex1, ez1 = (float(v) for v in cp["emit"])
    level = float(cp["light_dir"][3])
    d = np.asarray(cp["light_dir"][:3], np.float64)
    d /= np.linalg.norm(d)
    ix, iz = (i % gx).astype(float), (i // gx).astype(float)
    p = np.stack([ex0 + (ix + jx) * (ex1 - ex0) / gx, np.full(len(i), level),
                  ez0 + (iz + jz) * (ez1 - ez0) / gz], -1)
    if cp["light_pos"][3] > 0:
        return p, d
    return p - d * ((float(cp["emit_y"]) - level) / -d[1]), d


def photon_starts(cp) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origins, unit directions and fluxes (W, rgb) of a launch's photons, each (n, 3)."""
    p, axis = photon_origins(cp)
    flux = np.asarray(cp["flux"][:3], np.float64)
    if cp["light_pos"][3] <= 0:
        return p, np.tile(axis, (len(p), 1)), np.tile(flux, (len(p), 1))
    P = np.asarray(cp["light_pos"][:3], np.float64)
    to = p - P
    dist2 = np.sum(to * to, 1)
    d = to / np.sqrt(dist2)[:, None]
    lo, hi = float(cp["cos_outer"]), float(cp["cos_inner"])
    t = np.clip((d @ axis - lo) / max(hi - lo, 1e-7), 0.0, 1.0)
    cone = t * t * (3 - 2 * t)
    return np.tile(P, (len(p), 1)), d, flux * (cone * -d[:, 1] / dist2)[:, None]


def face_of(nf: np.ndarray) -> np.ndarray:
    """Atlas face of facing normals (n, 3), -1 for none (kernels/caustics.h caustic_face)."""
    conds = [nf[:, 1] > 0.5, nf[:, 2] > 0.5, nf[:, 2] < -0.5, nf[:, 0] > 0.5, nf[:, 0] < -0.5]
    return np.select(conds, list(range(5)), -1)


def texel_of(cp, f: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Atlas texel of points p (n, 3) on faces f (clamped into the face)."""
    nx, ny, nz = int(cp["nx"]), int(cp["ny"]), int(cp["nz"])
    lo = np.asarray(cp["box_lo"][:3], np.float64)
    tx = np.asarray(cp["texel"][:3], np.float64)
    q = (p - lo) / tx
    dims = [(nx, nz, 0), (nx, ny, nx * nz), (nx, ny, nx * nz + nx * ny),
            (nz, ny, nx * nz + 2 * nx * ny), (nz, ny, nx * nz + 2 * nx * ny + nz * ny)]
    axes = [(0, 2), (0, 1), (0, 1), (2, 1), (2, 1)]
    out = np.full(len(p), -1)
    for k in range(5):
        sel = f == k
        nu, nv, off = dims[k]
        a, b = axes[k]
        iu = np.clip(np.floor(q[sel, a]), 0, nu - 1).astype(int)
        iv = np.clip(np.floor(q[sel, b]), 0, nv - 1).astype(int)
        out[sel] = off + iv * nu + iu
    return out


def trace_photons(tables: dict, cp) -> dict:
    """Every photon of the launch ``cp``: where it lands (texel, -1: nowhere on the pool), the
    hit point and its flux (W, rgb) there."""
    world = ref.World(tables)
    mats = tables["materials"]
    o, d, phi = photon_starts(cp)
    n = len(o)
    medium = np.full(n, -1)
    alive = np.ones(n, bool)
    texel = np.full(n, -1)
    point = np.full((n, 3), np.nan)
    pool = int(cp["pool_instance"])
    for _ in range(3):
        idx = np.nonzero(alive)[0]
        if not len(idx):
            break
        t, j, u, v = world.intersect(o[idx], d[idx])
        miss = j < 0
        alive[idx[miss]] = False
        idx, t, j, u, v = idx[~miss], t[~miss], j[~miss], u[~miss], v[~miss]
        if not len(idx):
            break
        p, ng, ns, _, mat = world.surface(j, u, v)
        inside = medium[idx] >= 0
        sig = np.array([mats[m]["absorption"][:3] if m >= 0 else np.zeros(3)
                        for m in medium[idx]], np.float64)
        phi[idx] *= np.where(inside[:, None], np.exp(-sig * t[:, None]), 1.0)
        front = np.sum(d[idx] * ng, 1) < 0
        nf_g = np.where(front[:, None], ng, -ng)
        nf_s = np.where(front[:, None], ns, -ns)
        nf_s = np.where((np.sum(nf_s * d[idx], 1) >= 0)[:, None], nf_g, nf_s)
        ior = np.array([mats[m]["absorption"][3] for m in mat], np.float64)
        opaque = ior <= 0
        land = opaque & inside & (world.inst[j] == pool)
        f = face_of(nf_g)
        land &= f >= 0
        texel[idx[land]] = texel_of(cp, f[land], p[land])
        point[idx[land]] = p[land]
        stop = opaque | inside | ~front
        alive[idx[stop]] = False
        go = ~stop
        if not go.any():
            break
        g = idx[go]
        eta = 1.0 / ior[go]
        tdir, ok = ref.refract(d[g], nf_s[go], eta)
        bad = ok & (np.sum(tdir * nf_g[go], 1) >= 0)
        n_use = np.where(bad[:, None], nf_g[go], nf_s[go])
        t2, ok2 = ref.refract(d[g], nf_g[go], eta)
        tdir = np.where(bad[:, None], t2, tdir)
        ok = np.where(bad, ok2, ok)
        F = ref.fresnel(int(cp["fresnel"]), -np.sum(d[g] * n_use, 1), eta)
        phi[g] *= (1.0 - F)[:, None]
        alive[g[~ok]] = False
        medium[g] = mat[go]
        o[g] = p[go] - 1e-7 * nf_g[go]
        d[g] = tdir
    return {"texel": texel, "point": point, "flux": phi}


def texel_flux(tables: dict, cp) -> np.ndarray:
    """Flux (W, rgb) per atlas texel (n_texels, 3) of one photon launch."""
    r = trace_photons(tables, cp)
    out = np.zeros((int(cp["n_texels"]), 3))
    ok = r["texel"] >= 0
    np.add.at(out, r["texel"][ok], r["flux"][ok])
    return out
