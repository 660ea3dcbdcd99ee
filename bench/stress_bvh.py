"""Stress the device BVH build and refit for races: rebuild and refit a large height-field BVH many
times. Both are deterministic, so every node must come out bit-identical to the first build, whose
boxes are checked to contain their children and triangles. Prints the counts; exits 1 on any
difference. Usage: python bench/stress_bvh.py [GRID_VERTICES_PER_SIDE] [ROUNDS] [--device SPEC]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def main(argv=None) -> int:
    from app.meshes import height_field_grid
    from kernels import get_runtime
    from raytrace import Scene
    from raytrace.bvh import tree_report

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("n", type=int, nargs="?", default=1026)
    ap.add_argument("rounds", type=int, nargs="?", default=30)
    ap.add_argument("--device")
    args = ap.parse_args(argv)
    rt = get_runtime(args.device)
    v, t = height_field_grid(args.n)
    scene = Scene(rt)
    scene.add_instance(scene.add_mesh(v, t))
    scene.update()
    blas = scene.blas(0)
    rt.finish()
    first = blas.host_arrays()
    rep = tree_report(first["nodes"], first["tris"], int(first["info"]["root"]))
    boxes_ok = bool(np.all(rep["child_lo"] >= rep["parent_lo"])
                    and np.all(rep["child_hi"] <= rep["parent_hi"]))
    ref = first["nodes"].view(np.uint8).reshape(len(first["nodes"]), -1)
    bad = {"rebuild": 0, "refit": 0}
    nodes_off = {"rebuild": 0, "refit": 0}
    for _ in range(args.rounds):
        for kind in ("rebuild", "refit"):
            getattr(blas, kind)()
            rt.finish()
            got = blas.host_arrays()["nodes"].view(np.uint8).reshape(ref.shape)
            diff = int((got != ref).any(axis=1).sum())
            bad[kind] += diff > 0
            nodes_off[kind] += diff
    rt.timer.reset()
    print(f"{rt.name}: {len(t)} triangles, first build boxes contain children: {boxes_ok}; "
          f"{args.rounds} rounds: rebuilds differing {bad['rebuild']} ({nodes_off['rebuild']} "
          f"nodes), refits differing {bad['refit']} ({nodes_off['refit']} nodes)")
    return 0 if boxes_ok and not any(bad.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
