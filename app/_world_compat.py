"""TEMPORARY: the frame API of docs/frame_api.md over the pre-rewrite ``app.world.World``, so the
window can be built and tested before the lead's "World: the frame API" lands. Delete this file
when it does (``app.window.make_world`` then uses ``app.world.World`` directly).

Frames here are not truly in flight (``enqueue_frame`` reads its image at once), ``pick`` reads
the water vertices back and traces them with ``raytrace.query.intersect`` (water only), and rain
drops have a fixed size.
"""

from __future__ import annotations

import collections
import dataclasses
import time

import numpy as np


@dataclasses.dataclass(frozen=True)
class FrameStats:
    frame: int
    sim_time: float
    lbm_steps: int
    stage_ms: dict
    kernel_ms: float
    wall_ms: float
    rays_per_depth: tuple
    n_rays: int
    n_triangles: int
    device_bytes: int
    guard: dict
    water_cells: tuple | None


def _resized(scene, cells):
    from app.quality import grid_for

    w = scene.water
    nx, ny = (cells if isinstance(cells, tuple) else grid_for(w.size, int(cells)))
    if (nx, ny) == tuple(w.cells):
        return scene
    return dataclasses.replace(scene, water=dataclasses.replace(w, cells=(nx, ny)))


class CompatWorld:
    def __init__(self, scene, device=None, *, width=None, height=None, spp=None, bounces=None,
                 cells=None, seed=None, **_ignored):
        from app.scene import Scene, load_scene
        from app.world import World

        if not isinstance(scene, Scene):
            scene = load_scene(scene)
        if cells is not None and scene.water is not None:
            scene = _resized(scene, cells)
        self._w = World(scene, device, width=width, height=height, spp=spp, bounces=bounces)
        self.scene = scene
        c = scene.camera
        self._camera = (tuple(c.eye), tuple(c.target), tuple(c.up), float(c.fov))
        self._done: collections.deque = collections.deque()
        self._carry = 0.0
        self._index = 0
        self._steps = 0
        self._rain_seed = 0 if seed is None else int(seed)
        self.stats = None
        self.sim_time = 0.0

    # -- the frame API ----------------------------------------------------------------------
    @property
    def size(self):
        s = self._w.renderer.settings
        return s.width, s.height

    @property
    def device_name(self):
        return self._w.rt.name

    @property
    def camera(self):
        return self._camera

    def set_camera(self, eye, target, up=(0, 1, 0), fov=None):
        fov = self._camera[3] if fov is None else float(fov)
        self._camera = (tuple(map(float, eye)), tuple(map(float, target)),
                        tuple(map(float, up)), fov)
        self._w.renderer.set_camera(*self._camera)

    def add_drop(self, x, y, radius, height):
        self._w.sim.add_drop(x, y, radius, height)

    def push(self, x, y, dx, dy, strength):
        self._w.sim.push(x, y, dx, dy, strength)

    def set_rain(self, rate):
        sim = self._w.sim
        if sim is None:
            return
        sim.set_rain(rate, max(2.0 * sim.dx, 0.02), 0.01, seed=self._rain_seed)
        self._rain_seed += 1

    def enqueue_frame(self, seconds=0.0):
        t0 = time.perf_counter()
        steps = 0
        sim = self._w.sim
        if sim is not None and seconds > 0:
            total = seconds + self._carry
            steps = int(total // sim.dt)
            self._carry = total - steps * sim.dt
        self._w.enqueue_frame(steps)
        img = self._w.read_rgba().copy()
        stage = self._w.stage_times()
        st = self._w.renderer.read_stats()
        g = self._w.water_stats() or {}
        self._steps += steps
        self.sim_time = 0.0 if sim is None else float(sim.time)
        depth = tuple(st["rays_per_depth"])
        self.stats = FrameStats(
            frame=self._index, sim_time=self.sim_time, lbm_steps=steps, stage_ms=stage,
            kernel_ms=sum(stage.values()), wall_ms=(time.perf_counter() - t0) * 1e3,
            rays_per_depth=depth, n_rays=int(sum(depth)),
            n_triangles=int(self._w.render_scene.n_triangles), device_bytes=0,
            guard={"nan": bool(g.get("nan", False)), "cells_limited": int(g.get("clamped", 0)),
                   "acted": bool(g.get("clamped", 0) or g.get("restored", 0)),
                   "report": g.get("report", "")},
            water_cells=None if sim is None else (sim.nx, sim.ny))
        self._done.append((self._index, img))
        self._index += 1
        return self._index - 1

    def read_frame(self):
        return self._done.popleft()

    def frame(self, seconds=0.0):
        self.enqueue_frame(seconds)
        return self.read_frame()[1]

    def pick(self, px, py):
        import lbm
        from app.controls import pixel_ray
        from raytrace.query import intersect

        sim = self._w.sim
        if sim is None:
            return None
        eye, target, up, fov = self._camera
        w, h = self.size
        o, d = pixel_ray(eye, target, up, fov, w, h, px, py)
        v = self._w.rt.to_host(self._w.water_vertices, np.float32, 4 * sim.nx * sim.ny)
        v = v.reshape(-1, 4)[:, :3]
        hit = intersect(v, lbm.grid_triangles(sim.nx, sim.ny), o[None], d[None],
                        device=self._w.rt)
        if not hit["hit"][0]:
            return None
        return tuple(float(c) for c in o + float(hit["t"][0]) * d)

    def water_fields(self):
        return self._w.sim.fields()

    def close(self):
        pass
