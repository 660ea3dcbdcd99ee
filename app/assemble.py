"""Scene assembly: a validated scene spec (:class:`app.scene.Scene`) becomes the things a frame
drives: the water solver, the render scene (meshes, materials, textures, lights, sky) and the
renderer. Nothing here runs per frame; :mod:`app.world` owns the frame.

The water surface is a dynamic mesh whose vertex and normal buffers the solver writes each
frame (``sim.write_surface``); the BVH refits over them and the shader reads them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from app.assets import (
    STONE,
    TILES,
    WATER,
    load_texture,
    material_from_spec,
    mesh_transform,
    pool_meshes,
)
from app.errors import InputError
from app.scene import Scene, WaterSpec, check_material_names


@dataclasses.dataclass
class WaterSurface:
    """The water mesh in the render scene and the device buffers the solver writes."""

    mesh: int
    instance: int
    vertices: object   #: cl.Buffer, float4 per cell
    normals: object    #: cl.Buffer, float4 per cell
    origin: tuple


@dataclasses.dataclass
class Assembly:
    """What :func:`assemble` makes of a scene on one runtime."""

    render_scene: object            #: raytrace.render_scene.RenderScene
    sim: object | None              #: lbm.ShallowWater or None (no [water])
    water: WaterSurface | None
    instances: dict                 #: instance id -> what it is ("water", "pool", mesh file)
    caustic_box: object | None = None  #: raytrace.caustics.PoolBox (a pool with water) or None
    boat_instances: list = dataclasses.field(default_factory=list)  #: [[boats]] instance ids
    boats: object | None = None     #: lbm.bodies.Boats stepped with the water, or None


def resized_water(water: WaterSpec, cells: int) -> WaterSpec:
    """``water`` with ``cells`` cells along its longer side (square cells, same pool size);
    drops keep their places."""
    if not 2 <= int(cells) <= 16384:
        raise InputError(f"cells {cells} is out of range; allowed [2, 16384]")
    sx, sy = water.size
    nx, ny = ((cells, max(2, round(cells * sy / sx))) if sx >= sy
              else (max(2, round(cells * sx / sy)), cells))
    dx = sx / nx
    size = (sx, ny * dx)
    drops = tuple(d for d in water.drops if d.x <= size[0] and d.y <= size[1])
    return dataclasses.replace(water, cells=(int(nx), int(ny)), size=size, drops=drops)


class _Builder:
    """Fills one RenderScene from a scene spec; materials and textures are made once each."""

    def __init__(self, scene: Scene, rt):
        from raytrace.render_scene import RenderScene

        self.scene, self.rt = scene, rt
        self.rs = RenderScene(rt)
        self.textures: dict = {}
        self.materials: dict = {}
        self.instances: dict = {}
        self.boat_instances: list = []   #: instance ids of the [[boats]], in order

    def texture(self, path: Path) -> int:
        if path not in self.textures:
            self.textures[path] = self.rs.add_texture(load_texture(path))
        return self.textures[path]

    def material(self, name: str, default: dict, texture: Path | None = None) -> int:
        """The scene's material ``name``, or a built-in one (``default``) when name is empty."""
        from raytrace.render_scene import Material

        if name:
            return self.materials[name]
        key = f"<builtin {sorted(default.items())} {texture}>"
        if key not in self.materials:
            tex = -1 if texture is None else self.texture(texture)
            self.materials[key] = self.rs.add_material(Material(**default, texture=tex))
        return self.materials[key]

    def materials_lights_sky(self) -> None:
        from raytrace.render_scene import Sky
        from raytrace.render_types import SkyKind

        rs, sc = self.rs, self.scene
        for name, m in sc.materials.items():
            self.materials[name] = rs.add_material(material_from_spec(m, rs, self.textures))
        if sc.shading is not None:
            rs.ambient = sc.shading.ambient
        for li in sc.lights:
            rs.add_light(li.kind, direction=li.direction, color=li.color, position=li.position,
                         inner_angle=li.inner_angle, outer_angle=li.outer_angle)
        sky = sc.sky
        if sky is not None:
            cube = -1
            if sky.kind == "cubemap":
                cube = len(rs.textures)
                for p in sky.cubemap:
                    rs.add_texture(load_texture(p))
            rs.set_sky(Sky(kind=SkyKind.from_str(sky.kind), zenith=sky.zenith,
                           horizon=sky.horizon, ground=sky.ground,
                           sun_direction=sky.sun_direction, sun_color=sky.sun_color,
                           sun_radius=sky.sun_radius, sun_glow=sky.sun_glow, cubemap=cube))

    def mtl_table(self, m, names) -> list[int]:
        """Material ids for a mesh's MTL groups: the scene's mapping, else the MTL colours."""
        from app.meshes import mtl_path, read_mtl

        mtl = read_mtl(mtl_path(m.file))
        table = []
        for name in names:
            if name in m.materials:
                table.append(self.materials[m.materials[name]])
                continue
            c = mtl.get(name, {})
            ks = np.clip(np.asarray(c.get("Ks", (0.0, 0.0, 0.0))) * 0.25, 0, 1)
            table.append(self.material("", {
                "diffuse": tuple(c.get("Kd", (0.8, 0.8, 0.8))),
                "specular": tuple(ks), "shininess": float(min(c.get("Ns", 32.0), 1e4))}))
        return table

    def meshes(self) -> None:
        from app.meshes import load_mesh, load_mesh_groups, smooth_normals

        rs = self.rs
        # [[boats]] render like [[meshes]], placed at their starting pose; a bodies stage
        # (lbm.bodies.Boats, app.boats) moves them by writing their transform rows
        for m in (*self.scene.meshes, *self.scene.boats):
            V, F = load_mesh(m.file)
            normals = smooth_normals(V, F) if m.smooth else None
            groups = None if m.material else load_mesh_groups(m.file, len(F))
            if m.material:
                mesh = rs.add_mesh(V, F, normals=normals, material=self.materials[m.material])
            elif groups is not None:
                ids, names = groups
                table = self.mtl_table(m, names)
                tri_mat = np.asarray(table, np.int64)[np.clip(ids, 0, len(table) - 1)]
                mesh = rs.add_mesh(V, F, normals=normals, tri_materials=tri_mat)
            else:
                mesh = rs.add_mesh(V, F, normals=normals,
                                   material=self.material("", TILES | {"specular": (0.2,) * 3}))
            inst = rs.add_instance(mesh, mesh_transform(V, m.position, m.rotation, m.size))
            self.instances[inst] = m.file.name
            if m in self.scene.boats:
                self.boat_instances.append(inst)

    def water(self, sim, water: WaterSpec, water_accel: str) -> WaterSurface:
        import lbm

        rs, pool = self.rs, self.scene.pool
        nx, ny = water.cells
        water_mat = self.material(pool.water_material if pool else "", WATER)
        # the solver writes the surface straight into the buffers the BVH and shader read
        # grid: traced as a height field (raytrace.heightfield), no BVH; bvh: an LBVH refitted
        mesh, vertices, normals = rs.add_dynamic_mesh(
            nx * ny, lbm.grid_triangles(nx, ny), material=water_mat,
            grid=(nx, ny) if water_accel == "grid" else None)
        sim.write_surface(vertices, normals, water.origin)
        inst = rs.add_instance(mesh)
        self.instances[inst] = "water"
        if pool is not None:
            (Vp, Fp, uvp), deck = pool_meshes(water, pool)
            tiles = self.material(pool.floor_material, TILES, pool.floor_texture)
            self.instances[rs.add_instance(rs.add_mesh(Vp, Fp, uvs=uvp, material=tiles))] = "pool"
            if deck is not None:
                Vd, Fd, uvd = deck
                deck_mat = self.material(pool.deck_material, STONE)
                deck_inst = rs.add_instance(rs.add_mesh(Vd, Fd, uvs=uvd, material=deck_mat))
                self.instances[deck_inst] = "deck"
        return WaterSurface(mesh, inst, vertices, normals, tuple(water.origin))


def water_spec(scene: Scene, cells: int | None = None) -> WaterSpec | None:
    """The scene's water, resized to ``cells`` along its longer side when given."""
    if scene.water is None or cells is None:
        return scene.water
    return resized_water(scene.water, cells)


#: How rays find the water surface: ``grid`` walks its cells as a height field (a bounds pass
#: per frame, no BVH: raytrace.heightfield), ``bvh`` refits (or rebuilds) an LBVH over it.
WATER_ACCELS = ("grid", "bvh")


def check_water_accel(water_accel: str) -> str:
    if water_accel not in WATER_ACCELS:
        raise InputError(f"water_accel {water_accel!r} is not one of {', '.join(WATER_ACCELS)}")
    return water_accel


def assemble(scene: Scene, rt, *, cells: int | None = None, water_steps: int | None = None,
             water_accel: str = "grid") -> Assembly:
    """Make the solver and the render scene of ``scene`` on runtime ``rt``.

    ``cells``: the water grid's cells along its longer side (default: the scene's);
    ``water_steps``: LBM steps taken before the first frame (default ``[pool] steps``, 30);
    ``water_accel``: one of :data:`WATER_ACCELS`.
    """
    check_water_accel(water_accel)
    check_material_names(scene)
    b = _Builder(scene, rt)
    b.materials_lights_sky()
    b.meshes()
    sim = surface = None
    water = water_spec(scene, cells)
    if water is not None:
        import lbm

        sim = lbm.from_water_spec(water, device=rt)
        steps = water_steps if water_steps is not None else (
            scene.pool.steps if scene.pool else 30)
        if steps:
            sim.step(int(steps))
        surface = b.water(sim, water, water_accel)
    boats = None
    if sim is not None and scene.boats:
        # after every instance exists: the transform buffer no longer moves
        from app.boats import boat_bodies, make_boats

        sc = b.rs.scene
        boats = make_boats(scene, sim, boat_bodies(scene), sc.transform_buffer,
                           [sc.transform_row(i) for i in b.boat_instances])
    if not b.rs.meshes:
        raise InputError(f"{scene.path}: the scene has nothing to render (no [[meshes]], no "
                         "[water])")
    return Assembly(b.rs, sim, surface, b.instances, caustic_box(scene, water, b.instances),
                    b.boat_instances, boats)


def caustic_box(scene: Scene, water: WaterSpec | None, instances: dict):
    """The pool's floor and walls as the caustics' receiver (app.assets.pool_meshes's box), the
    water's rectangle and rest level; None without [water] and [pool]."""
    from raytrace.caustics import PoolBox

    if water is None or scene.pool is None:
        return None
    pool = next(i for i, what in instances.items() if what == "pool")
    ox, oy, oz = water.origin
    sx, sz = water.size
    h = water.dx / 2
    lo = (ox + h, oy, oz + h)
    hi = (ox + sx - h, oy + scene.pool.wall_height, oz + sz - h)
    return PoolBox(lo, hi, (lo[0], lo[2], hi[0], hi[2]), oy + water.depth, pool)


def caustic_settings(scene: Scene, mode: str | None = None):
    """``[shading] caustics*`` as :class:`raytrace.caustics.CausticSettings` (``mode``
    overrides), validated; a one-line InputError naming the scene file."""
    from raytrace.caustics import CausticSettings

    sh = scene.shading
    kw = {} if sh is None else {
        "mode": sh.caustics, "photons": sh.caustic_photons,
        "resolution": sh.caustic_resolution, "filter": sh.caustic_filter,
        "blend": sh.caustic_blend}
    if mode is not None:
        kw["mode"] = mode
    try:
        return CausticSettings(**kw).resolved()
    except InputError as exc:
        raise InputError(f"{scene.path}: [shading] {exc}") from None


def render_settings(scene: Scene, *, width=None, height=None, spp=None, bounces=None,
                    aov=False, seed=None, coop_from=None, cost_bins=False, light_buffer=0,
                    shadow_list=False):
    """The renderer's settings from ``[render]`` and ``[shading]``, with overrides;
    ``coop_from``, ``cost_bins``, ``light_buffer`` and ``shadow_list``: the device's choices
    (raytrace.render.device_coop_from, device_cost_bins, device_light_buffer,
    device_shadow_list)."""
    from raytrace.render import RenderSettings

    r, sh = scene.render, scene.shading
    return RenderSettings(
        width=width or r.width, height=height or r.height, spp=spp or r.spp,
        bounces=r.bounces if bounces is None else bounces, aov=aov,
        pattern=None if sh is None or sh.pattern == "auto" else sh.pattern,
        order=sh.order if sh else "tiles",
        fresnel=sh.fresnel if sh else "exact",
        tonemap=sh.tonemap if sh else "aces",
        exposure=sh.exposure if sh else 1.0,
        min_weight=sh.min_contribution if sh else 1e-3,
        seed=(seed if seed is not None else sh.seed if sh else 0), coop_from=coop_from,
        cost_bins=cost_bins, light_buffer=light_buffer, shadow_list=shadow_list)
