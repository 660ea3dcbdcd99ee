"""Our closest-hit trace against Embree (embreex, one thread), interleaved run by run.

The height-field grid and the two ray sets of ``lbwater bench bvh`` (Warp's anchor workload:
primary rays of a 1920x1080 camera and 2^21 incoherent downward rays; ``--rays small``: 480x270 and
2^17), the same rays for both tracers. For each ray set, ``--rounds`` rounds each run Embree once
and then ours once (``app.bench_bvh.embree_rate`` with ``ours=``), so both sides of a round see the
same load on a shared host. Printed as JSON: per ray set the median rate of each (Mrays/s, wall
clock), the ratio of the medians, the median of the per-round ratios, the rates per second of
process CPU time (all of PoCL's threads; on a shared host less sensitive to other jobs than the
wall clock), and the fraction of rays whose hit triangle is the same in both (exit status 1 below
0.999).

    python bench/ab_embree_interleaved.py [--n 301] [--rounds 9] [--rays full|small] [--device SPEC]
"""

from __future__ import annotations

import argparse
import datetime
import json
import statistics
import sys
import time

import numpy as np

MIN_SAME_HITS = 0.999


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=301, help="grid vertices per side")
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--rays", choices=("full", "small"), default="full")
    ap.add_argument("--local-size", type=int, default=64, help="work-group of the trace kernel")
    ap.add_argument("--device", help="device spec (default: LBWATER_DEVICE or the default)")
    args = ap.parse_args(argv)
    if args.n < 2 or args.rounds < 1:
        ap.error("--n must be >= 2 and --rounds >= 1")

    from app.bench_bvh import embree_rate, rays_incoherent, rays_primary
    from app.meshes import height_field_grid
    from kernels import get_runtime
    from raytrace import RayQuery, Scene
    from raytrace.bvh import HIT_DTYPE
    from raytrace.query import pack_rays

    rt = get_runtime(args.device)
    w, h, n_inc = (1920, 1080, 1 << 21) if args.rays == "full" else (480, 270, 1 << 17)
    rays = {"primary": rays_primary(w, h),
            "incoherent": rays_incoherent(n_inc, np.random.default_rng(1))}
    vertices, triangles = height_field_grid(args.n)
    scene = Scene(rt, stage="ab.bvh")
    scene.add_instance(scene.add_mesh(vertices, triangles))
    scene.update()
    rt.finish()
    out = {"command": " ".join(["python", "bench/ab_embree_interleaved.py",
                                *(argv if argv is not None else sys.argv[1:])]),
           "device": rt.name, "date": datetime.date.today().isoformat(), "grid": args.n - 1,
           "tris": len(triangles), "layout": scene.layout, "rounds": args.rounds}
    ok = True
    for kind, (o, d) in rays.items():
        ro, rd = pack_rays(o, d, 0.0, 1e6)
        hits = rt.buffer(HIT_DTYPE.itemsize * len(o))
        q = RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits, len(o), stage="ab.trace")
        q.enqueue(args.local_size)   # warm-up
        rt.finish()
        ours_s, ours_cpu = [], []

        def ours(q=q, ours_s=ours_s, ours_cpu=ours_cpu):
            t0, c0 = time.perf_counter(), time.process_time()
            q.enqueue(args.local_size)
            rt.finish()
            ours_s.append(time.perf_counter() - t0)
            ours_cpu.append(time.process_time() - c0)

        emb = embree_rate(vertices, triangles, o, d, args.rounds, ours=ours)
        rt.timer.collect()
        if emb is None:
            print("embreex is not installed", file=sys.stderr)
            return 2
        ours_rate = len(o) / statistics.median(ours_s) / 1e6
        same = float(np.mean(rt.to_host(hits, HIT_DTYPE, len(o))["prim"] == emb["prim"]))
        ok &= same >= MIN_SAME_HITS
        out[kind] = {"rays": len(o), "ours_Mrays_s": round(ours_rate, 3),
                     "embree_1t_Mrays_s": round(emb["Mrays_s"], 3),
                     "ratio_of_medians": round(ours_rate / emb["Mrays_s"], 3),
                     "median_paired_ratio": round(emb["paired_ratio"], 3),
                     "ours_Mrays_per_cpu_s": round(len(o) / statistics.median(ours_cpu) / 1e6, 3),
                     "embree_1t_Mrays_per_cpu_s": round(emb["Mrays_per_cpu_s"], 3),
                     "same_hit_fraction": same}
    print(json.dumps(out, indent=1))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
