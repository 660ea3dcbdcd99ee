"""A/B of the BVH build with 4-bit against 8-bit radix digits, interleaved in one process.

Two binary-layout BLASes over the same device mesh (the height field of ``lbwater bench bvh``,
Warp's anchor grid, 301^2 vertices = 300^2 cells by default) differ only in the digit width of
their Morton-key sort. Each round times ``--builds`` full builds of one, then of the other (the
order swaps every round, so a drift in host load hits both alike). Per build: wall ms from the
first enqueue to ``queue.finish()``, and device ms (the sum of the build's OpenCL event times).
Printed as JSON: the medians over all builds (``--no-profiling``: a queue without profiling, so
wall times only), the per-round medians, and whether the two trees are
the same bit for bit (nodes, leaf triangles, header fields); exit status 1 when they are not.

    python bench/ab_radix_bits.py [--n 301] [--rounds 9] [--builds 20] [--device SPEC]
"""

from __future__ import annotations

import argparse
import datetime
import json
import statistics
import sys
import time

import numpy as np

BITS = (4, 8)


def make_blas(rt, vbuf, tbuf, n_vertices: int, n_tris: int, bits: int):
    """A BLAS whose sort uses ``bits``-bit digits. ``Blas`` picks its sorter from the key count
    and device (``raytrace.sort.default_radix_bits``) and takes no digit width, so the sorter
    is replaced by one over the same key and order buffers with the width forced."""
    from raytrace.bvh import Blas
    from raytrace.sort import RadixSorter

    stage = f"ab.bits{bits}"
    blas = Blas(rt, vbuf, tbuf, n_vertices, n_tris, stage=stage)
    if not hasattr(blas, "_sorter"):
        raise RuntimeError("raytrace.bvh.Blas no longer keeps its sorter in _sorter")
    blas._sorter = RadixSorter(rt, blas.keys, blas.order, n_tris, key_bits=blas.key_bits,
                               radix_bits=bits, stage=sort_stage(bits))
    return blas


def sort_stage(bits: int) -> str:
    return f"ab.bits{bits}.sort{bits}"


def time_builds(rt, blas, builds: int) -> tuple[list[float], list[float]]:
    """Wall and device ms of ``builds`` builds, one at a time."""
    walls, devs = [], []
    for _ in range(builds):
        rt.finish()
        rt.timer.collect()
        t0 = time.perf_counter()
        blas.rebuild()
        rt.finish()
        walls.append((time.perf_counter() - t0) * 1e3)
        devs.append(sum(rt.timer.collect().values()))
    return walls, devs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=301, help="grid vertices per side")
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--builds", type=int, default=20, help="timed builds per variant per round")
    ap.add_argument("--device", help="device spec (default: LBWATER_DEVICE or the default)")
    ap.add_argument("--no-profiling", dest="profiling", action="store_false",
                    help="a queue without profiling (no device times)")
    args = ap.parse_args(argv)
    if args.n < 2 or args.rounds < 1 or args.builds < 1:
        ap.error("--n must be >= 2, --rounds and --builds >= 1")

    from app.meshes import height_field_grid
    from kernels import Runtime, get_runtime
    from raytrace.bvh import vertices_to_float4

    rt = get_runtime(args.device) if args.profiling else Runtime(args.device, profiling=False)
    vertices, triangles = height_field_grid(args.n)
    vbuf = rt.to_device(vertices_to_float4(vertices))
    tbuf = rt.to_device(triangles)
    blases = {b: make_blas(rt, vbuf, tbuf, len(vertices), len(triangles), b) for b in BITS}
    for b, blas in blases.items():   # warm-up: programs built, first touch of every buffer
        blas.rebuild()
        rt.finish()
        if args.profiling and sort_stage(b) not in rt.timer.collect():
            raise RuntimeError(f"the {b}-bit sorter did not run in the build")

    walls = {b: [] for b in BITS}
    devs = {b: [] for b in BITS}
    rounds = {b: [] for b in BITS}
    for r in range(args.rounds):
        for b in BITS if r % 2 == 0 else BITS[::-1]:
            w, d = time_builds(rt, blases[b], args.builds)
            walls[b] += w
            devs[b] += d
            rounds[b].append(round(statistics.median(w), 4))

    trees = {b: blases[b].host_arrays() for b in BITS}
    header = [f for f in trees[4]["info"].dtype.names if f != "pad"]  # pad is never written
    same = (all(trees[4][k].tobytes() == trees[8][k].tobytes() for k in ("nodes", "tris"))
            and all(np.array_equal(trees[4]["info"][f], trees[8]["info"][f]) for f in header))
    out = {
        "command": " ".join(["python", "bench/ab_radix_bits.py", *(argv or sys.argv[1:])]),
        "device": rt.name, "date": datetime.date.today().isoformat(),
        "grid": args.n - 1, "tris": len(triangles), "rounds": args.rounds,
        "builds": args.builds, "profiling": args.profiling, "same_tree": bool(same),
        **{f"bits{b}_passes": -(-blases[b].key_bits // b) for b in BITS},
        **{f"bits{b}_wall_ms": round(statistics.median(walls[b]), 4) for b in BITS},
        **{f"bits{b}_device_ms": round(statistics.median(devs[b]), 4) if args.profiling
           else None for b in BITS},
        **{f"bits{b}_round_wall_ms": rounds[b] for b in BITS},
    }
    print(json.dumps(out, indent=1))
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
