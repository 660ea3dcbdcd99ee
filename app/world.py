"""The one frame loop: a :class:`World` owns the device, the water solver, the render scene and
the renderer, and every driver (``render``, the benchmarks, and later the window, capture and
sweep) advances it through :meth:`World.frame`.

One frame, all enqueued with no host sync inside::

    lbm.step x k            the water advances by the frame's simulated time
    lbm.surface             heights and normals into the water vertex buffers (device to device)
    scene update            water BLAS refit (or rebuild), TLAS rebuild
    render                  wavefront Whitted frame, tonemapped to RGBA8 on the device

then the RGBA8 image and a handful of guard scalars come back (:meth:`World.read_rgba`,
:meth:`World.water_stats`). Nothing else crosses between host and device.
"""

from __future__ import annotations

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
from app.scene import Scene


class World:
    """A scene made live on one device: water, geometry, lights, camera and renderer.

    ``width``/``height``/``spp``/``bounces`` override the scene's ``[render]`` values;
    ``water_steps`` overrides ``[pool] steps``, the LBM steps taken before the first frame.
    """

    def __init__(self, scene: Scene, device=None, *, width=None, height=None, spp=None,
                 bounces=None, aov=False, water_steps=None, rebuild_water_bvh=False):
        from app.scene import check_material_names
        from kernels import get_runtime
        from raytrace.render_scene import RenderScene

        check_material_names(scene)
        self.scene = scene
        self.rt = get_runtime(device)
        self.rebuild_water_bvh = rebuild_water_bvh
        self.render_scene = RenderScene(self.rt)
        self._textures: dict = {}
        self._materials: dict = {}
        self._add_materials_lights_sky()
        self._add_meshes()
        self.sim = None
        if scene.water is not None:
            self._add_water(water_steps)
        if not self.render_scene.meshes:
            raise InputError(f"{scene.path}: the scene has nothing to render (no [[meshes]], no "
                             "[water])")
        self.renderer = self._make_renderer(width, height, spp, bounces, aov)
        self.frames = 0
        self.last_stage_ms: dict[str, float] = {}

    # -- building ---------------------------------------------------------------------------
    def _texture(self, path: Path) -> int:
        if path not in self._textures:
            self._textures[path] = self.render_scene.add_texture(load_texture(path))
        return self._textures[path]

    def _add_materials_lights_sky(self) -> None:
        from raytrace.render_scene import Sky
        from raytrace.render_types import SkyKind

        rs, ex = self.render_scene, self.scene.extra
        for name, m in ex.get("materials", {}).items():
            self._materials[name] = rs.add_material(material_from_spec(m, rs, self._textures))
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
            rs.set_sky(Sky(kind=SkyKind.from_str(sky.kind), zenith=sky.zenith,
                           horizon=sky.horizon, ground=sky.ground,
                           sun_direction=sky.sun_direction, sun_color=sky.sun_color,
                           sun_radius=sky.sun_radius, sun_glow=sky.sun_glow, cubemap=cube))

    def _material(self, name: str, default: dict, texture: Path | None = None) -> int:
        """The scene's material ``name``, or a built-in one (``default``) when name is empty."""
        from raytrace.render_scene import Material

        if name:
            return self._materials[name]
        key = f"<builtin {sorted(default.items())} {texture}>"
        if key not in self._materials:
            tex = -1 if texture is None else self._texture(texture)
            self._materials[key] = self.render_scene.add_material(Material(**default,
                                                                           texture=tex))
        return self._materials[key]

    def _add_meshes(self) -> None:
        from app.meshes import load_mesh, load_mesh_groups, mtl_path, read_mtl, smooth_normals

        rs = self.render_scene
        for m in self.scene.extra.get("meshes", ()):
            V, F = load_mesh(m.file)
            normals = smooth_normals(V, F) if m.smooth else None
            groups = None if m.material else load_mesh_groups(m.file, len(F))
            if m.material:
                mesh = rs.add_mesh(V, F, normals=normals, material=self._materials[m.material])
            elif groups is not None:
                ids, names = groups
                mtl = read_mtl(mtl_path(m.file))
                table = []
                for name in names:
                    if name in m.materials:
                        table.append(self._materials[m.materials[name]])
                        continue
                    c = mtl.get(name, {})
                    ks = np.clip(np.asarray(c.get("Ks", (0.0, 0.0, 0.0))) * 0.25, 0, 1)
                    table.append(self._material("", {
                        "diffuse": tuple(c.get("Kd", (0.8, 0.8, 0.8))),
                        "specular": tuple(ks), "shininess": float(min(c.get("Ns", 32.0), 1e4))}))
                tri_mat = np.asarray(table, np.int64)[np.clip(ids, 0, len(table) - 1)]
                mesh = rs.add_mesh(V, F, normals=normals, tri_materials=tri_mat)
            else:
                mesh = rs.add_mesh(V, F, normals=normals,
                                   material=self._material("", TILES | {"specular": (0.2,) * 3}))
            rs.add_instance(mesh, mesh_transform(V, m.position, m.rotation, m.size))

    def _add_water(self, water_steps) -> None:
        import lbm

        rs, rt = self.render_scene, self.rt
        w = self.scene.water
        pool = self.scene.extra.get("pool")
        nx, ny = w.cells
        self.sim = lbm.from_water_spec(w, device=rt)
        steps = water_steps if water_steps is not None else (pool.steps if pool else 30)
        if steps:
            self.sim.step(int(steps))
        self.water_vertices = rt.buffer(16 * nx * ny)
        self.water_normals = rt.buffer(16 * nx * ny)
        self.sim.write_surface(self.water_vertices, self.water_normals, w.origin)
        water_mat = self._material(pool.water_material if pool else "", WATER)
        self.water_mesh = rs.add_mesh(self.water_vertices, lbm.grid_triangles(nx, ny),
                                      normals=self.water_normals, material=water_mat,
                                      dynamic=True, n_vertices=nx * ny)
        rs.add_instance(self.water_mesh)
        if pool is not None:
            (Vp, Fp, uvp), deck = pool_meshes(w, pool)
            tiles = self._material(pool.floor_material, TILES, pool.floor_texture)
            rs.add_instance(rs.add_mesh(Vp, Fp, uvs=uvp, material=tiles))
            if deck is not None:
                Vd, Fd, uvd = deck
                rs.add_instance(rs.add_mesh(Vd, Fd, uvs=uvd,
                                            material=self._material(pool.deck_material, STONE)))

    def _make_renderer(self, width, height, spp, bounces, aov):
        from raytrace.render import Renderer, RenderSettings

        r, shading = self.scene.render, self.scene.extra.get("shading")
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
        renderer = Renderer(self.rt, self.render_scene, settings)
        c = self.scene.camera
        renderer.set_camera(c.eye, c.target, c.up, c.fov)
        return renderer

    # -- the frame --------------------------------------------------------------------------
    def steps_for(self, seconds: float) -> int:
        """LBM steps that advance the water by ``seconds`` of simulated time (at least 1)."""
        if self.sim is None:
            return 0
        return max(1, round(seconds / self.sim.dt))

    def enqueue_frame(self, water_steps: int = 0) -> None:
        """Queue one frame: ``water_steps`` LBM steps, the water surface, BVH update, render.

        No host sync inside; read the image with :meth:`read_rgba`. The previous frame's stage
        times move to :attr:`last_stage_ms` first (its events are complete by then).
        """
        self.last_stage_ms = self.rt.timer.collect()
        if self.sim is not None and water_steps > 0:
            self.sim.step(int(water_steps))
            self.sim.write_surface(self.water_vertices, self.water_normals,
                                   self.scene.water.origin)
        self.render_scene.update(rebuild=self.rebuild_water_bvh)
        self.renderer.enqueue_frame(update_scene=False)
        self.frames += 1

    def frame(self, water_steps: int = 0) -> np.ndarray:
        """One whole frame; returns the RGBA8 image (height, width, 4), top row first."""
        self.enqueue_frame(water_steps)
        return self.read_rgba()

    def read_rgba(self) -> np.ndarray:
        return self.renderer.read_rgba()

    def water_stats(self) -> dict | None:
        """The solver's guard record (mass, max speed, min depth, NaN flag, actions taken)."""
        return None if self.sim is None else self.sim.stats()

    def stage_times(self) -> dict[str, float]:
        """Milliseconds per stage of the frames since the last call (waits on their events)."""
        self.last_stage_ms = self.rt.timer.collect()
        return self.last_stage_ms
