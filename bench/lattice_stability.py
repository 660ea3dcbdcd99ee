"""Where BGK LABSWE on D2Q9 goes unstable: limiter clamps over a grid of g h/e^2 and tau.

A slip box of n x n cells holds a lake of ``--depth`` m with a Gaussian depression of ``--dip`` x
depth (sigma ``--sigma`` cells) in its middle (and, with ``--noise``, uniform random depth noise of
that amplitude x depth), released at rest and run for ``--seconds`` of water. For each ratio g
H/e^2 (H the lake depth) the lattice speed is forced, ``lattice_speed = sqrt(g H / ratio)``, and
for each tau the viscosity is set to give it, ``nu = (tau - 1/2) e dx / 3`` (lbm/lattice.py). A
cell of the table is the number of cell updates the limiter clamped
(``ShallowWater.stats()["clamped"]``): 0 means the run stayed inside the limits. The guard may
raise tau after clamps and restore a checkpoint after a non-finite state; both are counted in the
CSV.

Two solvers (``--solver``):

* ``device`` (default): the OpenCL solver as built (``lbm.ShallowWater``). Its limiter caps
  g h/e^2 at 0.6 (``lbm.lattice.GH_LIMIT``), so a wave crest above the lake is clamped at 0.6
  whatever tau is, and it refuses a lattice speed with g H/e^2 above 0.6 ("refused").
* ``reference``: the float64 NumPy model ``lbm.reference`` (stream, moments, BGK) with the
  limiter's other rules (depth floor, |u|/e and Froude caps, f0_eq >= 0) but *without* the depth
  cap and without the guard: the scheme as it was before the cap, which is where the cap of 0.6
  comes from. A run that turns non-finite stops and is reported as "nan".

    python bench/lattice_stability.py --out out/lattice_stability.csv [--device SPEC]
    python bench/lattice_stability.py --solver reference --ratios 0.5,0.58,0.6,0.62,0.64

Writes the CSV (one row per run) and prints the markdown table.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time

import numpy as np


def _floats(text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: not a list of numbers") from None


G = 9.81  # m/s^2


def initial_depth(args) -> np.ndarray:
    """The lake with its Gaussian depression and noise, (n, n) in metres."""
    c = (np.arange(args.n) + 0.5 - args.n / 2) / args.sigma
    r2 = c[None, :] ** 2 + c[:, None] ** 2
    noise = np.random.default_rng(args.seed).uniform(-1.0, 1.0, (args.n, args.n))
    return args.depth * (1.0 - args.dip * np.exp(-0.5 * r2) + args.noise * noise)


def run_device(rt, ratio: float, tau: float, args) -> dict:
    """One run of the OpenCL solver: what the limiter and the guard did, or ``refused``."""
    import lbm

    depth, n, dx = args.depth, args.n, args.dx
    e = math.sqrt(G * depth / ratio)
    row = {"ratio": ratio, "tau": tau, "e": e}
    try:
        sim = lbm.ShallowWater(n, n, dx, "slip", device=rt, gravity=G, depth=depth,
                               lattice_speed=e, viscosity=(tau - 0.5) * e * dx / 3.0)
    except ValueError as exc:
        return {**row, "refused": str(exc)}
    sim.set_state(initial_depth(args))
    mass0 = sim.stats()["mass"]
    steps = round(args.seconds / sim.dt)
    t0 = time.perf_counter()
    sim.step(steps)
    s = sim.stats()
    return {**row, "tau_set": sim.tau, "dt": sim.dt, "steps": steps, "clamped": s["clamped"],
            "restored": s["restored"], "damped": s["damped"], "tau_end": s["tau"],
            "max_speed_ratio": s["max_speed_ratio"], "mass_drift": s["mass"] / mass0 - 1.0,
            "seconds_wall": time.perf_counter() - t0, "refused": ""}


def _limit_uncapped(h, u, v, *, e, h_min, u_ratio_max=0.5, froude_max=1.0):
    """The kernel limiter's rules (lbm.reference.limit) without the depth cap g h/e^2 <= 0.6."""
    from lbm.reference import F0_LIMIT

    hit = h < h_min
    h = np.where(hit, h_min, h)
    s2 = u * u + v * v
    cap = np.minimum((u_ratio_max * e) ** 2, froude_max**2 * G * h)
    fast = s2 > cap
    scale = np.where(fast, np.sqrt(cap / np.where(fast, s2, 1.0)), 1.0)
    u, v = u * scale, v * scale
    s2 = u * u + v * v
    deep = 5 * G * h / (6 * e * e) + 2 * s2 / (3 * e * e) > F0_LIMIT
    h = np.where(deep, (F0_LIMIT - 2 * s2 / (3 * e * e)) * 6 * e * e / (5 * G), h)
    return h, u, v, hit | fast | deep


def run_reference(ratio: float, tau: float, args) -> dict:
    """One run of the float64 reference without the depth cap and without the guard."""
    from lbm import reference as ref

    e = math.sqrt(G * args.depth / ratio)
    dt = args.dx / e
    steps = round(args.seconds / dt)
    h = initial_depth(args)
    bed = np.zeros_like(h)
    zero = np.zeros_like(h)
    f = ref.feq_si(h, zero, zero, G, e)
    mass0 = h.sum()
    clamped, nan = 0, False
    t0 = time.perf_counter()
    for _ in range(steps):
        f = ref.stream(f, h, bed, "slip", G, e, with_bed=False)
        h, u, v = ref.macro(f, e)
        if not np.all(np.isfinite(h)):
            nan = True
            break
        h, u, v, hit = _limit_uncapped(h, u, v, e=e, h_min=0.01 * args.depth)
        feq = ref.feq_si(h, u, v, G, e)
        f = f - (f - feq) / tau
        f[:, hit] = feq[:, hit]
        clamped += int(hit.sum())
    h, u, v = ref.macro(f, e)
    return {"ratio": ratio, "tau": tau, "e": e, "tau_set": tau, "dt": dt, "steps": steps,
            "clamped": clamped, "nan": nan,
            "max_speed_ratio": float(np.sqrt((u * u + v * v).max()) / e),
            "mass_drift": f.sum() / mass0 - 1.0, "seconds_wall": time.perf_counter() - t0,
            "refused": ""}


def table(rows: list[dict], ratios: list[float], taus: list[float]) -> str:
    cell = {(r["ratio"], r["tau"]): r for r in rows}
    out = ["| g h/e^2 \\ tau | " + " | ".join(f"{t:g}" for t in taus) + " |",
           "|---" * (len(taus) + 1) + "|"]
    for q in ratios:
        vals = []
        for t in taus:
            r = cell[(q, t)]
            vals.append("refused" if r["refused"] else
                        f"{r['clamped']}" + (" (nan)" if r.get("nan") else ""))
        out.append(f"| {q:.2f} | " + " | ".join(vals) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--solver", choices=("device", "reference"), default="device",
                    help="device: the OpenCL solver as built; reference: float64 NumPy without "
                    "the limiter's depth cap")
    ap.add_argument("--ratios", type=_floats, default=_floats("0.5,0.55,0.58,0.6"),
                    help="g H/e^2 values (comma-separated)")
    ap.add_argument("--taus", type=_floats, default=_floats("0.505,0.51,0.52,0.55,0.6,0.8"))
    ap.add_argument("--n", type=int, default=48, help="cells per side")
    ap.add_argument("--dx", type=float, default=0.02, help="cell size, m")
    ap.add_argument("--depth", type=float, default=1.0, help="lake depth H, m")
    ap.add_argument("--dip", type=float, default=0.05, help="depression depth / H")
    ap.add_argument("--sigma", type=float, default=6.0, help="depression width, cells")
    ap.add_argument("--noise", type=float, default=0.0,
                    help="uniform depth noise amplitude / H (seeded by --seed)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=2.0, help="simulated time, s")
    ap.add_argument("--device", help="device spec (default: LBWATER_DEVICE or the default)")
    ap.add_argument("--out", help="CSV path (one row per run)")
    args = ap.parse_args(argv)
    if args.n < 3 or min(args.dx, args.depth, args.sigma, args.seconds) <= 0:
        ap.error("--n must be >= 3 and --dx, --depth, --sigma, --seconds > 0")
    if min(args.ratios, default=0) <= 0 or min(args.taus, default=0) <= 0.5:
        ap.error("--ratios must be > 0 and --taus > 0.5 (both non-empty)")
    if not 0 <= args.dip < 1 or not 0 <= args.noise < 1:
        ap.error("--dip and --noise must lie in [0, 1)")

    from app.io import atomic_path
    from kernels import get_runtime

    rt = get_runtime(args.device) if args.solver == "device" else None
    rows = []
    for q in args.ratios:
        for t in args.taus:
            rows.append(run_device(rt, q, t, args) if rt else run_reference(q, t, args))
            print(f"g H/e^2 {q:g} tau {t:g}: "
                  + (rows[-1]["refused"] or f"{rows[-1]['clamped']} clamped, "
                     f"{rows[-1]['steps']} steps"), file=sys.stderr)
    if args.out:
        keys = list(dict.fromkeys(k for r in rows for k in r))
        with atomic_path(args.out) as tmp, open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, keys)
            w.writeheader()
            w.writerows(rows)
    where = rt.name if rt else "float64 reference, no depth cap"
    print(f"{where}: {args.n}^2 slip box, {args.depth:g} m lake, {args.dip:.0%} Gaussian "
          f"depression (sigma {args.sigma:g} cells), noise {args.noise:g} H, dx {args.dx:g} m, "
          f"{args.seconds:g} s of water; limiter clamps (0 = stable)")
    print(table(rows, args.ratios, args.taus))
    return 0


if __name__ == "__main__":
    sys.exit(main())
