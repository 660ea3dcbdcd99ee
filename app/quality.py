"""Quality for the window: the water grid, render scale and bounce depth that hold a target frame
rate on this device, chosen from one short measurement.

:func:`measure` times a few frames of a probe World and reduces them to :class:`Costs` (ms per
cell-step of the water, per cell of the surface and BVH, per ray, and a fixed part);
:func:`choose` is a pure function of those costs: it walks a ladder of settings from the best
down, each rung cheaper than the one before, and takes the first whose predicted frame time fits
``1000 / target_fps`` ms. A slower device (larger costs) therefore lands on the same or a lower
rung, never a higher one. Fixed presets (``low``, ``medium``, ``high``) skip the measurement, and
explicit ``--cells``/``--scale``/``--bounces`` pin their own part of any choice.
"""

from __future__ import annotations

import dataclasses
import math
import time

#: Fixed presets: cells along the pool's longer side (None: the scene's), render scale, bounces
#: (None: the scene's), caustics mode (None: the scene's setting, "off": off).
PRESETS = {
    "low": (64, 0.5, 1, "off"),
    "medium": (128, 0.75, 2, None),
    "high": (None, 1.0, None, None),
}
QUALITIES = ("auto", *PRESETS)

CELL_LADDER = (1024, 768, 512, 384, 256, 192, 128, 96, 64, 48, 32)
SCALE_LADDER = (1.0, 0.75, 0.5, 0.375, 0.25)


@dataclasses.dataclass(frozen=True)
class Quality:
    cells: int        #: water cells along the pool's longer side
    scale: float      #: image pixels per window pixel (per axis)
    bounces: int
    source: str       #: "auto", a preset name, or "auto (fixed: ...)"
    predicted_ms: float | None = None
    caustics: str | None = None    #: caustics mode over the scene's ("off"); None: the scene's

    def describe(self) -> str:
        ms = "" if self.predicted_ms is None else f", predicted {self.predicted_ms:.1f} ms"
        ca = f", caustics {self.caustics}" if self.caustics else ""
        return (f"quality {self.source}: {self.cells} cells, scale {self.scale:g}, "
                f"{self.bounces} bounces{ca}{ms}")


@dataclasses.dataclass(frozen=True)
class Costs:
    """Per-unit frame costs measured on this device (ms)."""

    per_cell_step: float     #: LBM step + guard, per cell and step
    per_cell: float          #: surface + BVH refit/TLAS, per cell and frame
    per_ray: float           #: ray generation, tracing, shading, per ray
    fixed: float             #: the rest: launches, read-back, host work, per frame
    ray_ratio: tuple = (1.0, 0.7, 0.5, 0.35)  #: rays at depth d per primary ray (d = 0, 1, ..)
    steps_per_frame: float = 1.0   #: LBM steps per frame at the scene's cell size
    per_pixel: float = 0.0   #: read-back + upload, per pixel
    caustics: float = 0.0    #: traced caustics (photons, filter), per frame

    def scaled(self, factor: float) -> Costs:
        """The same device `factor` times slower (tests, and what-ifs)."""
        return dataclasses.replace(self, per_cell_step=self.per_cell_step * factor,
                                   per_cell=self.per_cell * factor,
                                   per_ray=self.per_ray * factor, fixed=self.fixed * factor,
                                   per_pixel=self.per_pixel * factor,
                                   caustics=self.caustics * factor)


def rays_per_pixel(costs: Costs, bounces: int, spp: int) -> float:
    r = list(costs.ray_ratio)
    while len(r) <= bounces:   # beyond what was measured: the last ratio decays geometrically
        r.append(r[-1] * (r[-1] / r[-2] if len(r) > 1 and r[-2] > 0 else 0.5))
    return spp * sum(r[: bounces + 1])


def predict_ms(costs: Costs, *, cells: int, aspect: float, scale: float, bounces: int,
               window: tuple[int, int], spp: int = 1, base_cells: int | None = None,
               caustics: bool = False) -> float:
    """Predicted frame time (ms) at these settings. ``aspect`` = shorter/longer pool side;
    finer grids take proportionally more LBM steps per frame (dt ~ dx)."""
    n_cells = cells * max(2, round(cells * aspect))
    steps = costs.steps_per_frame * (cells / base_cells if base_cells else 1.0)
    pixels = max(1, round(window[0] * scale)) * max(1, round(window[1] * scale))
    return (costs.fixed + n_cells * (costs.per_cell_step * max(1.0, steps) + costs.per_cell)
            + pixels * (rays_per_pixel(costs, bounces, spp) * costs.per_ray + costs.per_pixel)
            + (costs.caustics if caustics else 0.0))


def ladder(max_cells: int, max_bounces: int,
           caustics: bool = False) -> list[tuple[int, float, int, bool]]:
    """Settings (cells, scale, bounces, caustics) from the best down; each rung lowers one of
    them, so costs never rise. Order of sacrifice: bounces to 2, scale to 0.75, caustics off
    (where the scene traces them), scale to 0.5, cells to 96, bounces to 1, scale to 0.25,
    cells to the smallest."""
    cells = [c for c in CELL_LADDER if c < max_cells]
    c, s, b, k = max_cells, 1.0, max_bounces, bool(caustics)
    out = [(c, s, b, k)]

    def step(**kw):
        nonlocal c, s, b, k
        c, s, b, k = kw.get("c", c), kw.get("s", s), kw.get("b", b), kw.get("k", k)
        if (c, s, b, k) != out[-1]:
            out.append((c, s, b, k))

    for bb in range(max_bounces - 1, 1, -1):
        step(b=bb)
    for lo in (0.75, 0.5):
        if lo == 0.5:
            step(k=False)
        for ss in SCALE_LADDER:
            if lo <= ss < s:
                step(s=ss)
    for cc in cells:
        if 96 <= cc < c:
            step(c=cc)
    if b > 1:
        step(b=1)
    for ss in SCALE_LADDER:
        if ss < s:
            step(s=ss)
    for cc in cells:
        if cc < c:
            step(c=cc)
    return out


def choose(costs: Costs, *, target_fps: float, window: tuple[int, int], max_cells: int,
           max_bounces: int, aspect: float, spp: int = 1, base_cells: int | None = None,
           caustics: bool = False, fixed_cells: int | None = None,
           fixed_scale: float | None = None, fixed_bounces: int | None = None) -> Quality:
    """The first rung of :func:`ladder` whose predicted time fits ``1000/target_fps`` ms (else
    the last rung). ``caustics``: the scene traces them (turning them off is a rung);
    ``fixed_*`` pin a setting (user overrides); the rest is still chosen."""
    budget = 1000.0 / target_fps
    pinned = [n for n, v in (("cells", fixed_cells), ("scale", fixed_scale),
                             ("bounces", fixed_bounces)) if v is not None]
    rungs, seen = [], set()
    for c, s, b, k in ladder(max_cells, max(max_bounces, 1), caustics):
        rung = (fixed_cells or c, fixed_scale or s,
                b if fixed_bounces is None else fixed_bounces, k)
        if rung not in seen:
            seen.add(rung)
            rungs.append(rung)
    best = None
    for c, s, b, k in rungs:
        ms = predict_ms(costs, cells=c, aspect=aspect, scale=s, bounces=b, window=window,
                        spp=spp, base_cells=base_cells, caustics=k)
        best = (c, s, b, k, ms)
        if ms <= budget:
            break
    c, s, b, k, ms = best
    source = "auto" + (f" (fixed: {', '.join(pinned)})" if pinned else "")
    return Quality(c, s, b, source, ms, caustics="off" if caustics and not k else None)


def preset(name: str, *, max_cells: int, max_bounces: int) -> Quality:
    if name not in PRESETS:
        raise ValueError(f"unknown quality {name!r}; valid: {', '.join(QUALITIES)}")
    c, s, b, k = PRESETS[name]
    return Quality(min(c or max_cells, max_cells), s,
                   max_bounces if b is None else min(b, max_bounces), name, caustics=k)


def costs_from_stats(stats_list, wall_ms: float, *, n_cells: int, steps: float) -> Costs:
    """Reduce the stats of a few probe frames (median-like: the mean of all but the slowest)
    to per-unit costs. ``wall_ms``: host time per frame, of which the rest is ``fixed``."""
    def stage_sum(prefixes, s):
        return sum(v for k, v in s.stage_ms.items() if k.startswith(prefixes))

    def typical(xs):
        xs = sorted(xs)
        return sum(xs[:-1]) / (len(xs) - 1) if len(xs) > 1 else xs[0]

    lbm = typical([stage_sum(("lbm.step", "lbm.guard", "lbm.sources"), s) for s in stats_list])
    cell = typical([stage_sum(("lbm.surface", "bvh.", "render.geometry"), s) for s in stats_list])
    ray = typical([stage_sum(("render.",), s) - stage_sum(("render.geometry",), s)
                   for s in stats_list])
    caustics = typical([stage_sum(("caustics.",), s) for s in stats_list])
    # everything else (other stages, launches, read-back, host work) counts as fixed
    rays = max(1, stats_list[-1].n_rays)
    depth = stats_list[-1].rays_per_depth or (rays,)
    ratio = tuple(d / max(1, depth[0]) for d in depth) if depth[0] else (1.0,)
    return Costs(per_cell_step=lbm / max(1, n_cells * steps), per_cell=cell / max(1, n_cells),
                 per_ray=ray / rays, fixed=max(0.0, wall_ms - lbm - cell - ray - caustics),
                 ray_ratio=ratio, steps_per_frame=steps, caustics=caustics)


def measure(world, frame_seconds: float, frames: int = 4, warmup: int = 2):
    """Time ``frames`` frames of ``world`` after ``warmup``; (stats list, wall ms per frame)."""
    for _ in range(warmup):
        world.frame(frame_seconds)
    stats, t0 = [], time.perf_counter()
    for _ in range(frames):
        world.frame(frame_seconds)
        stats.append(world.stats)
    return stats, (time.perf_counter() - t0) * 1e3 / frames


def grid_for(size: tuple[float, float], cells: int) -> tuple[int, int]:
    """(nx, ny) with ``cells`` along the longer side and square cells."""
    sx, sy = size
    if sx >= sy:
        return cells, max(2, round(cells * sy / sx))
    return max(2, round(cells * sx / sy)), cells


def aspect_of(size) -> float:
    return min(size) / max(size)


def scaled_size(window: tuple[int, int], scale: float) -> tuple[int, int]:
    return max(1, math.floor(window[0] * scale + 0.5)), max(1, math.floor(window[1] * scale + 0.5))
