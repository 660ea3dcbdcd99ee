"""The bodies stage alone: the pool scene's water at ``--cells`` with N copies of its boat (as
``lbwater bench frame --boats N``), frames of 1/60 s of water, no rendering. Per frame (median
after warm-up): ``lbm.bodies`` ms (one launch per update: the bodies and their pressure
pass), bodies updates and launches per frame, work-groups per boat, water steps per frame;
``--groups`` sweeps the work-groups per boat (0: ``Boats.groups_per_boat``'s choice; 1: one
group per boat, the previous design); ``--every-step`` adds rows at the old cadence (an update
after every water step) for comparison. Prints one line per row and writes
DIR/bodies_stage.json.

    python3 bench/bodies_stage.py --cells 1024 --boats 1 16 --frames 60 --out DIR
    python3 bench/bodies_stage.py --cells 1024 --boats 1 16 --groups 0 1 4 8 16 32 --out DIR
    python3 bench/bodies_stage.py --cells 1024 --boats 1 16 --press-batch 1 2 4 8 --out DIR
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def measure(rt, scene, cells: int, n_boats: int, frames: int, warmup: int,
            every_step: bool, groups: int = 0, work_group: int = 512,
            press_batch: int = 4) -> dict:
    import lbm
    from app.assemble import water_spec
    from app.bench_frame import with_boats
    from app.boats import boat_bodies, make_boats

    sc = with_boats(scene, n_boats)
    water = water_spec(sc, cells)
    sim = lbm.from_water_spec(water, device=rt)
    bodies = boat_bodies(sc)
    boats = make_boats(sc, sim, bodies, rt.buffer(48 * len(bodies)), list(range(len(bodies))),
                       work_group=work_group, press_batch=press_batch)
    if every_step:
        boats.max_substep = sim.dt * (1 + 1e-6)
    if groups > 0:
        boats.press_groups = groups
    per_frame = max(1, round((1 / 60) / sim.dt))
    rows = []
    for i in range(warmup + frames):
        rt.timer.collect()
        sim.step(per_frame)
        rt.queue.finish()
        ms = rt.timer.collect()
        if i >= warmup:
            rows.append(ms)
    bodies_ms = statistics.median(r.get("lbm.bodies", 0.0) for r in rows)
    updates = per_frame / boats.every
    groups = boats.groups_per_boat(boats.every * sim.dt)
    boats.close()
    return {"device": rt.name, "cells": f"{sim.nx}x{sim.ny}", "boats": n_boats,
            "cadence": "every step" if every_step else f"every {boats.every} steps",
            "water_steps_per_frame": per_frame, "updates_per_frame": round(updates, 2),
            "launches_per_frame": round(updates, 2), "groups_per_boat": groups,
            "work_group": work_group, "press_batch": press_batch,
            "bodies_ms": round(bodies_ms, 4),
            "ms_per_launch": round(bodies_ms / updates, 4),
            "lbm_step_ms": round(statistics.median(r.get("lbm.step", 0.0) for r in rows), 4)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=str(ROOT / "scenes" / "pool.toml"))
    p.add_argument("--cells", type=int, default=1024)
    p.add_argument("--boats", type=int, nargs="+", default=[1, 16])
    p.add_argument("--frames", type=int, default=60)
    p.add_argument("--warmup", type=int, default=10)
    p.add_argument("--groups", type=int, nargs="+", default=[0],
                   help="work-groups per boat (0: the default choice)")
    p.add_argument("--work-group", type=int, nargs="+", default=[512],
                   help="work-items per work-group of the update (128, 256, 512, 1024)")
    p.add_argument("--every-step", action="store_true",
                   help="also time an update after every water step (the old cadence)")
    p.add_argument("--press-batch", type=int, nargs="+", default=[4],
                   help="cells per work-item per step of the pressure pass (1, 2, 4, 8)")
    p.add_argument("--device", default=None)
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    from app.scene import load_scene
    from kernels import get_runtime

    rt = get_runtime(args.device)
    scene = load_scene(args.scene)
    out = []
    for n in args.boats:
        for every_step in ((False, True) if args.every_step else (False,)):
            for g, wg, pb in ((g, wg, pb) for g in args.groups for wg in args.work_group
                              for pb in args.press_batch):
                row = measure(rt, scene, args.cells, n, args.frames, args.warmup, every_step, g,
                              wg, pb)
                out.append(row)
                print(f"{row['cells']} {n:2d} boats, {row['cadence']}, {row['groups_per_boat']}"
                      f" groups/boat of {wg}, press batch {pb}: bodies "
                      f"{row['bodies_ms']:.4f} ms/frame "
                      f"({row['ms_per_launch']:.4f} per launch), "
                      f"{row['launches_per_frame']} launches/frame, lbm.step "
                      f"{row['lbm_step_ms']:.3f} ms", flush=True)
    d = Path(args.out)
    d.mkdir(parents=True, exist_ok=True)
    (d / "bodies_stage.json").write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
