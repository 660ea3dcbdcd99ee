"""Sweep grid size, image size, bounces and samples: FPS, stage times, rays, memory; CSV, JSON
and charts.

    lbwater sweep scenes/pool.toml --cells 128,256,512 --size 640x360,1920x1080 \\
        --bounces 2,5 --spp 1,4 --frames 20 --warmup 5 -o out/sweep

Each point (every combination of the lists) makes one World and runs ``--warmup`` frames, then
``--frames`` timed frames through the frame pipeline (frame N+1 enqueued before N is read, as
capture and the window run), each advancing the water by ``--frame-time`` s. Per point: FPS
(frames over wall time), the median frame's wall ms, median ms per stage (OpenCL events), the
triangles, the rays per frame and the device memory. Rows go to ``DIR/sweep.csv`` and
``DIR/sweep.json`` as each point finishes; a rerun skips the points already there (same scene,
device and settings), so an interrupted sweep resumes. Charts: ``fps_vs_cells.png`` (with the
seed's water demo: 100^2 18, 200^2 12, 300^2 6 FPS), ``stages_by_cells.png`` (stacked stage
times per grid) and ``frame_ms_vs_rays.png``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import statistics
import sys
import time
from pathlib import Path

from app.errors import InputError

SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"
#: The seed's water demo (LBM on the CPU, heights copied every frame): grid side -> FPS.
SEED_FPS = {100: 18.0, 200: 12.0, 300: 6.0}
#: Stage groups of the stacked chart, in drawing order: (label, name prefixes). With the
#: renderer's overlap_levels, "shadows" also holds the secondary traces launched with them
#: (render.shadow_trace).
STAGE_GROUPS = (("lbm", ("lbm.step", "lbm.guard", "lbm.sources")), ("surface", ("lbm.surface",)),
                ("bvh", ("bvh.",)), ("primary trace", ("render.trace",)),
                ("shadows", ("render.shadow", "render.shadow_trace")),
                ("secondary", ("render.trace_secondary", "render.secondary")),
                ("shade + gather", ("render.shade", "render.gather")), ("other", ()))
KEY = ("scene", "device", "cells", "width", "height", "bounces", "spp", "frames", "warmup",
       "frame_time")


def _int_list(name: str, lo: int, hi: int):
    def parse(text: str) -> list[int]:
        try:
            vals = [int(x) for x in text.split(",") if x.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"--{name} {text!r}: give integers separated by "
                                             "commas, e.g. 128,256") from None
        bad = [v for v in vals if not lo <= v <= hi]
        if not vals or bad:
            raise argparse.ArgumentTypeError(f"--{name} {text!r}: each value must lie in "
                                             f"[{lo}, {hi}]")
        return vals
    return parse


def _sizes(text: str) -> list[tuple[int, int]]:
    out = []
    for part in text.split(","):
        try:
            w, h = (int(v) for v in part.lower().split("x"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"--size {part!r}: give WxH, e.g. 1920x1080") \
                from None
        if not (1 <= w <= 16384 and 1 <= h <= 16384):
            raise argparse.ArgumentTypeError(f"--size {part!r}: sides must lie in [1, 16384]")
        out.append((w, h))
    return out


def add_arguments(p) -> None:
    p.add_argument("scene", nargs="?", default=str(SCENES_DIR / "pool.toml"),
                   help="scene TOML file with [water] (default scenes/pool.toml)")
    p.add_argument("--cells", type=_int_list("cells", 2, 16384), default=[100, 200, 300, 512],
                   help="water cells along the pool's longer side (default 100,200,300,512)")
    p.add_argument("--size", type=_sizes, default=[(1280, 720)],
                   help="image sizes WxH (default 1280x720)")
    p.add_argument("--bounces", type=_int_list("bounces", 0, 32),
                   help="bounce depths (default the scene's)")
    p.add_argument("--spp", type=_int_list("spp", 1, 4096),
                   help="samples per pixel (default the scene's)")
    p.add_argument("--frames", type=int, default=20, help="timed frames per point (default 20)")
    p.add_argument("--warmup", type=int, default=5, help="untimed frames first (default 5)")
    p.add_argument("--frame-time", type=float, default=1 / 60,
                   help="simulated seconds of water per frame (default 1/60)")
    p.add_argument("--device", help="OpenCL device: gpu, cpu, P:D or part of a name")
    p.add_argument("-o", "--out", default="out/sweep", help="folder for sweep.csv/json, charts")
    p.add_argument("--workers", type=int, metavar="N",
                   help="measure on N Ray actors (one per GPU, else per CPU), one point per "
                        "device at a time (needs lbwater[cluster])")
    p.add_argument("--ray-address", metavar="ADDR",
                   help="Ray cluster to join (HOST:PORT or auto; default: a local Ray)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _median_stages(stats: list) -> dict[str, float]:
    names = sorted({k for s in stats for k in s.stage_ms})
    return {k: statistics.median(s.stage_ms.get(k, 0.0) for s in stats) for k in names}


def measure(scene, rt, *, cells, size, bounces, spp, frames, warmup, frame_time) -> dict:
    """One point: warm-up, then ``frames`` pipelined frames; the row of numbers."""
    from app.frames import open_world

    world = open_world(scene, rt, width=size[0], height=size[1], bounces=bounces, spp=spp,
                       cells=cells)
    try:
        for _ in range(warmup):
            world.frame(frame_time)
        world.drain()
        stats, t0 = [], time.perf_counter()
        world.enqueue_frame(frame_time)
        for i in range(frames):
            if i + 1 < frames:
                world.enqueue_frame(frame_time)
            _, img = world.read_frame()
            st = world.stats
            if st is not None:
                stats.append(st)
                if st.guard.get("nan"):
                    raise RuntimeError(f"sweep: {cells} cells: the water guard found NaN "
                                       f"({st.guard.get('report')})")
            if img[..., 3].min() != 255:
                raise RuntimeError(f"sweep: {cells} cells: the image has unset pixels")
        elapsed = time.perf_counter() - t0
    finally:
        world.close()
    if not stats:
        raise RuntimeError("sweep: no frame statistics came back")
    last = stats[-1]
    stages = _median_stages(stats)
    nx, ny = last.water_cells or (0, 0)
    row = {"water_cells": f"{nx}x{ny}", "grid_side": round(math.sqrt(nx * ny), 1),
           "fps": round(frames / elapsed, 3),
           "frame_wall_ms": round(statistics.median(s.wall_ms for s in stats), 4),
           "kernel_ms": round(statistics.median(s.kernel_ms for s in stats), 4),
           "lbm_steps_per_frame": round(statistics.median(s.lbm_steps for s in stats), 1),
           "triangles": last.n_triangles,
           "rays_per_frame": round(statistics.median(s.n_rays for s in stats)),
           "rays_per_depth": " ".join(str(x) for x in last.rays_per_depth),
           "device_mib": round(last.device_bytes / 2**20, 2),
           "guard_acted": sum(bool(s.guard.get("acted")) for s in stats)}
    row.update(group_stages(stages))
    row["stages_ms"] = {k: round(v, 4) for k, v in stages.items()}
    return row


def _in_group(name: str, prefixes: tuple) -> bool:
    """``render.trace`` names that stage only; ``bvh.`` (a trailing dot) every bvh stage."""
    return any(name == p or (p.endswith(".") and name.startswith(p)) for p in prefixes)


def group_stages(stages: dict[str, float]) -> dict[str, float]:
    """Stage ms summed into the columns of :data:`STAGE_GROUPS`; "other" takes the rest."""
    out, grouped = {}, 0.0
    for label, prefixes in STAGE_GROUPS:
        if prefixes:
            ms = sum(v for k, v in stages.items() if _in_group(k, prefixes))
        else:
            ms = sum(stages.values()) - grouped
        grouped += ms
        out[_group_column(label)] = round(ms, 4)
    return out


def _group_column(label: str) -> str:
    return f"{label.replace(' + ', '_and_').replace(' ', '_')}_ms"


def _key(row: dict) -> tuple:
    return tuple(str(row[k]) for k in KEY)


def load_rows(out: Path) -> list[dict]:
    path = out / "sweep.json"
    if not path.exists():
        return []
    try:
        return list(json.loads(path.read_text())["rows"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{path}: not a sweep file this version can resume ({exc}); "
                         "move it away or use another -o") from None


def save_rows(out: Path, rows: list[dict]) -> None:
    from app.io import write_csv, write_json

    write_json(out / "sweep.json", {"rows": rows})
    write_csv(out / "sweep.csv", [{k: v for k, v in r.items() if k != "stages_ms"}
                                  for r in rows])


def _key_row(args, device: str, point: tuple) -> dict:
    cells, size, bounces, spp = point
    return {"scene": str(args.scene), "device": device, "cells": cells, "width": size[0],
            "height": size[1], "bounces": bounces, "spp": spp, "frames": args.frames,
            "warmup": args.warmup, "frame_time": round(args.frame_time, 9)}


def _measure_kw(args, point: tuple) -> dict:
    cells, size, bounces, spp = point
    return {"cells": cells, "size": size, "bounces": bounces, "spp": spp, "frames": args.frames,
            "warmup": args.warmup, "frame_time": args.frame_time}


def _print_row(row: dict) -> None:
    print(f"{row['water_cells']:>10} cells {row['width']}x{row['height']} b{row['bounces']} "
          f"spp{row['spp']}: {row['fps']:.2f} FPS, {row['frame_wall_ms']:.2f} ms/frame, "
          f"{row['rays_per_frame']} rays, {row['device_mib']:.1f} MiB", flush=True)


def run(args) -> int:
    from app.capture import Progress
    from app.scene import load_scene

    for name, lo in (("frames", 1), ("warmup", 0)):
        if getattr(args, name) < lo:
            raise InputError(f"--{name} {getattr(args, name)} must be >= {lo}")
    if not (math.isfinite(args.frame_time) and 0 <= args.frame_time <= 10):
        raise InputError(f"--frame-time {args.frame_time:g} is out of range; allowed [0, 10]")
    workers = getattr(args, "workers", None)
    if workers is not None:
        from app.cluster import check_workers, import_ray

        check_workers(workers)
        import_ray()
    elif getattr(args, "ray_address", None):
        raise InputError("--ray-address needs --workers N")
    scene = load_scene(args.scene)
    if scene.water is None:
        raise InputError(f"{args.scene}: sweep needs a scene with [water]")
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"-o {args.out!r}: cannot create the folder ({exc.strerror})") from None
    rows = load_rows(out)
    points = list(itertools.product(args.cells, args.size, args.bounces or [scene.render.bounces],
                                    args.spp or [scene.render.spp]))
    done = {_key(r) for r in rows}
    bar = Progress(len(points), not args.quiet)
    if workers is None:
        from kernels import get_runtime

        rt = get_runtime(args.device)
        device, skipped = rt.name, 0
        for k, point in enumerate(points):
            key_row = _key_row(args, rt.name, point)
            if _key(key_row) in done:
                skipped += 1
                bar.update(k + 1, f"skipped {skipped} done")
                continue
            row = {**key_row, "date": time.strftime("%Y-%m-%d"),
                   **measure(scene, rt, **_measure_kw(args, point))}
            rows.append(row)
            save_rows(out, rows)
            bar.update(k + 1)
            if not bar.enabled and not args.quiet:
                _print_row(row)
    else:
        from app import cluster

        with cluster.Pool(workers, address=args.ray_address, device=args.device) as pool:
            names = sorted({i["device"] for i in pool.info.values()})
            device = names[0]
            todo = [p for p in points
                    if not any(_key(_key_row(args, d, p)) in done for d in names)]
            skipped = len(points) - len(todo)
            finished = skipped
            bar.update(finished, f"skipped {skipped} done" if skipped else "")
            for k, result, dev in cluster.measure_points(
                    pool, str(Path(args.scene).resolve()),
                    [_measure_kw(args, p) for p in todo]):
                row = {**_key_row(args, dev, todo[k]), "date": time.strftime("%Y-%m-%d"),
                       **result}
                rows.append(row)
                save_rows(out, rows)
                finished += 1
                bar.update(finished)
                if not bar.enabled and not args.quiet:
                    _print_row(row)
    bar.finish()
    charts(rows, out, device)
    print(f"sweep: {len(points) - skipped} points measured, {skipped} skipped (already in "
          f"{out / 'sweep.json'}); charts in {out}", file=sys.stderr)
    return 0


# ---- charts --------------------------------------------------------------------------------------
def charts(rows: list[dict], out: Path, device: str) -> list[Path]:
    """fps_vs_cells.png, stages_by_cells.png, frame_ms_vs_rays.png from the sweep's rows."""
    from app import charts as ch

    if not rows:
        return []
    src = f"{device[:60]}, {rows[-1].get('date', '')}, {rows[0].get('frames')} frames/point"
    paths = []

    def label(r):
        return f"{r['width']}x{r['height']}, {r['bounces']} bounces, {r['spp']} spp"

    groups: dict[str, list] = {}
    for r in rows:
        groups.setdefault(label(r), []).append(r)
    fig, ax = ch.figure("Frame rate against water grid size", "grid side (sqrt of cells)",
                        "FPS (pipelined frames)", log=("x", "y"))
    for i, (name, part) in enumerate(groups.items()):
        part = sorted(part, key=lambda r: r["grid_side"])
        ch.series(ax, [r["grid_side"] for r in part], [r["fps"] for r in part], label=name,
                  index=i)
    ch.reference(ax, list(SEED_FPS), list(SEED_FPS.values()),
                 label="seed demo (CPU LBM, GTX 590, 2013)",
                 notes=[f"{n}^2" for n in SEED_FPS])
    paths.append(out / "fps_vs_cells.png")
    ch.save(fig, paths[-1], source=src)

    # stacked stages of the largest image's first setting, per grid
    big = max(groups.values(), key=lambda p: (p[0]["width"] * p[0]["height"], -p[0]["bounces"]))
    big = sorted(big, key=lambda r: r["grid_side"])
    fig, ax = ch.figure(f"Stage times per grid ({label(big[0])})", "water cells",
                        "ms per frame (device events, median)")
    stacks = {g: [r[_group_column(g)] for r in big] for g, _ in STAGE_GROUPS}
    ch.stacked_bars(ax, [r["water_cells"] for r in big], stacks)
    paths.append(out / "stages_by_cells.png")
    ch.save(fig, paths[-1], source=src)

    fig, ax = ch.figure("Frame time against rays per frame (labels: cells)", "rays per frame",
                        "ms per frame (wall, median)", log=("x", "y"))
    for i, (name, part) in enumerate(groups.items()):
        ch.series(ax, [max(r["rays_per_frame"], 1) for r in part],
                  [r["frame_wall_ms"] for r in part], label=name, index=i, line=False,
                  notes=[r["water_cells"] for r in part])
    paths.append(out / "frame_ms_vs_rays.png")
    ch.save(fig, paths[-1], source=src)
    return paths
