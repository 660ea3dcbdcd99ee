"""``lbwater bench lbm``: speed of the fused LBM step against the device's memory bandwidth.

For each grid n x n (``--sizes``), bed kind (``--variants``: flat, bed) and work-group
(``--local-sizes``): ``--repeats`` chains of ``--steps`` fused steps enqueued back to back with no
host sync (after one warm-up chain), timed by OpenCL events. Reported medians:

* ``step_ms``: kernel time per step (the chain's event durations over its steps); ``mlups`` =
  n^2 / step_ms. With ``--steps-per-launch 2`` a launch takes two steps (``lbm_step2``, one read
  and one write of the grid per two steps: ``bytes_per_cell`` counts them once per launch)
* ``chain_ms``: first start to last end of a chain, per step (adds the gaps between launches)
* ``bytes_per_cell`` from first principles: 9 fp32 loads + 9 fp32 stores = 72 B on a flat bed;
  the uneven bed adds the depth at t and the bed (neighbours from cache) and the new depth: 84 B
* ``gbps`` = bytes_per_cell x LUPs; ``of_ceiling`` = gbps / the device copy bandwidth measured in
  the same run (``kernels.bandwidth``, >= 256 MiB); ``of_72B_ceiling`` = LUPs / (copy / 72 B)
* ``guard_ms`` (reduction + checkpoint save, once per frame) and ``surface_ms`` (vertices and
  normals), per call.

Correctness in the same run (the run fails, exit 1, when wrong): each variant and work-group does
one step of a 96 x 64 grid against the float64 reference ``lbm.reference``, and every timed grid
keeps its volume (relative drift <= 1e-5) with a clean guard report.

Defaults suit the device: on a GPU grids 256^2..4096^2, 100 steps x 5 chains and a 256 MiB copy;
on a CPU grids 64^2..256^2, 20 steps x 3 chains and a 64 MiB copy (about a minute on 2 cores).
Each row is printed and lbm.json / lbm.csv are rewritten as it finishes, so an interrupted run
keeps what it measured.

    lbwater bench lbm --sizes 256,512,1024 --steps 50 --repeats 5 --out out/bench
"""

from __future__ import annotations

import datetime
import platform
import sys
import time

import numpy as np

BYTES_PER_CELL = {"flat": 72, "bed": 84}
CHECK_TOL = 5e-6

#: Defaults by device kind: a GPU run is the record; a CPU run must finish in about a minute.
GPU_DEFAULTS = {"sizes": [256, 512, 1024, 2048, 4096], "steps": 100, "repeats": 5,
                "bandwidth_mib": 256}
CPU_DEFAULTS = {"sizes": [64, 128, 256], "steps": 20, "repeats": 3, "bandwidth_mib": 64}


def _csv(values) -> str:
    return ",".join(str(v) for v in values)


def apply_device_defaults(args, is_gpu: bool) -> None:
    """Fill every option left at None with the GPU's or the CPU's default."""
    defaults = GPU_DEFAULTS if is_gpu else CPU_DEFAULTS
    for key, value in defaults.items():
        if getattr(args, key, None) is None:
            setattr(args, key, value)


def _ls_name(local_size) -> str:
    return "auto" if local_size is None else f"{local_size[0]}x{local_size[1]}"


def _int_list(text: str) -> list[int]:
    import argparse

    try:
        vals = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of integers"
                                         ) from None
    if not vals or any(not 16 <= v <= 32768 for v in vals):
        raise argparse.ArgumentTypeError(f"{text!r}: sizes must be integers in [16, 32768]")
    return vals


def _local_sizes(text: str) -> list[tuple[int, int] | None]:
    import argparse

    out = []
    for item in text.split(","):
        item = item.strip().lower()
        if item in ("auto", "none"):
            out.append(None)
            continue
        try:
            lx, ly = (int(v) for v in item.split("x"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"--local-sizes item {item!r} is not WxH or auto"
                                             ) from None
        if not (1 <= lx <= 1024 and 1 <= ly <= 1024 and lx * ly <= 1024):
            raise argparse.ArgumentTypeError(f"--local-sizes {item!r}: W, H >= 1, W*H <= 1024")
        out.append((lx, ly))
    return out


def _spl_list(text: str) -> list[int]:
    import argparse

    try:
        vals = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        vals = []
    if not vals or any(v not in (1, 2) for v in vals):
        raise argparse.ArgumentTypeError(f"--steps-per-launch {text!r}: a list of 1 and/or 2")
    return vals


def _variants(text: str) -> list[str]:
    import argparse

    vals = [v.strip() for v in text.split(",") if v.strip()]
    bad = [v for v in vals if v not in BYTES_PER_CELL]
    if not vals or bad:
        raise argparse.ArgumentTypeError(f"--variants {text!r}: valid are flat, bed")
    return vals


def _positive(text: str) -> int:
    import argparse

    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 1 <= v <= 100000:
        raise argparse.ArgumentTypeError(f"{v} is out of range; allowed [1, 100000]")
    return v


def add_arguments(p) -> None:
    p.add_argument("--sizes", type=_int_list, default=None,
                   help="grid sizes n (n x n cells), comma-separated (default: GPU "
                        f"{_csv(GPU_DEFAULTS['sizes'])}, CPU {_csv(CPU_DEFAULTS['sizes'])})")
    p.add_argument("--steps", type=_positive, default=None,
                   help=f"steps per timed chain (default: GPU {GPU_DEFAULTS['steps']}, "
                        f"CPU {CPU_DEFAULTS['steps']})")
    p.add_argument("--repeats", type=_positive, default=None,
                   help=f"timed chains, median (default: GPU {GPU_DEFAULTS['repeats']}, "
                        f"CPU {CPU_DEFAULTS['repeats']})")
    p.add_argument("--variants", type=_variants, default=["flat", "bed"],
                   help="flat and/or bed (uneven bed: the bed force and depth buffers)")
    p.add_argument("--local-sizes", type=_local_sizes, default=None,
                   help="work-groups of the step kernel to compare, e.g. 128x1,256x1,32x4,auto "
                        "(default: the solver's choice)")
    p.add_argument("--steps-per-launch", type=_spl_list, default=None,
                   help="steps per launch to compare, e.g. 1,2 (2: lbm_step2, two steps in "
                        "local memory; default: the solver's choice)")
    p.add_argument("--bandwidth-mib", type=_positive, default=None,
                   help="bytes copied by the bandwidth measurement, MiB (>= 256 for the record; "
                        f"default: GPU {GPU_DEFAULTS['bandwidth_mib']}, "
                        f"CPU {CPU_DEFAULTS['bandwidth_mib']})")


def _state(n: int, dx: float, variant: str):
    jj, ii = np.mgrid[0:n, 0:n]
    x, y = (ii + 0.5) / n, (jj + 0.5) / n
    bed = (0.2 * np.exp(-((x - 0.6) ** 2 + (y - 0.4) ** 2) / 0.05) if variant == "bed"
           else np.zeros((n, n)))
    h = 1.0 - bed + 0.02 * np.exp(-((x - 0.3) ** 2 + (y - 0.6) ** 2) / 0.01)
    return h, bed


def check_step(rt, variant: str, local_size) -> float:
    """Max |f_device - f_reference| after one step of a 96 x 64 grid with non-equilibrium
    populations, walls, drag and (variant "bed") the bed force."""
    import lbm
    from lbm import reference as ref

    nx, ny, dx = 96, 64, 0.01
    rng = np.random.default_rng(0)
    sim = lbm.ShallowWater(nx, ny, dx, device=rt, local_size=local_size, drag=1.0,
                           viscosity=1e-4)
    jj, ii = np.mgrid[0:ny, 0:nx]
    bed = 0.1 * rng.random((ny, nx)) if variant == "bed" else np.zeros((ny, nx))
    h = 1.0 - bed + 0.03 * np.sin(ii / 5.0) * np.cos(jj / 7.0)
    u, v = 0.2 * np.sin(jj / 9.0), 0.2 * np.cos(ii / 11.0)
    sim.set_state(h, u, v, bed)
    lat = sim.lattice
    f = ref.feq_si(h, u, v, lat.gravity, lat.e) * (1 + 0.01 * rng.standard_normal((9, ny, nx)))
    sim._load_populations(f)
    f32 = f.astype(np.float32).astype(np.float64)
    want, _, _ = ref.step(f32, f32.sum(0), bed.astype(np.float32), boundary="slip",
                          g=lat.gravity, e=lat.e, tau=lat.tau, drag_dt=lat.drag * lat.dt,
                          h_min=lat.min_depth, u_ratio_max=lat.max_speed_ratio,
                          froude_max=lat.max_froude, with_bed=variant == "bed")
    sim.enqueue_steps(1)
    return float(np.abs(sim.populations() - want).max())


def bench_one(rt, n: int, variant: str, local_size, steps: int, repeats: int,
              steps_per_launch: int | None = None) -> dict:
    import lbm

    dx = 1.0 / n
    sim = lbm.ShallowWater(n, n, dx, device=rt, local_size=local_size,
                           guard_interval=10**9, checkpoint_interval=1,
                           steps_per_launch=steps_per_launch)
    h, bed = _state(n, dx, variant)
    sim.set_state(h, bed=bed)
    m0 = sim.stats()["mass"]
    sim.enqueue_steps(steps)[-1].wait()   # warm-up chain
    rt.timer.collect()
    kernel, span = [], []
    for _ in range(repeats):
        evts = sim.enqueue_steps(steps)
        evts[-1].wait()
        kernel.append(sum(e.profile.end - e.profile.start for e in evts) * 1e-6 / steps)
        span.append((evts[-1].profile.end - evts[0].profile.start) * 1e-6 / steps)
        rt.timer.collect()
    guard, surface = [], []
    verts, norms = rt.buffer(16 * n * n), rt.buffer(16 * n * n)
    for _ in range(repeats + 1):   # the first (warm-up) is dropped
        sim.step(1)                # one step and one guard check (saving a checkpoint)
        sim.stats()
        sim.write_surface(verts, norms).wait()
        t = rt.timer.collect()
        guard.append(t.get("lbm.guard", 0.0))
        surface.append(t.get("lbm.surface", 0.0))
    s = sim.stats()
    step_ms = float(np.median(kernel))
    lups = n * n / (step_ms * 1e-3)
    return {
        "n": n, "cells": n * n, "variant": variant,
        "local_size": _ls_name(local_size), "steps_per_launch": sim.steps_per_launch,
        "steps": steps, "repeats": repeats,
        "step_ms": step_ms, "step_ms_min": float(np.min(kernel)),
        "chain_ms": float(np.median(span)),
        "mlups": lups / 1e6, "chain_mlups": n * n / (float(np.median(span)) * 1e-3) / 1e6,
        "bytes_per_cell": BYTES_PER_CELL[variant] / sim.steps_per_launch,
        "gbps": BYTES_PER_CELL[variant] / sim.steps_per_launch * lups / 1e9,
        "guard_ms": float(np.median(guard[1:])), "surface_ms": float(np.median(surface[1:])),
        "mass_drift": abs(s["mass"] - m0) / m0, "guard_report": s["report"],
        "e": sim.e, "dt": sim.dt, "tau": sim.tau,
    }


def run(args) -> int:
    from pathlib import Path

    from kernels import get_runtime
    from kernels.bandwidth import measure_copy_bandwidth

    rt = get_runtime(args.device)
    apply_device_defaults(args, rt.is_gpu)
    local_sizes = args.local_sizes or [None]
    launches = args.steps_per_launch or [None]
    out = Path(args.out)
    print(f"lbm bench on {rt.name} ({rt.device.platform.name.strip()}): sizes "
          f"{_csv(args.sizes)}, {args.steps} steps x {args.repeats} chains; writing "
          f"{out / 'lbm.json'} as rows finish", file=sys.stderr)
    bw = measure_copy_bandwidth(rt, args.bandwidth_mib << 20)
    copy_gbps = bw["GBps"]
    print(f"copy bandwidth {copy_gbps:.1f} GB/s ({bw['bytes'] >> 20} MiB)", file=sys.stderr)

    checks, failed = [], False
    for variant in args.variants:
        for ls in local_sizes:
            err = check_step(rt, variant, ls)
            ok = err <= CHECK_TOL
            failed |= not ok
            checks.append({"variant": variant, "local_size": _ls_name(ls), "max_abs_error": err,
                           "pass": ok})
            print(f"check {variant} work-group {_ls_name(ls)}: max |f - f_ref| = {err:.2e} "
                  f"{'ok' if ok else 'FAILED'}", file=sys.stderr)

    rows = []
    for n in args.sizes:
        for variant in args.variants:
            for ls, spl in ((ls, spl) for ls in local_sizes for spl in launches):
                t0 = time.perf_counter()
                r = bench_one(rt, n, variant, ls, args.steps, args.repeats, spl)
                r["of_ceiling"] = r["gbps"] / copy_gbps
                r["of_72B_ceiling"] = r["mlups"] * 1e6 / (copy_gbps * 1e9 / 72)
                r["ok"] = r["mass_drift"] <= 1e-5 and r["guard_report"] == "ok"
                failed |= not r["ok"]
                rows.append(r)
                print(f"{n:5d}^2 {variant:4s} {r['local_size']:>7s} x{r['steps_per_launch']}: "
                      f"{r['step_ms']:.4f} ms/step "
                      f"{r['mlups']:9.1f} MLUPs {r['gbps']:7.1f} GB/s "
                      f"{100 * r['of_ceiling']:5.1f}% of copy (72 B: "
                      f"{100 * r['of_72B_ceiling']:5.1f}%), chain {r['chain_ms']:.4f} ms, "
                      f"guard {r['guard_ms']:.3f} ms, surface {r['surface_ms']:.3f} ms "
                      f"[{time.perf_counter() - t0:.1f}s]{'' if r['ok'] else ' FAILED'}",
                      file=sys.stderr)
                _write(out, rt, bw, checks, failed, rows)

    _write(out, rt, bw, checks, failed, rows)
    print(f"wrote {out / 'lbm.json'} and {out / 'lbm.csv'}"
          + (" (FAILED: see the lines above)" if failed else ""), file=sys.stderr)
    return 1 if failed else 0


def _write(out, rt, bw: dict, checks: list, failed: bool, rows: list) -> None:
    """lbm.json and lbm.csv with the rows so far (rewritten after each row)."""
    from app.io import write_csv, write_json

    meta = {
        "bench": "lbm", "date": datetime.date.today().isoformat(),
        "command": "lbwater " + " ".join(sys.argv[1:]) if sys.argv else "",
        "device": rt.name, "platform": rt.device.platform.name.strip(),
        "driver": rt.device.driver_version, "host": platform.node(),
        "copy_bandwidth": bw, "checks": checks, "failed": failed,
    }
    write_json(out / "lbm.json", {**meta, "rows": rows})
    if rows:
        write_csv(out / "lbm.csv", rows)
