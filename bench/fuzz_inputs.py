"""The long fuzz run (issue 14): scene files through ``lbwater render`` (in-process, stopped
before any device work), mesh files through the loader, and the Python API of the solver and the
ray query, with the properties of tests/app/fuzz_cases.py. The CI runs the same properties on a
short fixed profile (tests/app/test_fuzz.py).

    PYTHONPATH=. python bench/fuzz_inputs.py --scenes 10000 --meshes 2000 --rays 500 \\
        --solvers 300 --out out/fuzz.json

Prints the outcome counts (inputs refused with one line vs accepted) per target and exits 1 on
the first input that breaks a property (Hypothesis prints it, shrunk).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
os.environ.setdefault("POCL_AFFINITY", "0")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", type=int, default=10000)
    p.add_argument("--meshes", type=int, default=2000)
    p.add_argument("--rays", type=int, default=500)
    p.add_argument("--solvers", type=int, default=300)
    p.add_argument("--seed", type=int, default=None, help="Hypothesis seed (default: random)")
    p.add_argument("--out", default="out/fuzz.json")
    args = p.parse_args()

    from hypothesis import HealthCheck, given, seed, settings

    from kernels import get_runtime
    from tests.app import fuzz_cases as fz

    rt = get_runtime()
    run_seed = args.seed if args.seed is not None else int.from_bytes(os.urandom(4), "little")
    rows = []

    def run(name, n, strategy, check):
        counts: collections.Counter = collections.Counter()

        @seed(run_seed)
        @settings(max_examples=n, deadline=None, database=None,
                  suppress_health_check=list(HealthCheck))
        @given(case=strategy)
        def prop(case):
            counts[check(case)] += 1

        t0 = time.perf_counter()
        prop()
        row = {"target": name, "examples": sum(counts.values()), **dict(counts),
               "seconds": round(time.perf_counter() - t0, 1)}
        rows.append(row)
        print(json.dumps(row), flush=True)

    def scene(case):
        with fz.workdir() as d:
            return fz.check_scene_cli(case[0], [w for pair in case[1] for w in pair], d)

    def mesh(case):
        with fz.workdir() as d:
            return fz.check_mesh_file(*case, d)

    from hypothesis import strategies as st

    try:
        run("scene files (lbwater render)", args.scenes, st.tuples(fz.scene_texts(),
                                                                  fz.RENDER_ARGS), scene)
        run("mesh files (OBJ, PLY, STL)", args.meshes, fz.mesh_files, mesh)
        run("raytrace.intersect", args.rays, fz.arrays_for_rays(),
            lambda c: fz.check_intersect(*c, rt))
        run("lbm.ShallowWater", args.solvers, fz.solver_calls(),
            lambda c: fz.check_solver(*c, rt))
    finally:
        from app.io import write_json

        write_json(args.out, {"date": time.strftime("%Y-%m-%d"), "seed": run_seed,
                              "device": rt.name, "host": platform.node(),
                              "command": " ".join(sys.argv), "rows": rows})
        print(f"seed {run_seed}; wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
