"""The renderer's pipeline in float64 NumPy, for tests on tiny scenes.

It follows the same rules as the kernels (camera and samples, Whitted shading with shadow rays,
Fresnel, total internal reflection, Beer-Lambert, contribution cut-off, tonemap) but computes them
independently: brute-force float64 ray/triangle tests over every world-space triangle, recursion
over a plain list of rays, no BVH, no offsets beyond a tiny float64 epsilon. The inputs are the
host tables of a :class:`raytrace.render_scene.RenderScene` and a :class:`Camera` record.
"""

from __future__ import annotations

import numpy as np

from raytrace.render_types import (
    MESH_HAS_NORMALS,
    MESH_HAS_UVS,
    MESH_TRI_MATERIALS,
    FresnelMode,
    LightKind,
    PixelOrder,
    SamplePattern,
    SkyKind,
    Tonemap,
)

EPS = 1e-9  # float64 origin offset along the normal (m), relative to 1 + |p|


# ---- samples and camera -------------------------------------------------------------------------
def hash_u32(x) -> np.ndarray:
    x = np.array(x, dtype=np.uint32, copy=True)
    x ^= x >> np.uint32(16)
    x *= np.uint32(0x7FEB352D)
    x ^= x >> np.uint32(15)
    x *= np.uint32(0x846CA68B)
    x ^= x >> np.uint32(16)
    return x


def hash_unit(x) -> np.ndarray:
    return (hash_u32(x) >> np.uint32(8)).astype(np.float64) / 16777216.0


def sample_offsets(cam, pixel_index: np.ndarray, s: np.ndarray) -> np.ndarray:
    pattern = SamplePattern(int(cam["pattern"]))
    n = len(pixel_index)
    if pattern == SamplePattern.CENTER:
        return np.full((n, 2), 0.5)
    if pattern == SamplePattern.RGSS:
        xs = np.array([0.375, 0.875, 0.125, 0.625])
        k = s & 3
        return np.stack([xs[k], 0.125 + 0.25 * k], axis=1)
    cols = int(cam["jitter_cols"])
    rows = int(cam["spp"]) // cols
    s = s.astype(np.uint32)
    pix = pixel_index.astype(np.uint32)
    seed = np.array([int(cam["seed"])], np.uint32)
    key = hash_u32((pix * np.uint32(0x9E3779B9)) ^ hash_u32(s + seed * np.uint32(0x85EBCA6B)))
    jx = hash_unit(key)
    jy = hash_unit(key ^ np.uint32(0x68E31DA4))
    return np.stack([((s % cols) + jx) / cols, ((s // cols) + jy) / rows], axis=1)


def pixel_of(cam, q: np.ndarray):
    """Tile-order ids -> (x, y, inside)."""
    w, h = int(cam["width"]), int(cam["height"])
    q = q.astype(np.int64)
    if PixelOrder(int(cam["order"])) == PixelOrder.ROWS:
        x, y = q % w, q // w
    else:
        tile, m = q >> 6, q & 63
        mx = sum(((m >> (2 * b)) & 1) << b for b in range(3))
        my = sum(((m >> (2 * b + 1)) & 1) << b for b in range(3))
        tx = int(cam["tiles_x"])
        x, y = (tile % tx) * 8 + mx, (tile // tx) * 8 + my
    return x, y, (x < w) & (y < h)


def n_tile_pixels(cam) -> int:
    w, h = int(cam["width"]), int(cam["height"])
    if PixelOrder(int(cam["order"])) == PixelOrder.ROWS:
        return w * h
    return int(cam["tiles_x"]) * (-(-h // 8)) * 64


def primary_rays(cam):
    """(origins, unit directions, weights, pixel (x, y)) for every live primary sample."""
    spp = int(cam["spp"])
    nq = n_tile_pixels(cam)
    q = np.repeat(np.arange(nq), spp)
    s = np.tile(np.arange(spp), nq)
    x, y, inside = pixel_of(cam, q)
    q, s, x, y = q[inside], s[inside], x[inside], y[inside]
    w, h = int(cam["width"]), int(cam["height"])
    off = sample_offsets(cam, y * w + x, s)
    sx = 2.0 * ((x + off[:, 0]) / w) - 1.0
    sy = 1.0 - 2.0 * ((y + off[:, 1]) / h)
    f = cam["forward"][:3].astype(np.float64)
    d = f + sx[:, None] * cam["right"][:3].astype(np.float64) \
        + sy[:, None] * cam["up"][:3].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(cam["origin"][:3].astype(np.float64), d.shape).copy()
    return o, d, np.full(len(d), 1.0 / spp), np.stack([x, y], axis=1), s


# ---- optics -------------------------------------------------------------------------------------
def reflect(d, n):
    return d - 2.0 * np.sum(d * n, axis=-1, keepdims=True) * n


def refract(d, n, eta):
    """Snell for unit d, unit n facing the incoming side, eta = n_from/n_to: (t, ok)."""
    eta = np.broadcast_to(np.asarray(eta, np.float64), d.shape[:-1])
    cosi = -np.sum(d * n, axis=-1)
    sin2t = eta**2 * np.maximum(0.0, 1.0 - cosi**2)
    ok = sin2t < 1.0
    cost = np.sqrt(np.maximum(0.0, 1.0 - sin2t))
    t = eta[..., None] * d + (eta * cosi - cost)[..., None] * n
    t /= np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-300)
    return t, ok


def fresnel_exact(cosi, eta):
    cosi, eta = np.broadcast_arrays(np.asarray(cosi, np.float64), np.asarray(eta, np.float64))
    sin2t = eta**2 * np.maximum(0.0, 1.0 - cosi**2)
    cost = np.sqrt(np.maximum(0.0, 1.0 - sin2t))
    rs = (eta * cosi - cost) / (eta * cosi + cost)
    rp = (cosi - eta * cost) / (cosi + eta * cost)
    return np.where(sin2t >= 1.0, 1.0, 0.5 * (rs**2 + rp**2))


def fresnel_schlick(cosi, eta):
    cosi, eta = np.broadcast_arrays(np.asarray(cosi, np.float64), np.asarray(eta, np.float64))
    r0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    sin2t = eta**2 * np.maximum(0.0, 1.0 - cosi**2)
    c = np.where(eta > 1.0, np.sqrt(np.maximum(0.0, 1.0 - sin2t)), cosi)
    out = r0 + (1.0 - r0) * (1.0 - c) ** 5
    return np.where((eta > 1.0) & (sin2t >= 1.0), 1.0, out)


def fresnel(mode, cosi, eta):
    if FresnelMode(int(mode)) == FresnelMode.SCHLICK:
        return fresnel_schlick(cosi, eta)
    return fresnel_exact(cosi, eta)


def sky_procedural(d, prm):
    hor = prm["sky_horizon"][:3].astype(np.float64)
    zen = prm["sky_zenith"][:3].astype(np.float64)
    gnd = prm["sky_ground"][:3].astype(np.float64)
    y = d[:, 1:2]
    up = hor + (zen - hor) * np.sqrt(np.maximum(y, 0.0))
    down = hor + (gnd - hor) * np.minimum(1.0, -10.0 * y)
    c = np.where(y >= 0.0, up, down)
    sun = prm["sun_dir"].astype(np.float64)
    col = prm["sun_color"].astype(np.float64)
    cs = d @ sun[:3]
    c = c + np.where(cs >= sun[3], 1.0, 0.0)[:, None] * col[:3]
    return c + col[:3] * (col[3] * np.maximum(cs, 0.0) ** 64)[:, None]


def tex_bilinear(tex: np.ndarray, uv: np.ndarray, wrap: bool = True) -> np.ndarray:
    h, w = tex.shape[:2]
    uv = uv - np.floor(uv) if wrap else np.clip(uv, 0.0, 1.0)
    x = uv[:, 0] * w - 0.5
    y = uv[:, 1] * h - 0.5
    fx, fy = np.floor(x), np.floor(y)
    ax, ay = (x - fx)[:, None], (y - fy)[:, None]
    x0, y0 = fx.astype(np.int64), fy.astype(np.int64)
    if wrap:
        x0, x1, y0, y1 = x0 % w, (x0 + 1) % w, y0 % h, (y0 + 1) % h
    else:
        x1, y1 = np.clip(x0 + 1, 0, w - 1), np.clip(y0 + 1, 0, h - 1)
        x0, y0 = np.clip(x0, 0, w - 1), np.clip(y0, 0, h - 1)
    t = tex.astype(np.float64)
    return ((t[y0, x0] * (1 - ax) + t[y0, x1] * ax) * (1 - ay)
            + (t[y1, x0] * (1 - ax) + t[y1, x1] * ax) * ay)


def tonemap(c, op):
    c = np.maximum(c, 0.0)
    op = Tonemap(int(op))
    if op == Tonemap.REINHARD:
        return c / (1.0 + c)
    if op == Tonemap.ACES:
        return np.clip((c * (2.51 * c + 0.03)) / (c * (2.43 * c + 0.59) + 0.14), 0.0, 1.0)
    return np.clip(c, 0.0, 1.0)


def srgb_encode(c):
    hi = 1.055 * np.power(np.maximum(c, 0.0), 1 / 2.4) - 0.055
    return np.where(c <= 0.0031308, 12.92 * c, hi)


def to_rgba8(fb: np.ndarray, prm) -> np.ndarray:
    c = srgb_encode(tonemap(fb * float(prm["exposure"][0]), prm["tonemap"]))
    rgb = (np.clip(c, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    return np.concatenate([rgb, np.full(rgb.shape[:-1] + (1,), 255, np.uint8)], axis=-1)


# ---- geometry -----------------------------------------------------------------------------------
class World:
    """Every triangle of every instance in world space, float64, with what shading needs."""

    def __init__(self, tables: dict):
        self.t = tables
        p0, p1, p2, inst, prim = [], [], [], [], []
        for k, rec in enumerate(tables["instances"]):
            mesh = tables["meshes"][int(rec["mesh"])]
            V = mesh["vertices"].astype(np.float64)
            F = mesh["triangles"].astype(np.int64)
            M = rec["world_from_object"].astype(np.float64)
            W = V @ M[:, :3].T + M[:, 3]
            p0.append(W[F[:, 0]])
            p1.append(W[F[:, 1]])
            p2.append(W[F[:, 2]])
            inst.append(np.full(len(F), k))
            prim.append(np.arange(len(F)))
        self.p0, self.p1, self.p2 = (np.concatenate(a) for a in (p0, p1, p2))
        self.inst, self.prim = np.concatenate(inst), np.concatenate(prim)

    def intersect(self, o, d, tmax=None):
        """Closest hits (float64 Moller-Trumbore): t (inf on a miss), index, u, v."""
        e1 = self.p1 - self.p0
        e2 = self.p2 - self.p0
        n = len(o)
        best_t = np.full(n, np.inf) if tmax is None else np.asarray(tmax, np.float64).copy()
        best = np.full(n, -1)
        bu, bv = np.zeros(n), np.zeros(n)
        for j in range(len(self.p0)):
            pv = np.cross(d, e2[j])
            det = pv @ e1[j]
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = 1.0 / det
                tv = o - self.p0[j]
                u = np.sum(tv * pv, axis=1) * inv
                qv = np.cross(tv, e1[j])
                v = np.sum(d * qv, axis=1) * inv
                t = (qv @ e2[j]) * inv
            ok = (np.abs(det) > 1e-300) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) \
                & (t < best_t)
            best_t = np.where(ok, t, best_t)
            best = np.where(ok, j, best)
            bu, bv = np.where(ok, u, bu), np.where(ok, v, bv)
        if tmax is not None:
            best_t = np.where(best < 0, np.inf, best_t)
        return best_t, best, bu, bv

    def surface(self, j, u, v):
        """Position, unit geometric and shading normals, diffuse colour and material id."""
        t = self.t
        w = 1.0 - u - v
        p = w[:, None] * self.p0[j] + u[:, None] * self.p1[j] + v[:, None] * self.p2[j]
        ng = np.cross(self.p1[j] - self.p0[j], self.p2[j] - self.p0[j])
        ng /= np.linalg.norm(ng, axis=1, keepdims=True)
        ns = ng.copy()
        kd = np.zeros((len(j), 3))
        mat = np.zeros(len(j), np.int64)
        for k in range(len(j)):
            rec = t["instances"][self.inst[j[k]]]
            mesh = t["meshes"][int(rec["mesh"])]
            tri = mesh["triangles"][self.prim[j[k]]]
            M = rec["world_from_object"].astype(np.float64)
            nrm_m = np.linalg.inv(M[:, :3]).T
            if mesh["flags"] & MESH_HAS_NORMALS:
                nn = mesh["normals"][tri].astype(np.float64)
                nv = w[k] * nn[0] + u[k] * nn[1] + v[k] * nn[2]
                if nv @ nv > 1e-20:
                    nv = nrm_m @ nv
                    nv /= np.linalg.norm(nv)
                    ns[k] = nv if nv @ ng[k] >= 0 else -nv
            if int(rec["material"]) >= 0:
                mat[k] = int(rec["material"])
            elif mesh["flags"] & MESH_TRI_MATERIALS:
                mat[k] = int(mesh["tri_materials"][self.prim[j[k]]])
            else:
                mat[k] = int(mesh["material"])
            m = t["materials"][mat[k]]
            kd[k] = m["diffuse"][:3]
            if int(m["texture"]) >= 0 and mesh["flags"] & MESH_HAS_UVS:
                uv = mesh["uvs"][tri].astype(np.float64)
                uvk = (w[k] * uv[0] + u[k] * uv[1] + v[k] * uv[2]) \
                    * np.array([m["uv_scale_u"], m["uv_scale_v"]], np.float64)
                kd[k] *= tex_bilinear(t["textures"][int(m["texture"])], uvk[None])[0, :3]
        return p, ng, ns, kd, mat


def _edge_distance(u, v):
    return np.minimum(np.minimum(u, v), 1.0 - u - v)


# ---- the pipeline -------------------------------------------------------------------------------
def render(tables: dict, cam, prm, lights) -> dict:
    """Linear framebuffer (H, W, 3), RGBA8 image, primary AOVs, a per-pixel 'fragile' flag and
    the number of shadow rays traced (``shadow_rays``).

    A pixel is fragile when one of its rays hits within 1e-4 (barycentric) of a triangle edge or
    within 1e-6 of the total-internal-reflection or cut-off thresholds, where float32 and float64
    may take different branches.
    """
    world = World(tables)
    mats = tables["materials"]
    W, H = int(cam["width"]), int(cam["height"])
    fb = np.zeros((H, W, 3))
    fragile = np.zeros((H, W), bool)
    o, d, wgt, pix, samples = primary_rays(cam)
    w3 = np.repeat(wgt[:, None], 3, axis=1)
    medium = np.full(len(o), -1)
    aov_depth = np.full((H, W), np.inf)
    aov_prim = np.full((H, W), -1)
    aov_inst = np.full((H, W), -1)
    max_depth = int(prm["max_depth"])
    min_w = float(prm["min_weight"])
    mode = int(prm["fresnel"])
    shadow_rays = 0
    for depth in range(max_depth + 1):
        if len(o) == 0:
            break
        t, j, u, v = world.intersect(o, d)
        hit = j >= 0
        sigma = np.zeros((len(o), 3))
        inside = medium >= 0
        sigma[inside] = np.stack([mats[m]["absorption"][:3] for m in medium[inside]]) \
            if inside.any() else sigma[inside]
        with np.errstate(invalid="ignore", over="ignore"):
            att = np.exp(-sigma * np.minimum(t, 1e30)[:, None])
        w_att = w3 * att
        L = np.zeros((len(o), 3))
        miss = ~hit
        if miss.any():
            if SkyKind(int(prm["sky"])) != SkyKind.PROCEDURAL:
                raise NotImplementedError("the reference renders the procedural sky only")
            L[miss] = w_att[miss] * sky_procedural(d[miss], prm)
        hi = np.flatnonzero(hit)
        if depth == 0:
            primary = np.zeros(len(o), bool)
            primary[hi] = samples[hi] == 0
            sel = hi[samples[hi] == 0]
            aov_depth[pix[sel, 1], pix[sel, 0]] = t[sel]
            aov_prim[pix[sel, 1], pix[sel, 0]] = world.prim[j[sel]]
            aov_inst[pix[sel, 1], pix[sel, 0]] = world.inst[j[sel]]
        child_o, child_d, child_w, child_m, child_pix = [], [], [], [], []
        if len(hi):
            fr = _edge_distance(u[hi], v[hi]) < 1e-4
            fragile[pix[hi[fr], 1], pix[hi[fr], 0]] = True
            p, ng, ns, kd, mat = world.surface(j[hi], u[hi], v[hi])
            for k, i in enumerate(hi):
                m = mats[mat[k]]
                diel = m["absorption"][3] > 0
                dfrac = 1.0 if diel else 1.0 - float(m["reflectivity"])
                wk = w_att[i]
                front = d[i] @ ng[k] < 0
                nfg = ng[k] if front else -ng[k]
                nfs = ns[k] if front else -ns[k]
                if nfs @ d[i] >= 0:
                    nfs = nfg
                Lk = wk * dfrac * prm["ambient"][:3] * kd[k]
                direct, near_cut, n_sh = _direct(world, mats, lights, prm, p[k], nfg, nfs,
                                                 d[i], kd[k], m, medium[i], wk * dfrac, min_w)
                shadow_rays += n_sh
                Lk = Lk + wk * dfrac * direct
                if near_cut:
                    fragile[pix[i, 1], pix[i, 0]] = True
                L[i] = Lk
                if depth >= max_depth:
                    continue
                if diel:
                    ior = float(m["absorption"][3])
                    eta = 1.0 / ior if front else ior
                    n_use = nfs
                    tdir, ok = refract(d[i][None], n_use[None], eta)
                    if ok[0] and tdir[0] @ nfg >= 0:
                        n_use = nfg
                        tdir, ok = refract(d[i][None], n_use[None], eta)
                    cosi = -(d[i] @ n_use)
                    sin2t = eta**2 * (1 - cosi**2)
                    if abs(sin2t - 1.0) < 1e-5:
                        fragile[pix[i, 1], pix[i, 0]] = True
                    F = float(fresnel(mode, cosi, eta)) if ok[0] else 1.0
                    w_refl, w_refr = wk * F, (wk * (1 - F) if ok[0] else np.zeros(3))
                    refr_med = int(mat[k]) if front else -1
                else:
                    w_refl, w_refr, refr_med = wk * float(m["reflectivity"]), np.zeros(3), -1
                for wc in (w_refl, w_refr):
                    if min_w > 0 and abs(wc.max() - min_w) < 1e-6 * min_w:
                        fragile[pix[i, 1], pix[i, 0]] = True
                if w_refl.max() > 0 and w_refl.max() >= min_w:
                    rd = reflect(d[i], nfs)
                    if rd @ nfg <= 0:
                        rd = reflect(d[i], nfg)
                    child_o.append(p[k] + EPS * (1 + np.abs(p[k]).max()) * nfg)
                    child_d.append(rd)
                    child_w.append(w_refl)
                    child_m.append(medium[i])
                    child_pix.append((pix[i], samples[i]))
                if w_refr.max() > 0 and w_refr.max() >= min_w:
                    child_o.append(p[k] - EPS * (1 + np.abs(p[k]).max()) * nfg)
                    child_d.append(tdir[0])
                    child_w.append(w_refr)
                    child_m.append(refr_med)
                    child_pix.append((pix[i], samples[i]))
        np.add.at(fb, (pix[:, 1], pix[:, 0]), L)
        if not child_o:
            break
        o, d, w3 = np.array(child_o), np.array(child_d), np.array(child_w)
        medium = np.array(child_m)
        pix = np.array([c[0] for c in child_pix])
        samples = np.array([c[1] for c in child_pix])
    return {"framebuffer": fb, "rgba": to_rgba8(fb, prm), "fragile": fragile,
            "depth": aov_depth, "prim": aov_prim, "inst": aov_inst, "shadow_rays": shadow_rays}


def _direct(world, mats, lights, prm, p, nfg, nfs, d, kd, m, medium, w, min_w):
    """Direct light at a hit, whether a light's share came within rounding of the cut-off
    (below ``min_w`` of the pixel, a light is added unshadowed, with no shadow ray), and the
    number of shadow rays traced."""
    total = np.zeros(3)
    near_cut = False
    n_rays = 0
    org = p + EPS * (1 + np.abs(p).max()) * nfg
    for li in lights[: int(prm["n_lights"])]:
        if LightKind(int(li["kind"])) == LightKind.SPOT:
            to = li["position"][:3].astype(np.float64) - p
            dist = float(np.linalg.norm(to))
            ldir = to / dist
            c = -(ldir @ li["direction"][:3].astype(np.float64))
            co, ci = float(li["cos_outer"]), float(li["cos_inner"])
            s = np.clip((c - co) / max(ci - co, 1e-7), 0.0, 1.0)
            E = li["color"][:3].astype(np.float64) * (s * s * (3 - 2 * s)) / dist**2
        else:
            ldir = -li["direction"][:3].astype(np.float64)
            dist = np.inf
            E = li["color"][:3].astype(np.float64)
        ndl = nfs @ ldir
        if ndl <= 0 or nfg @ ldir <= 0 or E.max() <= 0:
            continue
        rv = max(reflect(-ldir, nfs) @ (-d), 0.0)
        shin = float(m["specular"][3])
        spec = rv**shin if shin > 0 else 1.0
        brdf = kd * ndl + m["specular"][:3] * spec
        share = float((w * E * brdf).max())
        if min_w > 0 and abs(share - min_w) < 1e-3 * min_w:
            near_cut = True
        if share < min_w:
            total += E * brdf
            continue
        n_rays += 1
        T = _transmittance(world, mats, prm, org, ldir, dist, medium)
        if T.max() <= 0:
            continue
        total += T * E * brdf
    return total, near_cut, n_rays


def _transmittance(world, mats, prm, org, ldir, tmax, medium):
    transmissive = bool(prm["transmissive_shadows"])
    T = np.ones(3)
    for _ in range(4 if transmissive else 1):
        t, j, u, v = world.intersect(org[None], ldir[None], tmax=np.array([tmax]))
        if j[0] < 0:
            if medium >= 0:
                with np.errstate(over="ignore"):
                    T = T * np.exp(-mats[medium]["absorption"][:3] * min(tmax, 1e30))
            return T
        if not transmissive:
            return np.zeros(3)
        p, ng, ns, kd, mat = world.surface(j, u, v)
        m = mats[mat[0]]
        if m["absorption"][3] <= 0:
            return np.zeros(3)
        if medium >= 0:
            T = T * np.exp(-mats[medium]["absorption"][:3] * t[0])
        front = ldir @ ng[0] < 0
        nfg = ng[0] if front else -ng[0]
        ior = float(m["absorption"][3])
        eta = 1.0 / ior if front else ior
        T = T * (1.0 - float(fresnel(prm["fresnel"], -(ldir @ nfg), eta)))
        medium = int(mat[0]) if front else -1
        org = p[0] - EPS * (1 + np.abs(p[0]).max()) * nfg
        tmax = tmax - t[0]
    return np.zeros(3)
