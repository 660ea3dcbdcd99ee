"""Renderer benchmark: the seed's tables (BENCHMARKS.md, "Renderer") on its five scenes at
512^2 and 1024^2 (per-stage ms from OpenCL events, secondary ray counts, total ms and FPS, the
seed's numbers and our speed-up), and image error against a high-sample reference as samples per
pixel grow, with time (CSV + chart).

Each scene is also rendered small on a second device (--check-device, PoCL's CPU by default when
the bench runs on a GPU) and the run fails when the two images disagree, when a pixel is not
finite or when rays were dropped.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"

#: The seed (2013 OpenCL tracer, GTX 590): ms per frame at 512^2 and 1024^2 (BENCHMARKS.md).
SEED_MS = {
    "hand": (11.6, 23.3),
    "human": (21.9, 31.9),
    "boat": (22.9, 54.2),
    "dragon": (106.9, 290.9),
    "buddha": (57.1, 136.9),
}
SEED_BYTES_PER_RAY = 144

#: Our stage names -> the seed's table columns (with fuse_trace_shade, render.trace and
#: render.trace_secondary include the shading of their hits; with overlap_levels, the shadows
#: include the secondary traces launched with them, render.shadow_trace).
COLUMNS = {
    "ray_creation": ("render.raygen",),
    "primary_trace": ("render.trace",),
    "shadows": ("render.shadow", "render.shadow_trace"),
    "secondary_trace": ("render.trace_secondary",),
    "shading": ("render.shade", "render.secondary", "render.gather"),
}


def add_arguments(p) -> None:
    p.add_argument("--scenes", nargs="+", default=list(SEED_MS), choices=list(SEED_MS),
                   metavar="SCENE", help=f"seed scene names: {', '.join(SEED_MS)}")
    p.add_argument("--sizes", nargs="+", type=int, default=[512, 1024], help="square sizes")
    p.add_argument("--repeats", type=int, default=10, help="timed frames (median)")
    p.add_argument("--warmup", type=int, default=2, help="untimed frames first")
    p.add_argument("--check-device", default="cpu",
                   help="second device for the image check ('none' to skip)")
    p.add_argument("--check-size", type=int, default=64, help="image size of the check")
    p.add_argument("--convergence-scene", default="pool", help="scene of the spp study")
    p.add_argument("--convergence-size", type=int, nargs=2, default=[192, 108])
    p.add_argument("--spp", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32, 64])
    p.add_argument("--reference-spp", type=int, default=256)
    p.add_argument("--local-sizes", type=int, nargs="+", default=[64, 128, 256],
                   help="work-group sizes tried; the table reports the fastest")
    p.add_argument("--fuse", default="both", choices=["both", "on", "off"],
                   help="fuse_trace_shade settings tried (both: the table reports the fastest)")


def _frame_times(rt, renderer, repeats: int, warmup: int, enqueue_ms: list | None = None
                 ) -> tuple[dict, float]:
    """Median per-stage ms and median wall ms per frame; ``enqueue_ms`` (if given) receives
    the host time spent inside enqueue_frame of each timed frame."""
    for _ in range(warmup):
        renderer.enqueue_frame(update_scene=False)
    rt.finish()
    rt.timer.collect()
    stages: dict[str, list[float]] = {}
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        renderer.enqueue_frame(update_scene=False)
        t1 = time.perf_counter()
        rt.finish()
        walls.append((time.perf_counter() - t0) * 1e3)
        if enqueue_ms is not None:
            enqueue_ms.append((t1 - t0) * 1e3)
        for k, v in rt.timer.collect().items():
            stages.setdefault(k, []).append(v)
    return {k: statistics.median(v) for k, v in stages.items()}, statistics.median(walls)


def _with_local_size(rt, rs, renderer, ls: int, fused: bool):
    import dataclasses

    from raytrace.render import Renderer

    r = Renderer(rt, rs, dataclasses.replace(renderer.settings, local_size=ls,
                                             fuse_trace_shade=fused))
    r.set_camera_record(renderer.camera)
    return r


def _build(scene_name: str, rt, size, **kw):
    """(render scene, renderer, solver) of a shipped scene through the app's World."""
    from app.scene import load_scene
    from app.world import World

    w = World(load_scene(SCENES_DIR / f"{scene_name}.toml"), rt, width=size[0], height=size[1],
              **kw)
    return w.render_scene, w.renderer, w.sim


def _check_against(rt, check_rt, name: str, size: int) -> dict:
    """Render the scene small on both devices; raise when the images disagree."""
    imgs = []
    for r_ in (rt, check_rt):
        _, renderer, _ = _build(name, r_, (size, size))
        imgs.append(renderer.render().astype(np.int32))
        fb = renderer.read_framebuffer()
        if not np.isfinite(fb).all():
            raise RuntimeError(f"bench render: {name}: non-finite pixels on {r_.name}")
    diff = np.abs(imgs[0] - imgs[1])[..., :3].max(axis=2)
    mean, frac = float(diff.mean()), float((diff > 8).mean())
    if mean > 1.5 or frac > 0.01:
        raise RuntimeError(f"bench render: {name}: {rt.name} and {check_rt.name} disagree "
                           f"(mean |diff| {mean:.2f}/255, {100 * frac:.2f}% pixels off by > 8)")
    return {"check_mean_abs_diff": mean, "check_frac_off": frac}


def run(args) -> int:
    from app.io import write_csv
    from kernels import get_runtime

    rt = get_runtime(args.device)
    check_rt = None
    if args.check_device != "none":
        check_rt = get_runtime(args.check_device)
        if check_rt.device.int_ptr == rt.device.int_ptr:
            check_rt = None
    out = Path(args.out)
    rows = []
    date = time.strftime("%Y-%m-%d")
    for name in args.scenes:
        if name not in SEED_MS:
            raise ValueError(f"unknown seed scene {name!r}; valid: {', '.join(SEED_MS)}")
        check = _check_against(rt, check_rt, name, args.check_size) if check_rt else {}
        for size in args.sizes:
            rs, renderer, _ = _build(name, rt, (size, size))
            rs.update()
            by_ls = {}
            fuse = {"both": (False, True), "on": (True,), "off": (False,)}[args.fuse]
            variants = [(ls, f) for f in fuse for ls in args.local_sizes]
            for ls, f in variants:  # the same scene, each work-group size and fusion
                r_ls = renderer if (ls, f) == (renderer.settings.local_size, False) else \
                    _with_local_size(rt, rs, renderer, ls, f)
                r_ls.enqueue_frame(update_scene=False)
                rt.finish()
                enq: list[float] = []
                by_ls[(ls, f)] = (*_frame_times(rt, r_ls, args.repeats, args.warmup, enq),
                                  r_ls, statistics.median(enq))
            best = min(by_ls, key=lambda k: by_ls[k][1])
            stages, wall, renderer, enqueue = by_ls[best]
            stats = renderer.read_stats()
            fb = renderer.read_framebuffer()
            if not np.isfinite(fb).all():
                raise RuntimeError(f"bench render: {name} {size}: non-finite pixels")
            if stats["dropped"]:
                raise RuntimeError(f"bench render: {name} {size}: {stats['dropped']} rays "
                                   "dropped (wavefront full)")
            seed = SEED_MS[name][0 if size == 512 else 1] if size in (512, 1024) else None
            gpu_total = sum(stages.values())
            row = {"scene": name, "size": size, "triangles": rs.n_triangles,
                   "bounces": renderer.settings.bounces, "levels": stats["levels"],
                   "local_size": best[0], "fuse_trace_shade": best[1],
                   "wall_ms_by_variant": {f"ls{k[0]}{'_fused' if k[1] else ''}": round(v[1], 4)
                                          for k, v in by_ls.items()}}
            for col, names in COLUMNS.items():
                row[f"{col}_ms"] = round(sum(stages.get(n, 0.0) for n in names), 4)
            row |= {"kernel_total_ms": round(gpu_total, 4), "wall_ms": round(wall, 4),
                    "enqueue_ms": round(enqueue, 4), "fps": round(1000 / wall, 1),
                    "primary_rays": size * size,
                    "secondary_rays": stats["secondary_rays"],
                    "rays_per_depth": " ".join(map(str, stats["rays_per_depth"])),
                    "seed_ms": seed, "seed_fps": round(1000 / seed, 1) if seed else None,
                    "speedup_fps": round(seed / wall, 1) if seed else None,
                    "bytes_per_ray_slot": renderer.memory_report()["bytes_per_ray_slot"],
                    "bytes_per_triangle": round(rs.bytes_per_triangle()["total"], 1)}
            row |= check
            row["stages_ms"] = {k: round(v, 4) for k, v in sorted(stages.items())}
            rows.append(row)
            print(summary_line(row), flush=True)
            _write(out, rt, check_rt, date, args, rows, [])
    conv = _convergence(rt, args) if args.convergence_scene else []
    _write(out, rt, check_rt, date, args, rows, conv)
    if conv:
        write_csv(out / "render_convergence.csv", conv)
        _chart(conv, out / "render_convergence.png", rt.name, args.convergence_scene)
    print(f"wrote {out / 'render.json'}, render.csv"
          + (", render_convergence.csv/.png" if conv else ""))
    return 0


def summary_line(row: dict) -> str:
    """One readable line per timed scene and size: frame time, FPS, the seed's time and our
    speed-up where the seed has one, the work-group chosen and the slowest stages."""
    seed = (f"seed {row['seed_ms']:.1f} ms, {row['speedup_fps']:.1f}x faster"
            if row.get("seed_ms") else "no seed number at this size")
    stages = sorted(row["stages_ms"].items(), key=lambda kv: -kv[1])
    top = ", ".join(f"{k.removeprefix('render.')} {v:.3f}" for k, v in stages[:4])
    return (f"{row['scene']:7s} {row['size']:5d}^2: {row['wall_ms']:8.3f} ms/frame "
            f"({row['fps']:.1f} FPS), kernels {row['kernel_total_ms']:.3f} ms, "
            f"{row['secondary_rays']} secondary rays; {seed}; work-group {row['local_size']}"
            f"{' fused' if row['fuse_trace_shade'] else ''}; slowest stages (ms): {top}")


def _write(out: Path, rt, check_rt, date: str, args, rows: list, conv: list) -> None:
    """render.json and render.csv (rewritten after every row, so a cut-off run keeps its rows)."""
    from app.io import write_csv, write_json

    meta = {"device": rt.name, "date": date, "check_device": check_rt.name if check_rt else None,
            "repeats": args.repeats, "warmup": args.warmup,
            "seed_bytes_per_ray": SEED_BYTES_PER_RAY}
    write_json(out / "render.json", {"meta": meta, "scenes": rows, "convergence": conv})
    write_csv(out / "render.csv", [{k: v for k, v in r.items()
                                    if k not in ("stages_ms", "wall_ms_by_variant")}
                                   for r in rows])


def _convergence(rt, args) -> list[dict]:
    """RMSE (linear radiance) and PSNR (8-bit) against a high-spp jittered render, with time."""
    w, h = args.convergence_size
    _, ref, _ = _build(args.convergence_scene, rt, (w, h), spp=args.reference_spp)
    ref.render()
    ref_fb = ref.read_framebuffer().astype(np.float64)
    ref_img = ref.read_rgba()[..., :3].astype(np.float64)
    del ref
    rows = []
    for spp in args.spp:
        rs, r, _ = _build(args.convergence_scene, rt, (w, h), spp=spp)
        rs.update()
        img = r.render()
        rt.finish()
        rt.timer.collect()
        stages, wall = _frame_times(rt, r, max(3, args.repeats // 2), 1)
        fb = r.read_framebuffer().astype(np.float64)
        rmse = float(np.sqrt(np.mean((fb - ref_fb) ** 2)))
        mse8 = float(np.mean((img[..., :3].astype(np.float64) - ref_img) ** 2))
        psnr = float(10 * np.log10(255.0**2 / mse8)) if mse8 > 0 else float("inf")
        rows.append({"scene": args.convergence_scene, "width": w, "height": h, "spp": spp,
                     "reference_spp": args.reference_spp, "rmse_linear": rmse,
                     "psnr_8bit_db": round(psnr, 3), "wall_ms": round(wall, 4),
                     "kernel_ms": round(sum(stages.values()), 4)})
        print(f"convergence spp {spp:4d}: rmse {rmse:.5f}  psnr {psnr:6.2f} dB  "
              f"{wall:.3f} ms", flush=True)
    return rows


def _chart(rows: list[dict], path: Path, device: str, scene: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from app.io import atomic_path

    fig, ax = plt.subplots(figsize=(6, 4))
    t = [r["wall_ms"] for r in rows]
    e = [r["rmse_linear"] for r in rows]
    ax.loglog(t, e, "o-")
    for r in rows:
        ax.annotate(f"{r['spp']} spp", (r["wall_ms"], r["rmse_linear"]), fontsize=8,
                    xytext=(4, 4), textcoords="offset points")
    ax.set_xlabel("frame time (ms)")
    ax.set_ylabel(f"RMSE vs {rows[0]['reference_spp']} spp (linear radiance)")
    ax.set_title(f"{scene} {rows[0]['width']}x{rows[0]['height']}: error vs time ({device})",
                 fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    plt.close(fig)
