"""The one place where capture, sweep and studies make a World (docs/frame_api.md).

:func:`open_world` returns an object with the frame API: ``frame(seconds)``,
``enqueue_frame(seconds)``, ``read_frame()``, ``set_camera``, ``add_drop``, ``push``,
``set_rain``, ``stats``, ``sim_time``, ``size``, ``device_name``, ``close()``. When
``app.world.World`` has that API it is returned as it is; until then a thin adapter over the
older World (``frame(water_steps)``) stands in. Deleting :class:`_Adapter` is the one edit that
retires it.

:func:`with_cells` resizes a scene's water grid (square cells kept, the pool's size kept up to
a cell), so every driver resizes grids the same way.
"""

from __future__ import annotations

import dataclasses
import time
from collections import deque


def with_cells(scene, cells: int | None):
    """``scene`` with ``cells`` water cells along the pool's longer side (None: unchanged)."""
    if cells is None or scene.water is None:
        return scene
    w = scene.water
    sx, sy = w.size
    if sx >= sy:
        nx, ny = int(cells), max(2, round(cells * sy / sx))
    else:
        nx, ny = max(2, round(cells * sx / sy)), int(cells)
    dx = sx / nx if sx >= sy else sy / ny
    size = (nx * dx, ny * dx)
    drops = tuple(d for d in w.drops if d.x <= size[0] and d.y <= size[1])
    water = dataclasses.replace(w, cells=(nx, ny), size=size, drops=drops)
    return dataclasses.replace(scene, water=water)


def open_world(scene, device=None, *, width=None, height=None, spp=None, bounces=None,
               cells=None, seed=None, water_steps=None, rebuild_water_bvh=False,
               shading: dict | None = None):
    """A World with the frame API for ``scene`` (an ``app.scene.Scene``).

    ``cells`` resizes the water grid (:func:`with_cells`); ``shading`` replaces keys of the
    scene's ``[shading]`` (fresnel, min_contribution, ...), for the studies.
    """
    from app import world as world_mod

    scene = with_cells(scene, cells)
    if shading:
        scene = _with_shading(scene, shading)
    kw = dict(width=width, height=height, spp=spp, bounces=bounces, water_steps=water_steps,
              rebuild_water_bvh=rebuild_water_bvh)
    if hasattr(world_mod.World, "read_frame"):
        return world_mod.World(scene, device, seed=seed, **kw)
    return _Adapter(world_mod.World(scene, device, **kw), seed)


def _with_shading(scene, changes: dict):
    from app.scene import SHADING_SCHEMA, ShadingSpec

    cur = scene.extra.get("shading")
    base = dataclasses.asdict(cur) if cur is not None else {
        k: f.default for k, f in SHADING_SCHEMA.items()}
    base.update(changes)
    return dataclasses.replace(scene, extra={**scene.extra, "shading": ShadingSpec(**base)})


@dataclasses.dataclass(frozen=True)
class FrameStats:
    """docs/frame_api.md's record (the adapter fills what the older World can tell)."""

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


class _Adapter:
    """The frame API over the older ``World`` (frame(water_steps), one frame in flight)."""

    def __init__(self, world, seed):
        self._w = world
        self._carry = 0.0
        self._queue: deque = deque()   # (index, image or None, t_enqueue, steps)
        self._next = 0
        self.stats: FrameStats | None = None
        sim = world.sim
        rain = world.scene.water.rain if world.scene.water is not None else None
        self._rain = (rain.radius, rain.height, rain.seed if seed is None else seed) if rain \
            else (0.03, 0.005, 0 if seed is None else seed)
        if sim is not None and rain is not None and rain.rate > 0 and seed is not None:
            sim.set_rain(rain.rate, *self._rain)

    # -- inputs ------------------------------------------------------------------------------
    def set_camera(self, eye, target, up=(0.0, 1.0, 0.0), fov=None):
        c = self._w.scene.camera
        self._camera = (tuple(eye), tuple(target), tuple(up), float(fov or c.fov))
        self._w.renderer.set_camera(*self._camera)

    @property
    def camera(self):
        c = self._w.scene.camera
        return getattr(self, "_camera", (c.eye, c.target, c.up, c.fov))

    def add_drop(self, x, y, radius, height):
        if self._w.sim is not None:
            self._w.sim.add_drop(x, y, radius, height)

    def push(self, x, y, dx, dy, strength):
        if self._w.sim is not None:
            self._w.sim.push(x, y, dx, dy, strength)

    def set_rain(self, rate):
        if self._w.sim is not None:
            self._w.sim.set_rain(rate, *self._rain)

    # -- frames ------------------------------------------------------------------------------
    def _steps(self, seconds: float) -> int:
        sim = self._w.sim
        if sim is None or seconds <= 0:
            return 0
        total = seconds + self._carry
        n = int(total / sim.dt + 1e-9)
        self._carry = total - n * sim.dt
        return n

    def enqueue_frame(self, seconds: float = 0.0) -> int:
        if self._queue and self._queue[-1][1] is None:   # one frame in flight: read it first
            i, _, t0, steps = self._queue.pop()
            self._queue.append((i, self._finish(i, t0, steps), t0, steps))
        steps = self._steps(seconds)
        t0 = time.perf_counter()
        self._w.enqueue_frame(steps)
        i = self._next
        self._next += 1
        self._queue.append((i, None, t0, steps))
        return i

    def read_frame(self):
        i, img, t0, steps = self._queue.popleft()
        if img is None:
            img = self._finish(i, t0, steps)
        return i, img

    def frame(self, seconds: float = 0.0):
        self.enqueue_frame(seconds)
        while len(self._queue) > 1:
            self.read_frame()
        return self.read_frame()[1]

    def _finish(self, i: int, t0: float, steps: int):
        w = self._w
        img = w.read_rgba()
        wall = (time.perf_counter() - t0) * 1e3
        stages = w.stage_times()
        r = w.renderer.read_stats()
        g = w.water_stats() or {}
        guard = {"nan": bool(g.get("nan", False)), "cells_limited": int(g.get("clamped", 0)),
                 "volume_clipped": 0.0, "volume_created": 0.0,
                 "max_froude": float(g.get("max_froude", 0.0)),
                 "acted": bool(g.get("report", "ok") != "ok")}
        wc = tuple(w.scene.water.cells) if w.scene.water is not None else None
        mem = w.renderer.memory_report()
        n_bytes = mem["ray_slots"] * mem["bytes_per_ray_slot"] + int(
            w.render_scene.n_triangles * mem["bytes_per_triangle"]["total"])
        if w.sim is not None:   # 3 population buffers (ping-pong, checkpoint), 5 scalar fields
            n_bytes += w.sim.n_cells * (3 * 36 + 5 * 4 + 2 * 16)
        self.stats = FrameStats(
            frame=i, sim_time=self.sim_time, lbm_steps=steps, stage_ms=dict(stages),
            kernel_ms=float(sum(stages.values())), wall_ms=wall,
            rays_per_depth=tuple(int(x) for x in r["rays_per_depth"]),
            n_rays=int(sum(r["rays_per_depth"])), n_triangles=int(w.render_scene.n_triangles),
            device_bytes=int(n_bytes), guard=guard,
            water_cells=wc)
        return img

    @property
    def sim_time(self) -> float:
        return 0.0 if self._w.sim is None else float(self._w.sim.time)

    @property
    def size(self):
        s = self._w.renderer.settings
        return s.width, s.height

    @property
    def device_name(self) -> str:
        return self._w.rt.name

    def water_fields(self):
        """(For tests) the solver's fields, host copies."""
        return None if self._w.sim is None else self._w.sim.fields()

    def close(self) -> None:
        self._queue.clear()
