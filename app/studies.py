"""Speed against accuracy: each study writes ``DIR/<name>.csv`` and ``DIR/<name>.png`` (a chart
of error against time) and prints one line per point.

    lbwater study lbm-resolution -o out/studies            # full size (GPU minutes)
    lbwater study all -o out/studies --quick               # every study, tiny (PoCL seconds)

Studies (each speed-accuracy trade-off gets a chart of error against time; README "Charts:
speed against accuracy"):

``lbm-resolution``   Stoker's wet dam break (L1 error of h against the analytic solution) and the
                     linear seiche (period error against 2L/sqrt(gH)) against ms per LBM step, over
                     grid resolutions, with the observed convergence order between resolutions.
``lbm-precision``    float32 against float16 storage of the distributions (``storage="fp16s"`` of
                     ``lbm.ShallowWater`` where the solver accepts it): the same errors against
                     lattice updates per second.
``bvh``              the water BLAS refitted every frame against rebuilt every frame over a long
                     run with rain: trace time and SAH cost as the refitted tree ages, update ms.
``spp``, ``fresnel``, ``bounces``, ``min-contribution``
                     image error (RMSE of the 8-bit image / 255) against a high-sample, deep
                     reference (exact Fresnel, no contribution cut-off), against ms per frame.
``grid-vs-pixels``   the image difference when the water grid is refined, against the pixels a
                     water cell covers: where more cells stop changing the picture.
``caustics-noise``   the caustic map of the pool floor against photons per frame: relative RMS
                     error against a high-photon reference of the same water, frame-to-frame
                     flicker of still water (only the jitter changes) without and with the
                     temporal blend, and the caustics stage's device ms.
``stability``        where the methods fail: the plain LBM and the guarded one over depth, tau
                     and disturbances (drops, a dip, pushes at Froude 0.3-2.5, dam breaks);
                     blow-ups, what the guard did, Stoker and volume errors
                     (app/study_stability.py). A map, not an error-against-time chart.

``--quick`` runs each at the tiny size the tests use (seconds on PoCL); times then measure a
shared CPU, not a GPU: read the charts' shapes, not their numbers.
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app import study_stability

G = 9.81


@dataclass(frozen=True)
class Study:
    name: str
    run: object          # (ctx) -> list[dict]
    chart: object        # (rows, path, ctx) -> None
    doc: str


class Context:
    """What a study gets: the runtime, the size mode and a logger."""

    def __init__(self, rt, quick: bool, out: Path, log, size: tuple[int, int] | None = None):
        self.rt, self.quick, self.out, self.log = rt, quick, out, log
        self.size = size   # image size of the render studies (None: the mode's)

    @property
    def source(self) -> str:
        mode = "quick" if self.quick else "full"
        return f"{self.rt.name[:60]}, {time.strftime('%Y-%m-%d')}, {mode}"


def _event_ms(rt, stage: str) -> float:
    return float(rt.timer.collect().get(stage, 0.0))


def _orders(rows: list[dict], key_h: str, key_e: str) -> None:
    """Observed order log(e1/e2)/log(h1/h2) between consecutive rows (in place)."""
    for a, b in zip(rows, rows[1:], strict=False):
        if a[key_e] > 0 and b[key_e] > 0 and a[key_h] != b[key_h]:
            b["order"] = round(math.log(a[key_e] / b[key_e]) / math.log(a[key_h] / b[key_h]), 3)
    if rows:
        rows[0].setdefault("order", "")
    for r in rows:
        r.setdefault("order", "")


def fit_order(h, e) -> float:
    """Least-squares slope of log e against log h: the convergence order over all points."""
    lh, le = np.log(np.asarray(h, float)), np.log(np.asarray(e, float))
    return float(np.polyfit(lh, le, 1)[0]) if len(lh) >= 2 else float("nan")


# ---- LBM: Stoker's dam break and the seiche -----------------------------------------------------
def _solver(rt, nx: int, dx: float, storage: str | None, **kw):
    import lbm

    if storage is None or storage == "fp32":
        return lbm.ShallowWater(nx, 3, dx, boundary="slip", device=rt, **kw)
    return lbm.ShallowWater(nx, 3, dx, boundary="slip", device=rt, storage=storage, **kw)


def stoker_run(rt, nx: int, storage: str | None = None, L: float = 2.0, frac: float = 0.8):
    """(L1 error of h / h0, ms per step, steps) of Stoker's wet dam break (h0 = 1, hr = 0.5, dam
    in the middle) on nx cells, run until the waves have covered ``frac`` of the way to the
    walls: the setup of tests/lbm/test_validation.py."""
    from lbm.analytic import stoker

    dx = L / nx
    x = (np.arange(nx) + 0.5) * dx
    sim = _solver(rt, nx, dx, storage, expected_speed=1.0)
    sim.set_state(np.tile(np.where(x < L / 2, 1.0, 0.5), (3, 1)))
    steps = round(frac * L / 2 / math.sqrt(G) / sim.dt)
    rt.finish()
    rt.timer.collect()
    sim.step(steps)
    rt.finish()
    ms = _event_ms(rt, "lbm.step") / steps
    h = sim.fields()["h"]
    exact, _ = stoker(x, sim.time, L / 2, 1.0, 0.5, G)
    return float(np.mean(np.abs(h[1] - exact))), ms, steps


def seiche_run(rt, nx: int, storage: str | None = None, L: float = 4.0, H: float = 0.5,
               A: float = 0.005, periods: float = 2.0):
    """(|period error| / T, ms per step, steps) of the linear seiche 2L/sqrt(gH) in a basin of nx
    cells: the mode's amplitude is sampled ~60 times a period; zero crossings interpolated."""
    dx = L / nx
    x = (np.arange(nx) + 0.5) * dx
    sim = _solver(rt, nx, dx, storage)
    sim.set_state(np.tile(H + A * np.cos(np.pi * x / L), (3, 1)))
    T = 2 * L / math.sqrt(G * H)
    mode = np.cos(np.pi * x / L)
    chunk = max(1, int(T / sim.dt / 60))
    ts, amp, ms, steps = [0.0], [A], 0.0, 0
    rt.finish()
    rt.timer.collect()
    while sim.time < periods * T + 2 * chunk * sim.dt:
        sim.step(chunk)
        steps += chunk
        ts.append(sim.time)
        amp.append((sim.fields()["h"][1].astype(np.float64) - H) @ mode / (mode @ mode))
        ms += _event_ms(rt, "lbm.step")
    ts, amp = np.array(ts), np.array(amp)
    k = np.flatnonzero(np.sign(amp[:-1]) * np.sign(amp[1:]) < 0)
    if len(k) < 2:
        return float("nan"), ms / steps, steps
    crossings = ts[k] - amp[k] * (ts[k + 1] - ts[k]) / (amp[k + 1] - amp[k])
    measured = 2 * float(np.mean(np.diff(crossings)))
    return abs(measured - T) / T, ms / steps, steps


def _square_mlups(rt, n: int, storage: str | None, steps: int) -> float:
    """Lattice updates per second (millions) of a square n x n pool with a drop: throughput on a
    grid big enough to time, beside the 3-row validation runs."""
    import lbm

    kw = {} if storage in (None, "fp32") else {"storage": storage}
    sim = lbm.ShallowWater(n, n, 1.0 / n, device=rt, depth=0.3, **kw)
    sim.add_drop(0.5, 0.5, 0.1, 0.02)
    sim.step(2)
    rt.finish()
    rt.timer.collect()
    sim.enqueue_steps(steps)
    rt.finish()
    ms = _event_ms(rt, "lbm.step")
    return n * n * steps / max(ms, 1e-9) / 1e3


def lbm_resolution(ctx) -> list[dict]:
    stoker_n = (50, 100, 200) if ctx.quick else (100, 200, 400, 800, 1600)
    seiche_n = (16, 32, 64) if ctx.quick else (32, 64, 128, 256, 512)
    rows = []
    for case, ns, fn, L in (("stoker", stoker_n, stoker_run, 2.0),
                            ("seiche", seiche_n, seiche_run, 4.0)):
        part = []
        for n in ns:
            err, ms, steps = fn(ctx.rt, n)
            part.append({"case": case, "cells": n, "dx_m": L / n, "steps": steps,
                         "ms_per_step": round(ms, 5), "error": err})
            ctx.log(f"{case:6s} {n:5d} cells: error {err:.3e}, {ms:.4f} ms/step")
        _orders(part, "dx_m", "error")
        rows += part
    return rows


#: Errors of exactly 0 (an image identical to the reference) are drawn here on log axes.
ZERO_FLOOR = 1e-6


def _chart_error_time(rows, path, ctx, group: str, title: str, xkey: str, xlabel: str,
                      note: str, ykey: str = "error", ylabel: str = "error"):
    from app import charts

    fig, ax = charts.figure(title, xlabel, ylabel, log=("x", "y"))
    for i, g in enumerate(dict.fromkeys(r[group] for r in rows)):
        part = [dict(r, **{ykey: max(float(r[ykey]), ZERO_FLOOR)}) for r in rows
                if r[group] == g and r[ykey] not in ("", None) and np.isfinite(float(r[ykey]))]
        if not part:
            continue
        label = str(g)
        if "dx_m" in part[0] and len(part) >= 2:
            label += f" (order {fit_order([r['dx_m'] for r in part], [r[ykey] for r in part]):.2f})"
        charts.series(ax, [r[xkey] for r in part], [r[ykey] for r in part], label=label,
                      notes=[r[note] for r in part], index=i)
    charts.save(fig, path, source=ctx.source)


def lbm_resolution_chart(rows, path, ctx):
    _chart_error_time(rows, path, ctx, "case", "LBM: error against cost over grid resolutions "
                      "(labels: cells)", "ms_per_step", "ms per LBM step (device events)",
                      "cells", ylabel="Stoker L1(h)/h0; seiche |dT|/T")


def storage_options(rt) -> list[str]:
    """The distribution storages the solver accepts here: fp32 always, fp16s where
    ``lbm.ShallowWater(..., storage="fp16s")`` exists."""
    import lbm

    try:
        lbm.ShallowWater(3, 3, 1.0, device=rt, storage="fp16s")
    except (TypeError, ValueError):
        return ["fp32"]
    return ["fp32", "fp16s"]


def lbm_precision(ctx) -> list[dict]:
    storages = storage_options(ctx.rt)
    if storages == ["fp32"]:
        ctx.log("the solver has no storage='fp16s' option yet; fp32 only")
    n_stoker = 200 if ctx.quick else 800
    n_seiche = 32 if ctx.quick else 256
    n_square, steps = (64, 20) if ctx.quick else (1024, 200)
    rows = []
    for s in storages:
        mlups = _square_mlups(ctx.rt, n_square, s, steps)
        for case, n, fn in (("stoker", n_stoker, stoker_run), ("seiche", n_seiche, seiche_run)):
            err, ms, nsteps = fn(ctx.rt, n, s)
            rows.append({"storage": s, "case": case, "cells": n, "steps": nsteps,
                         "ms_per_step": round(ms, 5), "error": err,
                         "square_cells": f"{n_square}x{n_square}",
                         "mlups": round(mlups, 2)})
            ctx.log(f"{s:6s} {case:6s} {n} cells: error {err:.3e}; {mlups:.1f} MLUPs/s "
                    f"at {n_square}^2")
    return rows


def lbm_precision_chart(rows, path, ctx):
    from app import charts

    fig, ax = charts.figure("LBM storage: error against lattice updates per second",
                            f"MLUPs/s ({rows[0]['square_cells']} pool, device events)",
                            "Stoker L1(h)/h0; seiche |dT|/T", log=("y",))
    for i, case in enumerate(("stoker", "seiche")):
        part = [r for r in rows if r["case"] == case and r["error"] > 0]
        charts.series(ax, [r["mlups"] for r in part], [r["error"] for r in part],
                      label=f"{case} ({part[0]['cells']} cells)" if part else case,
                      notes=[r["storage"] for r in part], index=i, line=False)
    charts.save(fig, path, source=ctx.source)


# ---- BVH: refit against rebuild over a long run ----------------------------------------------
def _downward_rays(rt, n_side: int, size, depth: float, rng):
    """Primary-like rays from a camera above the pool corner, and incoherent rays just above the
    water going down: device (origins, directions) buffers and the count."""
    from raytrace.query import pack_rays

    lx, ly = size
    eye = np.array([-0.3 * lx, depth + 0.8 * max(lx, ly), -0.3 * ly])
    u, v = np.meshgrid(np.linspace(0.05, 0.95, n_side), np.linspace(0.05, 0.95, n_side))
    target = np.stack([u.ravel() * lx, np.full(u.size, depth), v.ravel() * ly], -1)
    d1 = target - eye
    o1 = np.broadcast_to(eye, d1.shape)
    o2 = np.stack([rng.uniform(0, lx, u.size), np.full(u.size, depth + 0.2),
                   rng.uniform(0, ly, u.size)], -1)
    d2 = rng.normal(size=(u.size, 3))
    d2[:, 1] = -np.abs(d2[:, 1]) - 0.1
    o, d = pack_rays(np.concatenate([o1, o2]), np.concatenate([d1, d2]), 0.0, 1e6)
    return rt.to_device(o), rt.to_device(d), len(o)


def bvh(ctx) -> list[dict]:
    import lbm
    from raytrace.bvh import HIT_DTYPE
    from raytrace.query import RayQuery
    from raytrace.scene import Scene

    rt = ctx.rt
    n, frames, every, side = (48, 60, 10, 48) if ctx.quick else (512, 2000, 100, 512)
    size, depth = (2.0, 2.0), 0.3
    rows = []
    for mode in ("refit", "rebuild"):
        sim = lbm.ShallowWater(n, n, size[0] / n, device=rt, depth=depth, viscosity=1e-5,
                               expected_speed=1.0)
        sim.set_rain(40.0 if ctx.quick else 20.0, 0.12, 0.04, seed=7)
        sim.add_drop(0.6, 0.7, 0.3, 0.08)
        verts, norms = rt.buffer(16 * n * n), rt.buffer(16 * n * n)
        sim.write_surface(verts, norms)
        scene = Scene(rt, stage="study.bvh")
        tris = lbm.grid_triangles(n, n)
        mesh = scene.add_mesh(verts, rt.to_device(np.ascontiguousarray(tris, np.uint32)),
                              dynamic=True, n_vertices=n * n, n_triangles=len(tris))
        scene.add_instance(mesh)
        scene.update()
        org, dirs, n_rays = _downward_rays(rt, side, size, depth, np.random.default_rng(3))
        hits = rt.buffer(HIT_DTYPE.itemsize * n_rays)
        q = RayQuery(scene, org, dirs, hits, n_rays, stage="study.trace")
        steps = max(1, round((1 / 60) / sim.dt))
        for f in range(frames + 1):
            sim.step(steps)
            sim.write_surface(verts, norms)
            rt.finish()
            rt.timer.collect()
            t0 = time.perf_counter()
            scene.update(rebuild=(mode == "rebuild"))
            rt.finish()
            update_wall = (time.perf_counter() - t0) * 1e3
            update_ms = sum(rt.timer.collect().values())   # only the update ran since the last
            if f % every:
                continue
            trace = []
            for _ in range(3):
                q.enqueue()
                rt.finish()
                trace.append(_event_ms(rt, "study.trace"))
            stats = scene.blas(mesh).stats()
            row = {"bvh": mode, "frame": f, "sim_time_s": round(sim.time, 4),
                   "cells": f"{n}x{n}", "rays": n_rays, "update_ms": round(update_ms, 4),
                   "update_wall_ms": round(update_wall, 4),
                   "trace_ms": round(statistics.median(trace), 4),
                   "mrays_s": round(n_rays / statistics.median(trace) / 1e3, 3),
                   "sah_cost": round(float(stats["sah_cost"]), 3)}
            rows.append(row)
            ctx.log(f"{mode:7s} frame {f:5d}: update {row['update_ms']:.3f} ms, trace "
                    f"{row['trace_ms']:.3f} ms ({row['mrays_s']:.2f} Mrays/s), SAH "
                    f"{row['sah_cost']:.2f}")
        del q, scene
    return rows


def bvh_chart(rows, path, ctx):
    from app import charts

    fig, ax = charts.figure("Water BLAS refit vs rebuild as the tree ages (labels: SAH cost)",
                            "frames since the first build", "update + trace ms per frame")
    for i, mode in enumerate(("refit", "rebuild")):
        part = [r for r in rows if r["bvh"] == mode]
        upd = statistics.median(r["update_ms"] for r in part)
        charts.series(ax, [r["frame"] for r in part],
                      [r["update_ms"] + r["trace_ms"] for r in part],
                      label=f"{mode} (update {upd:.3f} ms median)",
                      notes=[f"{r['sah_cost']:.1f}" for r in part], index=i)
    charts.save(fig, path, source=ctx.source)


# ---- render studies --------------------------------------------------------------------------
STUDY_SCENE = """
[scene]
name = "study pool"
description = "A small pool after two drops with a glass bunny: the render studies' scene."

[render]
width = 320
height = 180

[camera]
eye = [2.6, 1.1, 2.9]
target = [1.0, 0.2, 0.75]
fov = 50

[water]
size = [2.0, 1.5]
cells = [100, 75]
depth = 0.4

[[water.drops]]
x = 0.6
y = 0.5
radius = 0.15
height = 0.04

[[water.drops]]
x = 1.4
y = 1.0
radius = 0.12
height = -0.03

[[lights]]
kind = "directional"
direction = [-0.5, -0.75, -0.45]
color = [2.2, 2.1, 1.9]

[sky]
sun_direction = [0.5, 0.75, 0.45]

[pool]
wall_height = 0.6
steps = 0

[[meshes]]          # a glass bunny half in the water: paths several bounces deep
file = "bunny_5k.obj"
material = "glass"
size = 0.6
position = [1.0, 0.15, 0.75]
rotation = [0.0, 200.0, 0.0]

[materials.glass]
diffuse = [0.9, 0.9, 0.9]
specular = [0.6, 0.6, 0.6]
shininess = 200
ior = 1.5
absorption = [0.4, 0.2, 0.1]
"""


def study_scene():
    from app.scene import parse_scene

    return parse_scene(STUDY_SCENE, Path(__file__).resolve().parent.parent / "scenes" /
                       "<study scene>.toml")


def _render(ctx, *, spp=1, bounces=8, shading=None, cells=None, seconds=0.4, timed=2,
            size=None):
    """(RGBA8 image, median wall ms, median kernel ms) of the study scene after ``seconds`` of
    water: the render studies' only contact with the World."""
    from app.frames import open_world

    w, h = ctx.size or size or ((48, 27) if ctx.quick else (320, 180))
    world = open_world(study_scene(), ctx.rt, width=w, height=h, spp=spp, bounces=bounces,
                       cells=cells, shading=shading)
    img = world.frame(seconds).copy()
    walls, kernels = [], []
    for _ in range(timed):
        world.frame(0.0)
        if world.stats is not None:   # the last completed frame's
            walls.append(world.stats.wall_ms)
            kernels.append(world.stats.kernel_ms)
    world.close()
    return img, statistics.median(walls or [0.0]), statistics.median(kernels or [0.0])


def _rmse(a, b) -> float:
    d = a[..., :3].astype(np.float64) - b[..., :3].astype(np.float64)
    return float(np.sqrt(np.mean(d * d)) / 255.0)


def _ref_spp(ctx) -> int:
    return 16 if ctx.quick else 256


def _ref_bounces(ctx) -> int:
    return 8 if ctx.quick else 16


def _render_rows(ctx, variants) -> list[dict]:
    """One row per variant (name, value, render kwargs) against the shared reference: the
    highest spp and depth of the study, exact Fresnel, no contribution cut-off."""
    spp, bounces = _ref_spp(ctx), _ref_bounces(ctx)
    ref, _, _ = _render(ctx, spp=spp, bounces=bounces,
                        shading={"fresnel": "exact", "min_contribution": 0.0}, timed=1)
    rows = []
    for name, value, kw in variants:
        img, wall, kern = _render(ctx, **kw)
        err = _rmse(img, ref)
        rows.append({"variant": name, "value": value, "spp": kw.get("spp", 1),
                     "bounces": kw.get("bounces", 8), "rmse": err, "wall_ms": round(wall, 3),
                     "kernel_ms": round(kern, 3), "width": img.shape[1], "height": img.shape[0],
                     "reference": f"{spp} spp, {bounces} bounces, exact Fresnel, no cut-off"})
        ctx.log(f"{name} {value} ({rows[-1]['spp']} spp): RMSE {err:.3e}, {wall:.2f} ms/frame "
                f"(kernels {kern:.2f})")
    return rows


def spp_study(ctx):
    values = (1, 2, 4, 8) if ctx.quick else (1, 2, 4, 8, 16, 32, 64)
    return _render_rows(ctx, [("spp", s, {"spp": s, "bounces": _ref_bounces(ctx)})
                              for s in values])


def fresnel_study(ctx):
    """Both laws at a few spp, and Schlick at the reference's spp (its error alone)."""
    spps = (1, 4) if ctx.quick else (1, 4, 16)
    b = _ref_bounces(ctx)
    v = [(f, s, {"spp": s, "bounces": b, "shading": {"fresnel": f, "min_contribution": 0.0}})
         for f in ("exact", "schlick") for s in spps]
    s = _ref_spp(ctx)
    v.append(("schlick", s, {"spp": s, "bounces": b,
                             "shading": {"fresnel": "schlick", "min_contribution": 0.0}}))
    return _render_rows(ctx, v)


def bounces_study(ctx):
    """Depths at the reference's spp: the error is the depth's alone."""
    values = (0, 1, 2, 3, 5) if ctx.quick else (0, 1, 2, 3, 4, 5, 6, 8, 10)
    s = _ref_spp(ctx)
    return _render_rows(ctx, [("bounces", b, {"spp": s, "bounces": b,
                                              "shading": {"min_contribution": 0.0}})
                              for b in values])


def min_contribution_study(ctx):
    """Cut-offs at the reference's spp and depth: the error is the cut-off's alone."""
    values = (0.1, 0.01, 1e-3) if ctx.quick else (0.3, 0.1, 0.03, 0.01, 3e-3, 1e-3, 3e-4, 1e-4)
    s, b = _ref_spp(ctx), _ref_bounces(ctx)
    return _render_rows(ctx, [("min_contribution", v, {"spp": s, "bounces": b,
                                                       "shading": {"min_contribution": v}})
                              for v in values])


def _render_chart(title):
    def chart(rows, path, ctx):
        _chart_error_time(rows, path, ctx, "variant", title, "wall_ms",
                          "ms per frame (wall, median)", "value", ykey="rmse",
                          ylabel=f"RMSE vs the reference (8-bit / 255; 0 drawn at {ZERO_FLOOR:g})")
    return chart


def _pool_pixels(scene, width: int, height: int) -> int:
    """Pixels whose centre ray meets the still water plane inside the pool (pinhole camera,
    independent of the tracer): the pool's footprint in the image."""
    c, w = scene.camera, scene.water
    eye, target, up = (np.asarray(v, float) for v in (c.eye, c.target, c.up))
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, fwd)
    t = math.tan(math.radians(c.fov) / 2)
    ys, xs = np.mgrid[0:height, 0:width]
    u = ((xs + 0.5) / width * 2 - 1) * t * width / height
    v = (1 - (ys + 0.5) / height * 2) * t
    d = fwd + u[..., None] * right + v[..., None] * cam_up
    plane = w.origin[1] + w.depth
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (plane - eye[1]) / d[..., 1]
    p = eye + s[..., None] * d
    inside = ((s > 0) & (p[..., 0] >= w.origin[0]) & (p[..., 0] <= w.origin[0] + w.size[0])
              & (p[..., 2] >= w.origin[2]) & (p[..., 2] <= w.origin[2] + w.size[1]))
    return int(inside.sum())


def grid_vs_pixels(ctx) -> list[dict]:
    import dataclasses

    from app.assemble import water_spec

    cells = (16, 32, 64, 128) if ctx.quick else (25, 50, 100, 200, 400, 800)
    size = ctx.size or ((64, 36) if ctx.quick else (640, 360))
    imgs = {}
    rows = []
    for n in cells:
        img, wall, kern = _render(ctx, cells=n, size=size, spp=1 if ctx.quick else 4,
                                  bounces=5, timed=2)
        imgs[n] = img
        base = study_scene()
        sc = dataclasses.replace(base, water=water_spec(base, n))
        nx, ny = sc.water.cells
        rows.append({"cells": n, "grid": f"{nx}x{ny}", "width": size[0], "height": size[1],
                     "pixels_per_cell": round(_pool_pixels(sc, *size) / (nx * ny), 4),
                     "wall_ms": round(wall, 3), "kernel_ms": round(kern, 3)})
    for r, n in zip(rows, cells, strict=True):
        finer = [m for m in cells if m > n]
        r["diff_to_next"] = _rmse(imgs[n], imgs[finer[0]]) if finer else ""
        r["diff_to_finest"] = _rmse(imgs[n], imgs[cells[-1]]) if finer else ""
        nxt = "-" if r["diff_to_next"] == "" else f"{r['diff_to_next']:.4f}"
        ctx.log(f"{r['grid']:>9s} cells: {r['pixels_per_cell']:.3f} px/cell, RMSE to the next "
                f"grid {nxt}")
    return rows


def grid_vs_pixels_chart(rows, path, ctx):
    from app import charts

    part = [r for r in rows if r["diff_to_next"] != ""]
    fig, ax = charts.figure("Image change when the water grid is refined (labels: grid)",
                            "pool pixels per water cell",
                            "RMSE to the next finer grid (8-bit / 255)", log=("x", "y"))
    charts.series(ax, [r["pixels_per_cell"] for r in part],
                  [max(r["diff_to_next"], 1e-6) for r in part], label="to the next grid",
                  notes=[r["grid"] for r in part], index=0)
    charts.series(ax, [r["pixels_per_cell"] for r in part],
                  [max(r["diff_to_finest"], 1e-6) for r in part],
                  label=f"to the finest ({rows[-1]['grid']})", index=1)
    charts.save(fig, path, source=ctx.source)


def _rel_rms(a, b) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / max(np.sqrt(np.mean(b**2)), 1e-30))


def caustics_noise(ctx) -> list[dict]:
    """The study scene's water after 0.4 s, then held still; floor maps per photon count."""
    from app.frames import open_world

    if ctx.quick:
        photons, reference, cells, res, settle = (1024, 4096, 16384), 131072, 40, 64, 4
    else:
        photons, reference, cells, res, settle = ((4096, 16384, 65536, 262144, 1048576),
                                                  4194304, 100, 256, 8)

    def world(n: int, blend: float):
        w = open_world(study_scene(), ctx.rt, width=16, height=16, cells=cells, shading={
            "caustics": "traced", "caustic_photons": n, "caustic_resolution": res,
            "caustic_blend": blend})
        w.frame(0.4)
        return w

    def floor(w) -> np.ndarray:
        return w.read_caustics()["floor"][..., 0].astype(np.float64)

    ref = floor(world(reference, 0.0))
    rows = []
    for n in photons:
        w = world(n, 0.0)
        a = floor(w)
        w.frame(0.0)
        b = floor(w)
        ms = sum(v for k, v in w.stats.stage_ms.items() if k.startswith("caustics."))
        wb = world(n, 0.5)
        for _ in range(settle):
            wb.frame(0.0)
        m1 = floor(wb)
        wb.frame(0.0)
        m2 = floor(wb)
        nz, nx = a.shape
        rows.append({"photons": n, "photons_per_floor_texel": round(n / (nx * nz), 4),
                     "error_vs_reference": round(_rel_rms(a, ref), 5),
                     "flicker": round(_rel_rms(b, a), 5),
                     "flicker_blended": round(_rel_rms(m2, m1), 5), "blend": 0.5,
                     "caustics_ms": round(ms, 3), "texels": f"{nx}x{nz}",
                     "reference_photons": reference})
        ctx.log(f"{n:>8d} photons: error {rows[-1]['error_vs_reference']:.4f}, flicker "
                f"{rows[-1]['flicker']:.4f} ({rows[-1]['flicker_blended']:.4f} blended), "
                f"{ms:.2f} ms")
    return rows


def caustics_noise_chart(rows, path, ctx):
    from app import charts

    fig, ax = charts.figure(f"Caustic noise against photons per frame ({rows[0]['texels']} "
                            "floor texels)", "photons per frame",
                            "relative RMS over the pool floor", log=("x", "y"))
    n = [r["photons"] for r in rows]
    charts.series(ax, n, [r["error_vs_reference"] for r in rows],
                  label=f"error vs {rows[0]['reference_photons']} photons", index=0)
    charts.series(ax, n, [r["flicker"] for r in rows], label="frame-to-frame flicker", index=1)
    charts.series(ax, n, [r["flicker_blended"] for r in rows],
                  label=f"flicker, blend {rows[0]['blend']}", index=2)
    k = rows[0]["flicker"] * math.sqrt(n[0])
    charts.reference(ax, n, [k / math.sqrt(x) for x in n], label="photons^-1/2")
    charts.save(fig, path, source=ctx.source)


STUDIES = {s.name: s for s in (
    Study("lbm-resolution", lbm_resolution, lbm_resolution_chart,
          "Stoker and seiche error against ms per step over resolutions"),
    Study("lbm-precision", lbm_precision, lbm_precision_chart,
          "fp32 vs fp16s storage: error against MLUPs/s"),
    Study("bvh", bvh, bvh_chart, "water BLAS refit vs rebuild over a long run"),
    Study("spp", spp_study, _render_chart("Samples per pixel: image error against time "
                                          "(labels: spp)"), "image error vs spp"),
    Study("fresnel", fresnel_study, _render_chart("Schlick vs exact Fresnel (labels: spp)"),
          "image error, Schlick vs exact Fresnel"),
    Study("bounces", bounces_study, _render_chart("Bounces: image error against time "
                                                  "(labels: depth)"), "image error vs depth"),
    Study("min-contribution", min_contribution_study,
          _render_chart("Contribution cut-off: image error against time (labels: cut-off)"),
          "image error vs the secondary-ray cut-off"),
    Study("grid-vs-pixels", grid_vs_pixels, grid_vs_pixels_chart,
          "image change when the grid is refined, vs pixels per cell"),
    Study("caustics-noise", caustics_noise, caustics_noise_chart,
          "caustic map error and flicker against photons per frame"),
    Study("stability", study_stability.stability, study_stability.stability_chart,
          "plain vs guarded LBM over depth, tau and disturbances: blow-ups and guard actions"),
)}


def run_study(name: str, out: Path, rt, quick: bool, log=print,
              size: tuple[int, int] | None = None) -> tuple[Path, Path]:
    """Run study ``name``; write ``out/name.csv`` and ``out/name.png``; return their paths."""
    from app.errors import InputError
    from app.io import write_csv

    if name not in STUDIES:
        raise InputError(f"unknown study {name!r}; valid: {', '.join(STUDIES)}, all")
    s = STUDIES[name]
    ctx = Context(rt, quick, out, log, size)
    rows = s.run(ctx)
    csv_path, png_path = out / f"{name}.csv", out / f"{name}.png"
    write_csv(csv_path, [{**r, "device": rt.name, "date": time.strftime("%Y-%m-%d"),
                          "mode": "quick" if quick else "full"} for r in rows])
    s.chart(rows, png_path, ctx)
    return csv_path, png_path


# ---- the command ------------------------------------------------------------------------------
def add_arguments(p) -> None:
    p.add_argument("name", help=f"study: {', '.join(STUDIES)}, or all")
    p.add_argument("-o", "--out", required=True, help="folder for NAME.csv and NAME.png")
    p.add_argument("--quick", action="store_true",
                   help="tiny sizes (seconds on a CPU; the tests' size)")
    p.add_argument("--size", metavar="WxH", help="image size of the render studies (default "
                   "320x180; 48x27 with --quick, 64x36 for grid-vs-pixels)")
    p.add_argument("--device", help="OpenCL device: gpu, cpu, P:D or part of a name")


def _size(text: str | None) -> tuple[int, int] | None:
    from app.errors import InputError

    if text is None:
        return None
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size {text!r}: give WxH, e.g. 320x180") from None
    if not (8 <= w <= 8192 and 8 <= h <= 8192):
        raise InputError(f"--size {text!r}: sides must lie in [8, 8192]")
    return w, h


def run(args) -> int:
    from app.errors import InputError
    from kernels import get_runtime

    names = list(STUDIES) if args.name == "all" else [args.name]
    if args.name != "all" and args.name not in STUDIES:
        raise InputError(f"unknown study {args.name!r}; valid: {', '.join(STUDIES)}, all")
    size = _size(args.size)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"-o {args.out!r} exists and is not a folder")
    rt = get_runtime(args.device)
    for name in names:
        t0 = time.perf_counter()
        csv_path, png_path = run_study(name, out, rt, args.quick,
                                       log=lambda m, n=name: print(f"{n}: {m}", flush=True),
                                       size=size)
        print(f"{name}: wrote {csv_path} and {png_path} in {time.perf_counter() - t0:.1f} s",
              file=sys.stderr)
    return 0
