"""Long runs (issue 14): what holds after many steps and frames, measured.

``volume``: 1e5 LBM steps of a closed pool (walls on every side, no rain, no drag; ``--bed``
adds a bump on the bed) that starts with drops on still water; the total volume must stay
within ``--tolerance`` (1e-6) of the start, and the guard must never act. Exit status 1 when
either fails. The volume is read three ways: the guard's device reduction every ``--chunk``
steps (a compensated float32 sum: the exact total rounded, so 0 drift reads 0), and every
``--check-every`` steps a float64 sum of the depths read back (``fields()``) and the exact
float64 sum of the stored populations (what the state holds; with float32 storage they are
multiples of a quantum and conserved to the bit, kernels/lbm.h lbm_quantize; before that fix
slip walls drifted 1.9e-6 in 1e5 steps, all three agreeing, so it was real, not measurement).

``frames``: 1e4 frames of the pool with rain and a boat through the World's frame API
(docs/frame_api.md: ``World(scene).frame(1/60)`` and ``world.stats``): host RSS and device memory
must stay flat after a warm-up and the volume budget (initial + rain - clipped + created ==
volume, from every frame's stats) must close within ``--budget-tolerance`` relative.

    PYTHONPATH=. python bench/long_runs.py volume --steps 100000 --cells 64 48 --out out/long
    PYTHONPATH=. python bench/long_runs.py volume --cells 1024 768 --boundary slip --bed
    PYTHONPATH=. python bench/long_runs.py frames --frames 10000 --out out/long
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("POCL_AFFINITY", "0")


def _stored(sim) -> float:
    """The exact volume the state holds (m^3): a float64 sum of the stored populations."""
    return float(sim.populations().astype(np.float64).sum()) * sim.dx**2


def volume_run(nx: int = 64, ny: int = 48, steps: int = 100_000, chunk: int = 1000,
               check_every: int = 10_000, boundary: str = "slip", device=None,
               log=None, bed: bool = False, storage: str = "fp32") -> dict:
    """Run a closed pool for ``steps`` steps; return the drift record (see the module doc)."""
    import lbm
    from kernels import get_runtime

    rt = get_runtime(device)
    dx = 0.02
    sim = lbm.ShallowWater(nx, ny, dx, boundary=boundary, device=rt, depth=0.3,
                           viscosity=1e-4, expected_speed=0.3, storage=storage)
    width, height = nx * dx, ny * dx
    if bed:   # a bump of 5 cm under the middle: the bed force in every step
        jj, ii = np.mgrid[0:ny, 0:nx]
        z = 0.05 * np.exp(-(((ii + 0.5) / nx - 0.5) ** 2 + ((jj + 0.5) / ny - 0.5) ** 2) / 0.02)
        sim.set_state(0.3 - z, bed=z)
    for fx, fy, r, h in ((0.25, 0.3, 0.1, 0.03), (0.7, 0.6, 0.08, -0.02), (0.5, 0.2, 0.05, 0.02)):
        sim.add_drop(fx * width, fy * height, r, h)   # waves that reach every wall
    s0 = sim.stats()
    host0 = float(sim.fields()["h"].astype(np.float64).sum()) * dx * dx
    stored0 = _stored(sim)
    m0 = s0["mass"]
    worst_dev, worst_host, worst_stored, acted, checks = 0.0, 0.0, 0.0, [], []
    t0 = time.perf_counter()
    done = 0
    while done < steps:
        n = min(chunk, steps - done)
        sim.step(n)
        done += n
        s = sim.stats()
        worst_dev = max(worst_dev, abs(s["mass"] - m0) / m0)
        if s["report"] != "ok":
            acted.append(f"step {done}: {s['report']}")
        if done % check_every == 0 or done == steps:
            host = float(sim.fields()["h"].astype(np.float64).sum()) * dx * dx
            drift = abs(host - host0) / host0
            stored = abs(_stored(sim) - stored0) / stored0
            worst_host = max(worst_host, drift)
            worst_stored = max(worst_stored, stored)
            checks.append({"step": done, "device_drift": abs(s["mass"] - m0) / m0,
                           "host_drift": drift, "stored_drift": stored,
                           "max_froude": s["max_froude"]})
            if log:
                log(f"step {done}: volume drift device {checks[-1]['device_drift']:.2e}, "
                    f"host float64 {drift:.2e}, stored {stored:.2e}, "
                    f"max Fr {s['max_froude']:.3g}")
    return {"part": "volume", "device": rt.name, "cells": [nx, ny], "boundary": boundary,
            "bed": bed, "storage": storage, "steps": steps, "dt": sim.dt,
            "simulated_s": sim.time, "seconds": round(time.perf_counter() - t0, 1),
            "volume_m3": host0, "max_drift_device": worst_dev, "max_drift_host": worst_host,
            "max_drift_stored": worst_stored, "guard_actions": acted, "checks": checks}


def frames_run(scene_path: Path, frames: int, warmup: int, device=None, log=None) -> dict:
    """The pool with rain and a boat for ``frames`` frames of 1/60 s through the frame API."""
    import resource

    from app.scene import load_scene
    from app.world import World

    world = World(load_scene(scene_path), device, width=320, height=180)
    world.set_rain(20.0)
    rss, dev, budget = [], [], []
    acted = 0
    t0 = time.perf_counter()
    for i in range(frames):
        world.frame(1 / 60)
        st = world.stats
        g = st.guard
        acted += bool(g.get("acted"))
        if g.get("nan"):
            return {"part": "frames", "failed": f"frame {i}: non-finite water"}
        if "volume" in g:
            # initial + sources - clipped + created == volume (m^3), relative to the volume
            expected = (g["volume_initial"] + g["volume_sources"] - g["volume_clipped"]
                        + g["volume_created"])
            budget.append(abs(expected - g["volume"]) / g["volume"])
        if i >= warmup and i % 100 == 0:
            rss.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
            dev.append(st.device_bytes)
        if log and i % 1000 == 0:
            log(f"frame {i}: rss {rss[-1] if rss else 0} KiB, device {st.device_bytes} B, "
                f"budget residual {budget[-1] if budget else 0:.2e}")
    last = world.stats.guard
    world.close()
    rss_flat = not rss or rss[-1] - rss[0] <= 0.05 * rss[0] + 20 * 1024   # KiB
    dev_flat = not dev or min(dev) == max(dev)
    out = {"part": "frames", "frames": frames, "seconds": round(time.perf_counter() - t0, 1),
           "rss_kib_first_last": [rss[0], rss[-1]] if rss else None,
           "device_bytes_min_max": [min(dev), max(dev)] if dev else None,
           "frames_guard_acted": acted,
           "volume_m3": {k: last.get(k) for k in ("volume_initial", "volume_sources",
                                                    "volume_clipped", "volume_created",
                                                    "volume")},
           "budget_max_relative_residual": max(budget) if budget else None,
           "rss_flat": rss_flat, "device_memory_flat": dev_flat}
    if not (rss_flat and dev_flat):
        out["failed"] = "host RSS or device memory grew"
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="part", required=True)
    v = sub.add_parser("volume")
    v.add_argument("--steps", type=int, default=100_000)
    v.add_argument("--cells", type=int, nargs=2, default=[64, 48])
    v.add_argument("--boundary", default="slip", choices=["slip", "noslip"])
    v.add_argument("--bed", action="store_true", help="a bump on the bed (the bed force)")
    v.add_argument("--storage", default="fp32", choices=["fp32", "fp16s"])
    v.add_argument("--chunk", type=int, default=1000, help="steps between device reads")
    v.add_argument("--check-every", type=int, default=10_000)
    v.add_argument("--tolerance", type=float, default=1e-6)
    f = sub.add_parser("frames")
    f.add_argument("--scene", default=str(ROOT / "scenes" / "pool.toml"))
    f.add_argument("--frames", type=int, default=10_000)
    f.add_argument("--warmup", type=int, default=200)
    f.add_argument("--budget-tolerance", type=float, default=1e-5)
    for q in (v, f):
        q.add_argument("--device")
        q.add_argument("--out", default="out/long")
    args = p.parse_args()

    from app.io import check_output_dir, write_json

    out = check_output_dir(args.out, "--out")

    def log(msg) -> None:
        print(msg, file=sys.stderr, flush=True)

    meta = {"date": time.strftime("%Y-%m-%d"), "host": platform.node(),
            "command": " ".join(sys.argv)}
    if args.part == "volume":
        r = volume_run(*args.cells, steps=args.steps, chunk=args.chunk,
                       check_every=args.check_every, boundary=args.boundary,
                       device=args.device, log=log, bed=args.bed, storage=args.storage)
        r["tolerance"] = args.tolerance
        r["ok"] = (max(r["max_drift_device"], r["max_drift_host"], r["max_drift_stored"])
                   <= args.tolerance and not r["guard_actions"])
    else:
        r = frames_run(Path(args.scene), args.frames, args.warmup, args.device, log)
        r["budget_tolerance"] = args.budget_tolerance
        if (r.get("budget_max_relative_residual") or 0.0) > args.budget_tolerance:
            r.setdefault("failed", "the volume budget did not close")
        r["ok"] = "failed" not in r
    write_json(out / f"long_{args.part}.json", {**meta, **r})
    log({k: v for k, v in r.items() if k != "checks"})
    return 0 if r["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
