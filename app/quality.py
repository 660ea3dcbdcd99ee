"""Quality for the window: the water grid, render scale, bounce depth and caustic photons that
hold a target frame rate on this device, chosen from one short measurement.

:func:`measure` times a few frames of a probe World (shown in the window where there is one, so
the display's own cost is in the wall time) and :func:`costs_from_stats` reduces them to
:class:`Costs` (ms per cell-step of the water, per cell of the surface and BVH, per ray, per
caustic photon, and a fixed part); :func:`choose` is a pure function of those costs: it walks a
ladder of settings from the best down, each rung cheaper than the one before, and takes the first
whose predicted frame time fits ``1000 / target_fps`` ms, else the last. A step down is a rung
only where it saves :data:`MIN_SAVING` of the frame time (else it waits until it does), a ratio
that a uniformly slower device shares: such a device (larger costs) lands on the same or a lower
rung, never a higher one. Fixed presets (``low``, ``medium``, ``high``) skip the
measurement, and explicit ``--cells``/``--scale``/``--bounces``/``--caustics`` pin their own part
of any choice.

Traced caustics come in levels: the scene's ``caustic_photons`` and a quarter and a sixteenth of
them, the caustic map's texels along its side falling with the square root (the photons per
texel, hence the noise, stay), then off. Their cost is linear in the photons.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import NamedTuple

#: Fixed presets: cells along the pool's longer side (None: the scene's), render scale, bounces
#: (None: the scene's), where the scene traces caustics the divisor of its photons (0: off).
PRESETS = {
    "low": (64, 0.5, 1, 0),
    "medium": (128, 0.75, 2, 4),
    "high": (None, 1.0, None, 1),
}
QUALITIES = ("auto", *PRESETS)

CELL_LADDER = (1024, 768, 512, 384, 256, 192, 128, 96, 64, 48, 32)
SCALE_LADDER = (1.0, 0.75, 0.5, 0.375, 0.25)


#: Photon divisors of the caustic levels (the scene's count, a quarter, a sixteenth).
CAUSTIC_DIVISORS = (1, 4, 16)
MIN_CAUSTIC_PHOTONS = 1024
#: Photons a probe traces at most (its time is scaled to the other counts).
PROBE_PHOTONS = 65536
#: A step down the ladder is taken only where it saves this share of the frame time at least:
#: one that saves less would coarsen the picture for nothing (on a CPU the water grid costs
#: little beside the rays, say).
MIN_SAVING = 0.05


@dataclasses.dataclass(frozen=True)
class Quality:
    cells: int        #: water cells along the pool's longer side
    scale: float      #: image pixels per window pixel (per axis)
    bounces: int
    source: str       #: "auto", a preset name, or "auto (fixed: ...)"
    predicted_ms: float | None = None
    caustics: str | None = None    #: caustics mode over the scene's ("off"); None: the scene's
    photons: int | None = None     #: caustic photons per frame (when traced); None: the scene's

    def describe(self) -> str:
        ms = "" if self.predicted_ms is None else f", predicted {self.predicted_ms:.1f} ms"
        if self.caustics == "off" or (self.caustics and not self.photons):
            ca = f", caustics {self.caustics}"
        elif self.photons:
            ca = f", caustics {self.caustics or 'traced'} ({self.photons} photons)"
        else:
            ca = ""
        return (f"quality {self.source}: {self.cells} cells, scale {self.scale:g}, "
                f"{self.bounces} bounces{ca}{ms}")


@dataclasses.dataclass(frozen=True)
class Costs:
    """Per-unit frame costs measured on this device (ms)."""

    per_cell_step: float     #: LBM step + guard, per cell and step
    per_cell: float          #: surface + BVH refit/TLAS, per cell and frame
    per_ray: float           #: ray generation, tracing, shading, per ray
    fixed: float             #: the rest: launches, read-back, display, host work, per frame
    ray_ratio: tuple = (1.0, 0.7, 0.5, 0.35)  #: rays at depth d per primary ray (d = 0, 1, ..)
    steps_per_frame: float = 1.0   #: LBM steps per frame at the scene's cell size
    per_pixel: float = 0.0   #: read-back + upload, per pixel
    caustics: float = 0.0    #: traced caustics (photons, map), per frame at ``caustic_photons``
    caustic_photons: int = 0  #: the photons ``caustics`` was measured with

    def scaled(self, factor: float) -> Costs:
        """The same device `factor` times slower (tests, and what-ifs)."""
        return dataclasses.replace(self, per_cell_step=self.per_cell_step * factor,
                                   per_cell=self.per_cell * factor,
                                   per_ray=self.per_ray * factor, fixed=self.fixed * factor,
                                   per_pixel=self.per_pixel * factor,
                                   caustics=self.caustics * factor)

    def caustic_ms(self, photons: int) -> float:
        """Traced caustics at ``photons`` per frame (0: off), the map's side scaled as
        :func:`caustic_map_resolution` scales it (photons and texels: both linear)."""
        if not photons:
            return 0.0
        return self.caustics * photons / max(1, self.caustic_photons or photons)


def rays_per_pixel(costs: Costs, bounces: int, spp: int) -> float:
    r = list(costs.ray_ratio)
    while len(r) <= bounces:   # beyond what was measured: the last ratio decays geometrically
        r.append(r[-1] * (r[-1] / r[-2] if len(r) > 1 and r[-2] > 0 else 0.5))
    return spp * sum(r[: bounces + 1])


def predict_ms(costs: Costs, *, cells: int, aspect: float, scale: float, bounces: int,
               window: tuple[int, int], spp: int = 1, base_cells: int | None = None,
               photons: int = 0) -> float:
    """Predicted frame time (ms) at these settings. ``aspect`` = shorter/longer pool side;
    finer grids take proportionally more LBM steps per frame (dt ~ dx); ``photons``: traced
    caustics per frame (0: off)."""
    n_cells = cells * max(2, round(cells * aspect))
    steps = costs.steps_per_frame * (cells / base_cells if base_cells else 1.0)
    pixels = max(1, round(window[0] * scale)) * max(1, round(window[1] * scale))
    return (costs.fixed + n_cells * (costs.per_cell_step * max(1.0, steps) + costs.per_cell)
            + pixels * (rays_per_pixel(costs, bounces, spp) * costs.per_ray + costs.per_pixel)
            + costs.caustic_ms(photons))


def caustic_levels(photons: int) -> list[int]:
    """Photon counts of the caustic rungs below a scene's ``photons`` (best first)."""
    out = []
    for d in CAUSTIC_DIVISORS:
        p = max(MIN_CAUSTIC_PHOTONS, photons // d) if photons else 0
        if p and p not in out and p <= photons:
            out.append(p)
    return out or ([photons] if photons else [])


def caustic_map_resolution(photons: int, scene_photons: int, scene_resolution: int) -> int:
    """The caustic map's texels along the floor's longer side at ``photons``: the scene's,
    scaled by the square root of the photon ratio (photons per texel kept), at least 8."""
    return max(8, round(scene_resolution * math.sqrt(photons / max(1, scene_photons))))


class Rung(NamedTuple):
    cells: int
    scale: float
    bounces: int
    photons: int      #: traced caustic photons per frame; 0: caustics off


def ladder(max_cells: int, max_bounces: int, photons: int = 0, worth=None) -> list[Rung]:
    """Settings from the best down; each rung lowers one of them, so costs never rise.
    ``photons``: the scene's traced caustic photons (0: it has none). Order of sacrifice:
    bounces to 2, scale to 0.75, caustic photons to a quarter and a sixteenth, caustics off,
    scale to 0.5, cells to 96, bounces to 1, scale to 0.25, cells to the smallest.
    ``worth(rung, lower)``, where given, says whether a step is taken now; one that is not
    waits, and is tried again (first) after each step taken later, while it still lowers."""
    cells = [c for c in CELL_LADDER if c < max_cells]
    cur = Rung(max_cells, 1.0, max_bounces, photons)
    out, waiting = [cur], []

    def step(**kw):
        nonlocal cur
        waiting.append(kw)
        taken = True
        while taken:
            taken = False
            for kw in list(waiting):
                new = cur._replace(**kw)
                if new == cur or any(getattr(new, f) > getattr(cur, f) for f in kw):
                    waiting.remove(kw)        # no longer a step down
                elif worth is None or worth(cur, new):
                    waiting.remove(kw)
                    cur = new
                    out.append(cur)
                    taken = True
                    break

    for bb in range(max_bounces - 1, 1, -1):
        step(bounces=bb)
    for ss in SCALE_LADDER:
        if 0.75 <= ss < cur.scale:
            step(scale=ss)
    for p in caustic_levels(photons)[1:]:
        step(photons=p)
    step(photons=0)
    for ss in SCALE_LADDER:
        if 0.5 <= ss < cur.scale:
            step(scale=ss)
    for cc in cells:
        if 96 <= cc < cur.cells:
            step(cells=cc)
    if cur.bounces > 1:
        step(bounces=1)
    for ss in SCALE_LADDER:
        if ss < cur.scale:
            step(scale=ss)
    for cc in cells:
        if cc < cur.cells:
            step(cells=cc)
    return out


def choose(costs: Costs, *, target_fps: float, window: tuple[int, int], max_cells: int,
           max_bounces: int, aspect: float, spp: int = 1, base_cells: int | None = None,
           photons: int = 0, keep_caustics: bool = False, fixed_cells: int | None = None,
           fixed_scale: float | None = None, fixed_bounces: int | None = None) -> Quality:
    """The first rung of :func:`ladder` whose predicted time fits ``1000/target_fps`` ms (else
    the last), on a ladder of steps that each save :data:`MIN_SAVING` of the time at least.
    The saving is a ratio of predicted times, the same on a device uniformly slower, so the
    ladder is too and a slower device never gets a higher rung (a step that waits for its
    saving to matter is taken later, as :func:`ladder` says). ``photons``: the scene's
    traced caustic photons (0: none; turning them down or off are rungs); ``keep_caustics``
    (the user asked for them): never off, the fewest photons instead; ``fixed_*`` pin a
    setting (user overrides); the rest is still chosen."""
    budget = 1000.0 / target_fps
    pinned = [n for n, v in (("cells", fixed_cells), ("scale", fixed_scale),
                             ("bounces", fixed_bounces)) if v is not None]
    if keep_caustics and photons:
        pinned.append("caustics")
    least = caustic_levels(photons)[-1] if photons else 0

    def pin(r: Rung) -> Rung:
        return Rung(fixed_cells or r.cells, fixed_scale or r.scale,
                    r.bounces if fixed_bounces is None else fixed_bounces,
                    r.photons or (least if keep_caustics else 0))

    def ms(r: Rung) -> float:
        r = pin(r)
        return predict_ms(costs, cells=r.cells, aspect=aspect, scale=r.scale,
                          bounces=r.bounces, window=window, spp=spp, base_cells=base_cells,
                          photons=r.photons)

    rungs = ladder(max_cells, max(max_bounces, 1), photons,
                   worth=lambda a, b: ms(b) <= (1.0 - MIN_SAVING) * ms(a))
    times = [ms(r) for r in rungs]
    k = next((i for i, m in enumerate(times) if m <= budget), len(rungs) - 1)
    r, t = pin(rungs[k]), times[k]
    source = "auto" + (f" (fixed: {', '.join(pinned)})" if pinned else "")
    if not photons:
        return Quality(r.cells, r.scale, r.bounces, source, t)
    # caustics off: C turns on the fewest photons (what this device can best afford)
    return Quality(r.cells, r.scale, r.bounces, source, t,
                   caustics="off" if not r.photons else None, photons=r.photons or least)


def preset(name: str, *, max_cells: int, max_bounces: int, photons: int = 0) -> Quality:
    """A fixed preset; ``photons``: the scene's traced caustic photons (0: none)."""
    if name not in PRESETS:
        raise ValueError(f"unknown quality {name!r}; valid: {', '.join(QUALITIES)}")
    c, s, b, d = PRESETS[name]
    q = Quality(min(c or max_cells, max_cells), s,
                max_bounces if b is None else min(b, max_bounces), name)
    if not photons:
        return q
    levels = caustic_levels(photons)
    if not d:   # off; C turns on the fewest photons
        return dataclasses.replace(q, caustics="off", photons=levels[-1])
    return dataclasses.replace(q, photons=max(levels[-1], photons // d))


def costs_from_stats(stats_list, wall_ms: float, *, n_cells: int, steps: float,
                     photons: int = 0) -> Costs:
    """Reduce the stats of a few probe frames (median-like: the mean of all but the slowest)
    to per-unit costs. ``wall_ms``: host time per frame, of which the rest is ``fixed``;
    ``photons``: the probe's traced caustic photons per frame (0: off)."""
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
    # everything else (other stages, launches, read-back, display, host work) counts as fixed
    rays = max(1, stats_list[-1].n_rays)
    depth = stats_list[-1].rays_per_depth or (rays,)
    ratio = tuple(d / max(1, depth[0]) for d in depth) if depth[0] else (1.0,)
    return Costs(per_cell_step=lbm / max(1, n_cells * steps), per_cell=cell / max(1, n_cells),
                 per_ray=ray / rays, fixed=max(0.0, wall_ms - lbm - cell - ray - caustics),
                 ray_ratio=ratio, steps_per_frame=steps, caustics=caustics,
                 caustic_photons=photons)


def measure(world, frame_seconds: float, frames: int = 4, warmup: int = 2, present=None):
    """Time ``frames`` frames of ``world`` after ``warmup``; (stats list, wall ms per frame).
    ``present(world, image)``, where given, shows each frame (the window's display cost is
    then part of the wall time, hence of the fixed cost)."""
    def one():
        img = world.frame(frame_seconds)
        if present is not None:
            present(world, img)

    for _ in range(warmup):
        one()
    stats, t0 = [], time.perf_counter()
    for _ in range(frames):
        one()
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
