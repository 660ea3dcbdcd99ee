"""Render a scene file to a PNG with the wavefront ray tracer (one still frame).

The water of a scene with [water] is the LBM solver's surface after [pool] steps (default 30)
from still water with the scene's drops; rain is not applied to a still. Example:

    lbwater render scenes/pool.toml -o pool.png --width 1280 --height 720 --spp 4
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from app.errors import InputError

#: Built-in materials used when a scene names none.
WATER = dict(diffuse=(0.0, 0.0, 0.0), specular=(1.0, 1.0, 1.0), shininess=400.0, ior=1.333,
             absorption=(0.45, 0.09, 0.06))
TILES = dict(diffuse=(0.9, 0.9, 0.9), specular=(0.1, 0.1, 0.1), shininess=30.0)
STONE = dict(diffuse=(0.55, 0.5, 0.45))


# ---- assets ---------------------------------------------------------------------------------
def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def load_texture(path: Path) -> np.ndarray:
    """An sRGB image file as linear float32 (h, w, 3|4), bottom row first (row 0 is v = 0)."""
    import imageio.v3 as iio

    try:
        img = np.asarray(iio.imread(path))
    except Exception as exc:  # imageio raises many kinds; the user needs one line
        raise InputError(f"{path}: unreadable image ({type(exc).__name__}: {exc})") from None
    if img.ndim == 2:
        img = img[..., None].repeat(3, axis=2)
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise InputError(f"{path}: image must be grey, RGB or RGBA, got shape {img.shape}")
    scale = 65535.0 if img.dtype == np.uint16 else 255.0
    c = img.astype(np.float64) / scale
    c[..., :3] = srgb_to_linear(c[..., :3])
    return np.ascontiguousarray(c[::-1], np.float32)




def mesh_transform(V: np.ndarray, position, rotation, size: float) -> np.ndarray:
    """world_from_object: bounding-box bottom centre to ``position``, largest extent ``size``
    (size 0 keeps the file's frame and only rotates and translates)."""
    M = np.eye(4)
    if size > 0:
        lo, hi = V.min(axis=0).astype(np.float64), V.max(axis=0).astype(np.float64)
        c = (lo + hi) / 2
        c[1] = lo[1]
        s = size / max(float((hi - lo).max()), 1e-30)
        M = np.diag([s, s, s, 1.0]) @ np.block([[np.eye(3), -c[:, None]], [np.zeros((1, 3)),
                                                                           np.ones((1, 1))]])
    R = np.eye(4)
    for axis, deg in zip((0, 1, 2), rotation, strict=True):
        a = math.radians(deg)
        c, s = math.cos(a), math.sin(a)
        i, j = [k for k in range(3) if k != axis]
        r = np.eye(4)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        R = r @ R
    T = np.eye(4)
    T[:3, 3] = position
    return T @ R @ M


# ---- scene -> renderer ------------------------------------------------------------------------
def _material(spec, rs, textures: dict):
    from raytrace.render_scene import Material

    tex = -1
    if spec.texture is not None:
        if spec.texture not in textures:
            textures[spec.texture] = rs.add_texture(load_texture(spec.texture))
        tex = textures[spec.texture]
    return Material(diffuse=spec.diffuse, specular=spec.specular, shininess=spec.shininess,
                    reflectivity=spec.reflectivity, ior=spec.ior, absorption=spec.absorption,
                    texture=tex, uv_scale=spec.uv_scale)


def _quad(p0, p1, p2, p3, tile: float, uv_axes):
    V = np.array([p0, p1, p2, p3], np.float32)
    uv = V[:, list(uv_axes)] / tile
    return V, np.array([[0, 1, 2], [0, 2, 3]], np.uint32), uv


def _pool_meshes(water, pool):
    """Floor, four inner walls (meeting the water mesh's edge vertices) and the deck, each
    (V, F, uv) with normals facing the pool's inside or up."""
    ox, oy, oz = water.origin
    sx, sz = water.size
    h = water.dx / 2
    x0, x1, z0, z1 = ox + h, ox + sx - h, oz + h, oz + sz - h
    y0, y1 = oy, oy + pool.wall_height
    t = pool.tile_size
    tiles = [
        _quad((x0, y0, z0), (x0, y0, z1), (x1, y0, z1), (x1, y0, z0), t, (0, 2)),  # floor, up
        _quad((x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), t, (0, 1)),  # z0 wall
        _quad((x1, y0, z1), (x0, y0, z1), (x0, y1, z1), (x1, y1, z1), t, (0, 1)),  # z1 wall
        _quad((x0, y0, z1), (x0, y0, z0), (x0, y1, z0), (x0, y1, z1), t, (2, 1)),  # x0 wall
        _quad((x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0), t, (2, 1)),  # x1 wall
    ]
    d = pool.deck
    deck = []
    if d > 0:
        X0, X1, Z0, Z1 = x0 - d, x1 + d, z0 - d, z1 + d
        deck = [
            _quad((X0, y1, Z0), (X0, y1, z0), (X1, y1, z0), (X1, y1, Z0), t, (0, 2)),
            _quad((X0, y1, z1), (X0, y1, Z1), (X1, y1, Z1), (X1, y1, z1), t, (0, 2)),
            _quad((X0, y1, z0), (X0, y1, z1), (x0, y1, z1), (x0, y1, z0), t, (0, 2)),
            _quad((x1, y1, z0), (x1, y1, z1), (X1, y1, z1), (X1, y1, z0), t, (0, 2)),
        ]

    def merge(quads):
        Vs, Fs, uvs, off = [], [], [], 0
        for V, F, uv in quads:
            Vs.append(V)
            Fs.append(F + off)
            uvs.append(uv)
            off += len(V)
        return np.concatenate(Vs), np.concatenate(Fs), np.concatenate(uvs)

    return merge(tiles), (merge(deck) if deck else None)




def build_world(scene, rt, *, width=None, height=None, spp=None, bounces=None, aov=False,
                water_steps=None):
    """A RenderScene, a Renderer (camera set) and the water solver (or None) for a scene."""
    import lbm
    from app.meshes import load_mesh, load_mesh_groups, mtl_path, read_mtl, smooth_normals
    from app.scene import check_material_names
    from raytrace.render import Renderer, RenderSettings
    from raytrace.render_scene import Material, RenderScene, Sky
    from raytrace.render_types import SkyKind

    check_material_names(scene)
    ex = scene.extra
    rs = RenderScene(rt)
    textures: dict = {}
    mats = {name: rs.add_material(_material(m, rs, textures))
            for name, m in ex.get("materials", {}).items()}
    shading = ex.get("shading")
    if shading is not None:
        rs.ambient = shading.ambient
    for li in ex.get("lights", ()):
        rs.add_light(li.kind, direction=li.direction, color=li.color, position=li.position,
                     inner_angle=li.inner_angle, outer_angle=li.outer_angle)
    sky = ex.get("sky")
    if sky is not None:
        cube = -1
        if sky.kind == "cubemap":
            cube = len(rs.textures)
            for p in sky.cubemap:
                rs.add_texture(load_texture(p))
        rs.set_sky(Sky(kind=SkyKind.from_str(sky.kind), zenith=sky.zenith, horizon=sky.horizon,
                       ground=sky.ground, sun_direction=sky.sun_direction,
                       sun_color=sky.sun_color, sun_radius=sky.sun_radius,
                       sun_glow=sky.sun_glow, cubemap=cube))

    def named(name: str, default: dict, tex: Path | None = None, tile: float = 1.0) -> int:
        if name:
            return mats[name]
        key = f"<builtin {id(default)} {tex}>"
        if key not in mats:
            t = -1
            if tex is not None:
                if tex not in textures:
                    textures[tex] = rs.add_texture(load_texture(tex))
                t = textures[tex]
            mats[key] = rs.add_material(Material(**default, texture=t))
        return mats[key]

    for m in ex.get("meshes", ()):
        V, F = load_mesh(m.file)
        M = mesh_transform(V, m.position, m.rotation, m.size)
        normals = smooth_normals(V, F) if m.smooth else None
        groups = None if m.material else load_mesh_groups(m.file, len(F))
        if m.material:
            mesh = rs.add_mesh(V, F, normals=normals, material=mats[m.material])
        elif groups is not None:
            ids, names = groups
            mtl = read_mtl(mtl_path(m.file))
            table = []
            for name in names:
                if name in m.materials:
                    table.append(mats[m.materials[name]])
                    continue
                c = mtl.get(name, {})
                ks = np.asarray(c.get("Ks", (0.0, 0.0, 0.0))) * 0.25
                table.append(named("", {"diffuse": tuple(c.get("Kd", (0.8, 0.8, 0.8))),
                                        "specular": tuple(np.clip(ks, 0, 1)),
                                        "shininess": float(min(c.get("Ns", 32.0), 1e4))}))
            tri_mat = np.asarray(table, np.int64)[np.clip(ids, 0, len(table) - 1)]
            mesh = rs.add_mesh(V, F, normals=normals, tri_materials=tri_mat)
        else:
            mesh = rs.add_mesh(V, F, normals=normals, material=named("", TILES | {
                "specular": (0.2, 0.2, 0.2)}))
        rs.add_instance(mesh, M)

    sim = None
    if scene.water is not None:
        w = scene.water
        pool = ex.get("pool")
        nx, ny = w.cells
        sim = lbm.ShallowWater(nx, ny, w.dx, boundary=w.boundary, device=rt, depth=w.depth,
                               viscosity=w.viscosity, expected_speed=w.expected_speed)
        for d in w.drops:
            sim.add_drop(d.x, d.y, d.radius, d.height)
        steps = water_steps if water_steps is not None else (pool.steps if pool else 30)
        if steps:
            sim.step(int(steps))
        vbuf, nbuf = rt.buffer(16 * nx * ny), rt.buffer(16 * nx * ny)
        sim.write_surface(vbuf, nbuf, w.origin)
        water_mat = named(pool.water_material if pool else "", WATER)
        mesh = rs.add_mesh(vbuf, lbm.grid_triangles(nx, ny), normals=nbuf, material=water_mat,
                           dynamic=True, n_vertices=nx * ny)
        rs.add_instance(mesh)
        if pool is not None:
            (Vp, Fp, uvp), deck = _pool_meshes(w, pool)
            tile_mat = named(pool.floor_material, TILES, pool.floor_texture)
            rs.add_instance(rs.add_mesh(Vp, Fp, uvs=uvp, material=tile_mat))
            if deck is not None:
                Vd, Fd, uvd = deck
                rs.add_instance(rs.add_mesh(Vd, Fd, uvs=uvd,
                                            material=named(pool.deck_material, STONE)))
    if not rs.meshes:
        raise InputError(f"{scene.path}: the scene has nothing to render (no [[meshes]], no "
                         "[water])")
    r = scene.render
    settings = RenderSettings(
        width=width or r.width, height=height or r.height, spp=spp or r.spp,
        bounces=r.bounces if bounces is None else bounces, aov=aov,
        pattern=None if shading is None or shading.pattern == "auto" else shading.pattern,
        order=shading.order if shading else "tiles",
        fresnel=shading.fresnel if shading else "exact",
        tonemap=shading.tonemap if shading else "aces",
        exposure=shading.exposure if shading else 1.0,
        min_weight=shading.min_contribution if shading else 1e-3,
        seed=shading.seed if shading else 0)
    renderer = Renderer(rt, rs, settings)
    c = scene.camera
    renderer.set_camera(c.eye, c.target, c.up, c.fov)
    return rs, renderer, sim


# ---- the command ----------------------------------------------------------------------------
def add_arguments(p) -> None:
    p.add_argument("scene", help="scene TOML file")
    p.add_argument("-o", "--output", required=True, help="PNG file to write")
    p.add_argument("--width", type=int, help="image width (px); default from [render]")
    p.add_argument("--height", type=int, help="image height (px)")
    p.add_argument("--spp", type=int, help="samples per pixel")
    p.add_argument("--bounces", type=int, help="maximum reflection/refraction depth")
    p.add_argument("--device", help="OpenCL device: gpu, cpu, P:D or part of a name")
    p.add_argument("--aov", help="also write primary depth, normal, prim and instance ids (.npz)")


def _check_args(args) -> None:
    out = Path(args.output)
    if out.suffix.lower() != ".png":
        raise InputError(f"--output {args.output!r} must end in .png")
    if args.aov is not None and Path(args.aov).suffix.lower() != ".npz":
        raise InputError(f"--aov {args.aov!r} must end in .npz")
    for name, lo, hi in (("width", 1, 16384), ("height", 1, 16384), ("spp", 1, 4096),
                         ("bounces", 0, 32)):
        v = getattr(args, name)
        if v is not None and not lo <= v <= hi:
            raise InputError(f"--{name} {v} is out of range; allowed [{lo}, {hi}]")


def run(args) -> int:
    from app.io import atomic_path
    from app.scene import load_scene
    from kernels import get_runtime

    _check_args(args)
    scene = load_scene(args.scene)
    rt = get_runtime(args.device)
    t0 = time.perf_counter()
    rs, renderer, _ = build_world(scene, rt, width=args.width, height=args.height, spp=args.spp,
                                  bounces=args.bounces, aov=args.aov is not None)
    img = renderer.render()
    elapsed = time.perf_counter() - t0
    fb = renderer.read_framebuffer()
    if not np.isfinite(fb).all():
        raise InputError(f"{args.scene}: the render produced non-finite pixels")
    import imageio.v3 as iio

    with atomic_path(args.output) as tmp:
        iio.imwrite(tmp, img, extension=".png")
    if args.aov is not None:
        aov = renderer.read_aov()
        with atomic_path(args.aov, suffix=".partial.npz") as tmp:
            np.savez_compressed(tmp, **aov)
    stats = renderer.read_stats()
    s = renderer.settings
    print(f"{args.output}: {s.width}x{s.height}, {s.spp} spp, {s.bounces} bounces, "
          f"{rs.n_triangles} triangles, {sum(stats['rays_per_depth'])} rays, "
          f"{elapsed:.2f} s on {rt.name}")
    return 0
