"""Whole-frame benchmark: the World's frame loop (LBM steps for 1/60 s of water, surface, water
BLAS refit or rebuild, TLAS, wavefront render, RGBA8 read-back) on a scene with its water grid
resized, per stage from OpenCL events and as wall time per frame (FPS), warm-up excluded.
``wall_ms`` is the throughput with frames in flight (the next frame enqueued before the last
image is read, as the window and capture run); ``latency_ms`` one frame at a time.

The goal (BENCHMARKS.md): a 1024^2 grid with a boat at 1920x1080, shadows, reflection and
refraction, >= 60 FPS on an H100. Every timed frame's guard is checked for NaN, and the last
image of each timed run for opaque pixels (the radiance for finite values at the end), else the
run fails. The timed loop reads each image as the window and capture do, into the pinned
read-back array (``read_frame(copy=False)``); ``--host-copy`` times what a plain
``read_frame()`` caller adds: a host copy of each image and a pass over its pixels.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"


def add_arguments(p) -> None:
    p.add_argument("--scene", default=str(SCENES_DIR / "pool.toml"), help="scene TOML file")
    p.add_argument("--cells", type=int, nargs="+", default=[256, 1024],
                   help="water cells along the pool's longer side (the other side keeps the "
                        "pool's aspect ratio)")
    p.add_argument("--size", type=int, nargs=2, default=[1920, 1080], help="image W H")
    p.add_argument("--frames", type=int, default=30, help="timed frames (median)")
    p.add_argument("--warmup", type=int, default=5, help="untimed frames first")
    p.add_argument("--frame-time", type=float, default=1 / 60,
                   help="simulated seconds of water per frame")
    p.add_argument("--caustics", choices=("off", "traced"),
                   help="caustics mode (default: the scene's [shading] caustics)")
    p.add_argument("--photons", type=int, metavar="N",
                   help="caustic photons per frame per light (default: the scene's "
                        "[shading] caustic_photons)")
    p.add_argument("--boats", type=int, metavar="N",
                   help="float N copies of the scene's first [[boats]] (0.5 m, in a grid) to "
                        "time the bodies stage; default: the scene's boats")
    p.add_argument("--per-depth", action="store_true",
                   help="time the renderer's stages per depth level (render.trace.d0, "
                        "render.shadow_trace.d1, ...)")
    p.add_argument("--no-overlap", action="store_true",
                   help="launch each depth level's shadow rays alone, not with the next level's "
                        "trace (RenderSettings.overlap_levels off: an A/B of the same image)")
    p.add_argument("--overlap-from", type=int, default=None, metavar="D",
                   help="overlap only the levels from depth D on (default: "
                        "RenderSettings.overlap_from, 1)")
    p.add_argument("--coop-from", default=None, metavar="D|off",
                   help="traverse the trace and shadow rays of depth D on one per work-group of "
                        "32 (RenderSettings.coop_from: the latency-bound tail levels); off: one "
                        "ray per work-item everywhere; default: the device's choice (2 on a "
                        "GPU, off on a CPU)")
    p.add_argument("--cost-bins", choices=("on", "off"), default=None,
                   help="group each work-group's shadow rays by cost (RenderSettings.cost_bins: "
                        "whole warps of crossing rays); default: the device's choice (on a GPU)")
    p.add_argument("--direct-crossings", choices=("on", "off"), default="on",
                   help="the shadow rays' crossings of the one instance holding dielectrics "
                        "(the water) walk it alone, or (off) go through the TLAS walk "
                        "(RenderSettings.direct_crossings; the same image)")
    p.add_argument("--one-crossing", choices=("on", "off"), default="on",
                   help="a shadow ray that climbs faster than the water's slopes crosses it at "
                        "most once: leave out the walks that can find nothing, or (off) walk "
                        "them (RenderSettings.one_crossing; the same image)")
    p.add_argument("--light-buffer", type=int, default=None, metavar="CELLS",
                   help="cells along each directional light's map of what blocks it "
                        "(RenderSettings.light_buffer: the shadow rays' any-hit query without a "
                        "BVH walk, the same image); 0: none; default: the device's choice")
    p.add_argument("--shadow-list", choices=("on", "off"), default=None,
                   help="trace every level's shadow rays as one list in one launch after the "
                        "last level (RenderSettings.shadow_list), or (off) a launch per level; "
                        "default: the device's choice (on a GPU)")
    p.add_argument("--no-profiling", action="store_true",
                   help="run on a queue without profiling (no per-stage times: wall and latency "
                        "only), to see what the event timestamps cost")
    p.add_argument("--host-copy", action="store_true",
                   help="copy each image out of the pinned read-back array and check its pixels "
                        "inside the timed loop (the cost a read_frame() caller adds)")
    p.add_argument("--rebuild", action="store_true",
                   help="rebuild the water BVH every frame instead of refitting it (implies "
                        "--water-accel bvh)")
    p.add_argument("--frames-in-flight", type=int, default=2,
                   help="frames queued before the loop waits for the oldest one's image "
                        "(World frames_in_flight, 1-8; the window keeps 2)")
    p.add_argument("--water-accel", choices=("grid", "bvh"), default=None,
                   help="how rays find the water: grid (its cells walked as a height field, "
                        "the default) or bvh (an LBVH refitted each frame)")


def with_boats(scene, n: int):
    """``scene`` floating ``n`` copies of its first boat, 0.5 m long, in a grid over the pool
    (mass scaled with the volume, so they float at the same relative draft)."""
    import dataclasses
    import math

    from app.errors import InputError

    if not 0 <= n <= 16:
        raise InputError(f"--boats {n} is out of range; allowed [0, 16]")
    if n and not scene.boats:
        raise InputError(f"{scene.path}: --boats needs a scene with a [[boats]] table to copy")
    if n == 0:
        return dataclasses.replace(scene, boats=())
    b = scene.boats[0]
    size = 0.5
    k = (size / b.size) ** 3 if b.size > 0 else 1.0
    cols = math.ceil(math.sqrt(n))
    rows = math.ceil(n / cols)
    sx, sy = scene.water.size
    ox, oy, oz = scene.water.origin
    boats = []
    for i in range(n):
        x = ox + sx * ((i % cols) + 0.5) / cols
        z = oz + sy * ((i // cols) + 0.5) / rows
        boats.append(dataclasses.replace(
            b, size=size, position=(x, oy + scene.water.depth - 0.02, z),
            mass=None if b.mass is None else b.mass * k))
    return dataclasses.replace(scene, boats=tuple(boats))


def run(args) -> int:
    from app.errors import InputError
    from app.frames import with_shading
    from app.io import write_csv, write_json
    from app.scene import load_scene
    from app.world import World
    from kernels import get_runtime
    from raytrace.render_types import MAX_DEPTH

    scene = load_scene(args.scene)
    if scene.water is None:
        raise InputError(f"{args.scene}: bench frame needs a scene with [water]")
    if args.boats is not None:
        scene = with_boats(scene, args.boats)
    if args.photons is not None:
        if not 1 <= args.photons <= 2**26:
            raise InputError(f"--photons {args.photons} is out of range; allowed [1, {2**26}]")
        scene = with_shading(scene, {"caustic_photons": args.photons})
    light_buffer = getattr(args, "light_buffer", None)
    if light_buffer is not None:
        from raytrace.light_buffer import MAX_CELLS

        if not 0 <= light_buffer <= MAX_CELLS:
            raise InputError(f"--light-buffer {light_buffer} is out of range; allowed "
                             f"[0, {MAX_CELLS}]")
    overlap_from = getattr(args, "overlap_from", None)
    if overlap_from is not None and not 0 <= overlap_from <= MAX_DEPTH:
        raise InputError(f"--overlap-from {overlap_from} is out of range; allowed [0, {MAX_DEPTH}]")
    coop_arg = getattr(args, "coop_from", None)
    coop_from = None if coop_arg in (None, "off") else coop_arg
    if coop_from is not None:
        try:
            coop_from = int(coop_from)
        except ValueError:
            raise InputError(f"--coop-from {coop_arg} is not a depth; allowed off or "
                             f"[0, {MAX_DEPTH}]") from None
        if not 0 <= coop_from <= MAX_DEPTH:
            raise InputError(f"--coop-from {coop_arg} is out of range; allowed off or "
                             f"[0, {MAX_DEPTH}]")
    rt = get_runtime(args.device)
    if getattr(args, "no_profiling", False):
        from kernels.runtime import Runtime

        rt = Runtime(rt.device, profiling=False, bvh_layout=rt.bvh_layout)
    rows = []
    for cells in args.cells:
        world = World(scene, rt, width=args.size[0], height=args.size[1], cells=cells,
                      rebuild_water_bvh=args.rebuild, caustics=args.caustics,
                      water_accel=getattr(args, "water_accel", None),
                      frames_in_flight=getattr(args, "frames_in_flight", 2),
                      light_buffer=light_buffer)
        if getattr(args, "per_depth", False):
            world.renderer.set_stage_per_depth(True)
        world.renderer.set_overlap(not getattr(args, "no_overlap", False), overlap_from)
        if coop_arg is not None:
            world.renderer.set_coop(coop_from)
        bins_arg = getattr(args, "cost_bins", None)
        if bins_arg is not None:
            world.renderer.set_cost_bins(bins_arg == "on")
        list_arg = getattr(args, "shadow_list", None)
        if list_arg is not None:
            world.renderer.set_shadow_list(list_arg == "on")
        world.renderer.set_direct_crossings(getattr(args, "direct_crossings", "on") == "on")
        world.renderer.set_one_crossing(getattr(args, "one_crossing", "on") == "on")
        for _ in range(args.warmup):
            world.frame(args.frame_time)
        # latency: one frame at a time, the host waiting on each image
        latency = []
        for _ in range(max(3, args.frames // 4)):
            t0 = time.perf_counter()
            world.frame(args.frame_time)
            latency.append(time.perf_counter() - t0)
        # throughput: frames in flight (the next enqueued before the last image is read)
        stages, steps, spans = [], [], []

        host_copy = bool(getattr(args, "host_copy", False))

        def check(img, pixels, world=world, cells=cells, stages=stages, steps=steps,
                  spans=spans):
            st = world.stats
            stages.append(st.stage_ms)
            steps.append(st.lbm_steps)
            spans.append(st.device_span_ms)
            if st.guard["nan"] or (pixels and img[..., 3].min() != 255):
                raise RuntimeError(f"bench frame: {cells} cells: bad frame "
                                   f"({st.guard['report']})")
            return st

        walls = []
        for _ in range(3):  # the median of three runs of --frames frames each
            t0 = time.perf_counter()
            for i in range(args.frames):
                world.enqueue_frame(args.frame_time)
                if i >= 1:
                    check(world.read_frame(copy=host_copy)[1], host_copy)
            st = check(world.read_frame(copy=host_copy)[1], True)
            walls.append((time.perf_counter() - t0) / args.frames)
        if not np.isfinite(world.read_radiance()).all():
            raise RuntimeError(f"bench frame: {cells} cells: non-finite pixels")
        names = sorted({k for s in stages for k in s})
        per_stage = {k: statistics.median(s.get(k, 0.0) for s in stages) for k in names}
        wall_ms = statistics.median(walls) * 1e3
        nx, ny = st.water_cells
        row = {"device": rt.name, "date": time.strftime("%Y-%m-%d"), "cells": f"{nx}x{ny}",
               "water_triangles": 2 * (nx - 1) * (ny - 1),
               "triangles": st.n_triangles, "width": args.size[0],
               "height": args.size[1], "lbm_steps_per_frame": round(statistics.mean(steps), 3),
               "water_accel": world.water_accel,
               "frames_in_flight": getattr(args, "frames_in_flight", 2),
               "bvh": ("rebuild" if args.rebuild else "refit") if world.water_accel == "bvh"
               else "none", "host_copy": host_copy,
               "overlap": world.renderer.settings.overlap_levels,
               "overlap_from": world.renderer.settings.overlap_from,
               "coop_from": world.renderer.settings.coop_from,
               "cost_bins": world.renderer.settings.cost_bins,
               "direct_crossings": world.renderer.settings.direct_crossings,
               "one_crossing": world.renderer.settings.one_crossing,
               "light_buffer": world.renderer.settings.light_buffer,
               "shadow_list": world.renderer.settings.shadow_list,
               "caustics": args.caustics or "scene", "boats": len(scene.boats),
               "caustic_photons": scene.shading.caustic_photons,
               "rays_per_depth": " ".join(str(n) for n in st.rays_per_depth),
               "wall_ms": round(wall_ms, 3),
               "latency_ms": round(statistics.median(latency) * 1e3, 3),
               "fps": round(1e3 / wall_ms, 1),
               "kernels_ms": round(sum(per_stage.values()), 3),
               "device_span_ms": round(statistics.median(spans), 3),
               "profiling": rt.timer.enabled,
               "device_mb": round(st.device_bytes / 2**20, 1),
               **{f"{k}_ms": round(v, 4) for k, v in per_stage.items()}}
        rows.append(row)
        print(f"{row['cells']:>10} cells, {row['lbm_steps_per_frame']:g} steps/frame, "
              f"{args.size[0]}x{args.size[1]}: "
              f"{wall_ms:.2f} ms/frame ({row['fps']} FPS), kernels {row['kernels_ms']:.2f} ms, "
              f"device span {row['device_span_ms']:.2f} ms", flush=True)
    out = Path(args.out)
    write_json(out / "bench_frame.json", rows)
    write_csv(out / "bench_frame.csv", rows)
    return 0
