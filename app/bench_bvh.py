"""``lbwater bench bvh``: GPU LBVH build, refit and TLAS times and closest-hit ray rates on the
exact workload of NVIDIA Warp's anchor script (reproduced below; BENCHMARKS.md: height-field
grids of n x n vertices, a 1920x1080 camera, 2^21 incoherent downward rays), build times of the
seed's meshes, the device radix sort against ``pyopencl.algorithm.RadixSort``, and (where embreex is
installed) Embree's single-thread ray rate on the same rays. On a CPU device it also times the other
BVH layout (binary beside wide, ``raytrace.bvh_wide``) on the same rays and reports rays per second
of process CPU time (the host may be shared) beside the wall-clock rates.

Times are medians over ``--reps`` after one warm-up: ``*_ms`` wall clock from the first enqueue to
the end of ``queue.finish()`` (as Warp's script measures), ``*_gpu_ms`` the sum of the OpenCL
event times of the stages. Every ray set is checked in the same run against an exact float64
reference on a random subsample (the grid's candidate cells along each ray, brute force); the run
fails (exit status 1) when hits disagree.
"""

from __future__ import annotations

import datetime
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

GRID_SIZES = (301, 1025, 2049)
MESHES = ("dragon_100k.obj", "buddha_100k.obj", "utah_hand_00_handonly.obj")
#: Warp 1.19 on an H100 (BENCHMARKS.md): grid -> (lbvh build, refit, primary SAH,
#: incoherent SAH, primary LBVH, incoherent LBVH) in ms and Mrays/s.
WARP_H100 = {
    301: {"build_ms": 0.36, "refit_ms": 0.089, "primary_sah": 5705, "incoherent_sah": 1227,
          "primary_lbvh": 2893, "incoherent_lbvh": 591},
    1025: {"build_ms": 1.54, "refit_ms": 0.38, "primary_sah": 4178, "incoherent_sah": 784,
           "primary_lbvh": 1641, "incoherent_lbvh": 321},
    2049: {"build_ms": 5.34, "refit_ms": 1.32, "primary_sah": 3106, "incoherent_sah": 637,
           "primary_lbvh": 1188, "incoherent_lbvh": 237},
}
#: Least agreement with the float64 reference that passes the run.
MIN_AGREEMENT = 0.999


# -- the anchor workload (copied from warp_anchor.py so the rays are bit-identical) -------------
def rays_primary(w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    eye = np.array([0, 1.3, -1.6], np.float32)
    look = np.array([0, 0, 0], np.float32)
    fwd = look - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0, 1, 0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    ys, xs = np.mgrid[0:h, 0:w]
    u = (xs + 0.5) / w * 2 - 1
    v = 1 - (ys + 0.5) / h * 2
    fov = np.tan(np.radians(30))
    asp = w / h
    d = (fwd[None] + (u.reshape(-1, 1) * fov * asp) * right[None]
         + (v.reshape(-1, 1) * fov) * up[None])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(eye, d.shape).copy()
    return o.astype(np.float32), d.astype(np.float32)


def rays_incoherent(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    o = np.stack([rng.uniform(-1, 1, n), rng.uniform(0.05, 0.3, n), rng.uniform(-1, 1, n)],
                 -1).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d[:, 1] = -np.abs(d[:, 1])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o, d


# -- exact reference on the grid ----------------------------------------------------------------
def grid_candidates(n: int, lo: np.ndarray, hi: np.ndarray, o: np.ndarray, d: np.ndarray,
                    tmax: float) -> np.ndarray:
    """Every triangle of the n x n grid the ray can touch (conservative): the cells whose centre
    lies within half a cell diagonal of the ray's xz path inside the grid's box [lo, hi]."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0, t1 = (lo - o) * inv, (hi - o) * inv
    tn = np.where(np.isnan(t0), -np.inf, np.minimum(t0, t1))
    tf = np.where(np.isnan(t1), np.inf, np.maximum(t0, t1))
    inside = (d == 0) & (o >= lo) & (o <= hi)
    tn = np.where(d == 0, np.where(inside, -np.inf, np.inf), tn)
    tf = np.where(d == 0, np.where(inside, np.inf, -np.inf), tf)
    a, b = max(tn.max(), 0.0), min(tf.min(), tmax)
    if not a <= b:
        return np.zeros(0, np.int64)
    h = 2.0 / (n - 1)
    p, q = o + a * d, o + b * d
    seg = np.array([[(p[0] + 1) / h, (p[2] + 1) / h], [(q[0] + 1) / h, (q[2] + 1) / h]])
    c0 = np.clip(np.floor(seg.min(0)) - 1, 0, n - 2).astype(int)
    c1 = np.clip(np.ceil(seg.max(0)) + 1, 0, n - 2).astype(int)
    cols, rows = np.meshgrid(np.arange(c0[0], c1[0] + 1), np.arange(c0[1], c1[1] + 1))
    cx, cz = cols.ravel() + 0.5, rows.ravel() + 0.5
    s = seg[1] - seg[0]
    ss = float(s @ s)
    w = np.clip(((cx - seg[0, 0]) * s[0] + (cz - seg[0, 1]) * s[1]) / ss, 0, 1) if ss > 0 else 0
    dist = np.hypot(cx - (seg[0, 0] + w * s[0]), cz - (seg[0, 1] + w * s[1]))
    keep = dist <= 0.7072
    cell = rows.ravel()[keep] * (n - 1) + cols.ravel()[keep]
    return np.concatenate([2 * cell, 2 * cell + 1])


def check_grid_hits(n: int, vertices: np.ndarray, triangles: np.ndarray, o: np.ndarray,
                    d: np.ndarray, hits: np.ndarray, tmax: float, count: int,
                    seed: int = 7) -> dict:
    """Agreement of device hits with the exact float64 reference on ``count`` random rays."""
    from raytrace.query import intersect_reference

    rng = np.random.default_rng(seed)
    pick = rng.choice(len(o), size=min(count, len(o)), replace=False)
    lo = vertices.min(0).astype(np.float64) - 1e-6
    hi = vertices.max(0).astype(np.float64) + 1e-6
    agree_hit = agree_prim = both = 0
    for i in pick:
        oi, di = o[i].astype(np.float64), d[i].astype(np.float64)
        cand = grid_candidates(n, lo, hi, oi, di, tmax)
        if cand.size:
            tri = triangles[cand]
            ref = intersect_reference(vertices[tri.ravel()], np.arange(3 * len(tri)).reshape(-1, 3),
                                      oi[None], di[None], 0.0, tmax)
            rp = int(cand[ref["prim"][0]]) if ref["prim"][0] >= 0 else -1
            rt_ = float(ref["t"][0])
        else:
            rp, rt_ = -1, np.inf
        gp, gt = int(hits["prim"][i]), float(hits["t"][i])
        agree_hit += (gp >= 0) == (rp >= 0)
        if gp >= 0 and rp >= 0:
            both += 1
            agree_prim += gp == rp or abs(gt - rt_) <= 1e-5 * max(abs(rt_), 1e-30)
    k = len(pick)
    return {"checked": k, "hit_agreement": agree_hit / k,
            "prim_or_t_agreement": agree_prim / max(both, 1)}


# -- timing -------------------------------------------------------------------------------------
def timed(rt, fn, reps: int) -> tuple[float, float, dict]:
    """(median wall ms, median summed-event ms, median ms per stage) of ``fn`` after a warm-up."""
    fn()
    rt.finish()
    rt.timer.collect()
    walls, gpus, stages = [], [], []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        rt.finish()
        walls.append((time.perf_counter() - t0) * 1e3)
        st = rt.timer.collect()
        stages.append(st)
        gpus.append(sum(st.values()))
    keys = sorted({k for s in stages for k in s})
    per_stage = {k: float(np.median([s.get(k, 0.0) for s in stages])) for k in keys}
    return float(np.median(walls)), float(np.median(gpus)), per_stage


def embree_rate(vertices, triangles, o, d, reps: int = 3, ours=None) -> dict | None:
    """Embree (embreex, robust mode) single-thread closest-hit rate on the same rays, or None:
    the median of ``reps`` runs after a warm-up, as for ours. With ``ours`` (a callable that runs
    our trace to completion), the two alternate run by run and ``paired_ratio`` is the median
    over the pairs of our rate over Embree's: both sides of a pair see the same load on a shared
    host, where medians taken minutes apart need not."""
    try:
        from embreex import mesh_construction, rtcore_scene
    except ImportError:
        return None
    scene = rtcore_scene.EmbreeScene(robust=True)
    mesh_construction.TriangleMesh(scene, vertices.astype(np.float32),
                                   triangles.astype(np.int32))
    o32, d32 = np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)
    scene.run(o32[:1000], d32[:1000], query="INTERSECT", output=1)  # warm-up (build)
    walls, cpus, ratios = [], [], []
    for _ in range(max(reps, 1)):
        t0, c0 = time.perf_counter(), time.process_time()
        res = scene.run(o32, d32, query="INTERSECT", output=1)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        if ours is not None:
            t0 = time.perf_counter()
            ours()
            ratios.append(walls[-1] / (time.perf_counter() - t0))
    return {"Mrays_s": len(o) / np.median(walls) / 1e6,
            "Mrays_per_cpu_s": len(o) / np.median(cpus) / 1e6, "prim": np.asarray(res["primID"]),
            "paired_ratio": float(np.median(ratios)) if ratios else None}


# -- the benchmark ------------------------------------------------------------------------------
def bench_grid(rt, n: int, args, rays: dict, log) -> dict:
    from app.meshes import height_field_grid
    from raytrace import RayQuery, Scene
    from raytrace.bvh import HIT_DTYPE
    from raytrace.query import pack_rays

    vertices, triangles = height_field_grid(n)
    row = {"grid": n - 1, "vertices_per_side": n, "tris": len(triangles)}
    scene = Scene(rt, leaf_size=args.leaf_size, layout=args.layout, stage="bench.bvh")
    mesh = scene.add_mesh(vertices, triangles, dynamic=True)
    scene.add_instance(mesh)
    scene.update()
    blas = scene.blas(mesh)
    row["layout"], row["leaf_size"] = scene.layout, scene.leaf_size
    row["build_ms"], row["build_gpu_ms"], st = timed(rt, blas.rebuild, args.reps)
    row.update({f"build.{k.split('.', 2)[-1]}_ms": v for k, v in st.items()})
    row["refit_ms"], row["refit_gpu_ms"], _ = timed(rt, blas.refit, args.reps)
    row["tlas_ms"], row["tlas_gpu_ms"], _ = timed(rt, scene._build_tlas, args.reps)
    blas.rebuild()
    stats = blas.stats()
    row.update({f"tree_{k}": v for k, v in stats.items() if k != "n_triangles"})
    if blas.wide is not None:
        winfo = blas.wide.info()
        row["wide_nodes"], row["wide_blocks"] = int(winfo["n_nodes"]), int(winfo["n_blocks"])
    log(f"grid {n - 1}^2 ({len(triangles)} tris, {scene.layout} layout, leaf {scene.leaf_size}):"
        f" build {row['build_ms']:.3f} ms (gpu {row['build_gpu_ms']:.3f}), refit "
        f"{row['refit_ms']:.3f} ms, tlas {row['tlas_ms']:.3f} ms, depth {stats['depth']}, "
        f"SAH {stats['sah_cost']:.1f}")
    other = None
    if args.compare_layouts and not rt.is_gpu:
        # the other layout on the same rays (its own default leaf size)
        other = Scene(rt, layout="binary" if scene.wide else "wide", stage="bench.bvh_other")
        other.add_instance(other.add_mesh(vertices, triangles, dynamic=True))
        other.update()
    warp = WARP_H100.get(n)
    if warp:
        row["build_vs_warp"] = warp["build_ms"] / row["build_ms"]
        row["refit_vs_warp"] = warp["refit_ms"] / row["refit_ms"]
    ok = True
    for kind, (o, d) in rays.items():
        ro, rd = pack_rays(o, d, 0.0, 1e6)
        hits_buf = rt.buffer(HIT_DTYPE.itemsize * len(o))
        q = RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits_buf, len(o),
                     stage="bench.trace")
        c0 = time.process_time()
        wall, gpu, _ = timed(rt, lambda q=q: q.enqueue(args.local_size), args.reps)
        cpu_s = (time.process_time() - c0) / (args.reps + 1)  # all host threads, per trace
        hits = rt.to_host(hits_buf, HIT_DTYPE, len(o))
        scene.check()
        row[f"{kind}_Mrays_s"] = len(o) / wall / 1e3
        row[f"{kind}_gpu_Mrays_s"] = len(o) / gpu / 1e3
        if not rt.is_gpu:
            # the host is shared: rays per second of CPU time this process used (PoCL's
            # threads included) is less sensitive to other processes than the wall clock
            row[f"{kind}_Mrays_per_cpu_s"] = len(o) / cpu_s / 1e6
        if other is not None:
            qg = RayQuery(other, q.org, q.dirs, rt.buffer(HIT_DTYPE.itemsize * len(o)),
                          len(o), stage="bench.trace_other")
            c0 = time.process_time()
            gwall, _, _ = timed(rt, lambda qg=qg: qg.enqueue(args.local_size), args.reps)
            g_cpu_s = (time.process_time() - c0) / (args.reps + 1)
            ghits = rt.to_host(qg.hits, HIT_DTYPE, len(o))
            row["other_layout"] = other.layout
            row[f"{kind}_other_Mrays_s"] = len(o) / gwall / 1e3
            row[f"{kind}_other_Mrays_per_cpu_s"] = len(o) / g_cpu_s / 1e6
            row[f"{kind}_other_same_hits"] = float(np.mean(ghits["prim"] == hits["prim"]))
            del qg
        row[f"{kind}_hit_frac"] = float((hits["prim"] >= 0).mean())
        chk = check_grid_hits(n, vertices, triangles, o, d, hits, 1e6, args.check_rays)
        row.update({f"{kind}_{k}": v for k, v in chk.items()})
        good = (chk["hit_agreement"] >= MIN_AGREEMENT
                and chk["prim_or_t_agreement"] >= MIN_AGREEMENT)
        row[f"{kind}_check"] = "ok" if good else "FAILED"
        ok &= good
        if warp:
            row[f"{kind}_vs_warp_sah"] = row[f"{kind}_Mrays_s"] / warp[f"{kind}_sah"]
            row[f"{kind}_vs_warp_lbvh"] = row[f"{kind}_Mrays_s"] / warp[f"{kind}_lbvh"]
        msg = (f"  {kind}: {row[f'{kind}_Mrays_s']:.1f} Mrays/s (gpu "
               f"{row[f'{kind}_gpu_Mrays_s']:.1f}), hits {row[f'{kind}_hit_frac']:.4f}, "
               f"check {row[f'{kind}_check']} ({chk['checked']} rays)")
        if args.embree and len(triangles) <= args.embree_max_tris:
            def ours(q=q):
                q.enqueue(args.local_size)
                rt.finish()

            emb = embree_rate(vertices, triangles, o, d, args.reps, ours=ours)
            if emb is not None:
                rt.timer.collect()  # the paired runs' events
                row[f"{kind}_embree_1t_Mrays_s"] = emb["Mrays_s"]
                row[f"{kind}_embree_1t_Mrays_per_cpu_s"] = emb["Mrays_per_cpu_s"]
                row[f"{kind}_vs_embree_1t"] = row[f"{kind}_Mrays_s"] / emb["Mrays_s"]
                row[f"{kind}_vs_embree_1t_paired"] = emb["paired_ratio"]
                row[f"{kind}_embree_prim_agreement"] = float(np.mean(emb["prim"] ==
                                                                     hits["prim"]))
                msg += (f"; embree 1 thread {emb['Mrays_s']:.1f} Mrays/s (ours "
                        f"{row[f'{kind}_vs_embree_1t']:.2f}x, paired runs "
                        f"{emb['paired_ratio']:.2f}x)")
        if f"{kind}_other_Mrays_s" in row:
            msg += (f"; {other.layout} layout {row[f'{kind}_other_Mrays_s']:.2f} Mrays/s (same "
                    f"hits {row[f'{kind}_other_same_hits']:.6f})")
        if f"{kind}_Mrays_per_cpu_s" in row:
            msg += f"; per CPU-second: ours {row[f'{kind}_Mrays_per_cpu_s']:.2f}"
            if f"{kind}_other_Mrays_per_cpu_s" in row:
                msg += f", {other.layout} {row[f'{kind}_other_Mrays_per_cpu_s']:.2f}"
            if f"{kind}_embree_1t_Mrays_per_cpu_s" in row:
                msg += f", embree {row[f'{kind}_embree_1t_Mrays_per_cpu_s']:.2f}"
        log(msg)
        del q, hits_buf
    if args.sort_compare:
        row.update(bench_sorts(rt, len(triangles), args.reps, log))
    row["check"] = "ok" if ok else "FAILED"
    return row


def bench_sorts(rt, n: int, reps: int, log) -> dict:
    """Our radix sort (the default digit width, and 4 and 8 bits per pass) vs
    pyopencl.algorithm.RadixSort on n random 32-bit keys (and values)."""
    from raytrace.sort import RadixSorter, default_radix_bits

    rng = np.random.default_rng(3)
    keys = rng.integers(0, 2**32, n, dtype=np.uint64).astype(np.uint32)
    vals = np.arange(n, dtype=np.uint32)
    kb, vb = rt.to_device(keys), rt.to_device(vals)

    def ours(sorter):
        cl.enqueue_copy(rt.queue, kb, keys)
        cl.enqueue_copy(rt.queue, vb, vals)
        rt.finish()
        t0 = time.perf_counter()
        sorter.enqueue()
        rt.finish()
        return (time.perf_counter() - t0) * 1e3

    bits_default = default_radix_bits(n, rt.is_gpu)
    out = {"sort_default_radix_bits": bits_default}
    for bits in (4, 8):
        sorter = RadixSorter(rt, kb, vb, n, radix_bits=bits, stage="bench.sort")
        ours(sorter)
        out[f"sort_ours{bits}_ms"] = float(np.median([ours(sorter) for _ in range(reps)]))
        assert np.array_equal(rt.to_host(kb, np.uint32, n), np.sort(keys)), "radix sort wrong"
    out["sort_ours_ms"] = out[f"sort_ours{bits_default}_ms"]
    try:
        import pyopencl.array as cla
        from pyopencl.algorithm import RadixSort

        rs = RadixSort(rt.context, "uint *keys, uint *vals", key_expr="keys[i]",
                       sort_arg_names=["keys", "vals"], key_dtype=np.uint32)
        ka, va = cla.to_device(rt.queue, keys), cla.to_device(rt.queue, vals)

        def theirs():
            t0 = time.perf_counter()
            (sk, _sv), evt = rs(ka, va, key_bits=32)
            evt.wait()
            rt.finish()
            return (time.perf_counter() - t0) * 1e3, sk

        theirs()
        times = [theirs() for _ in range(reps)]
        out["sort_pyopencl_ms"] = float(np.median([t for t, _ in times]))
        assert np.array_equal(times[-1][1].get(), np.sort(keys)), "pyopencl sort wrong"
    except ImportError as exc:  # mako missing
        out["sort_pyopencl_ms"] = None
        out["sort_pyopencl_error"] = str(exc)
    theirs_ms = out["sort_pyopencl_ms"]
    log(f"  sort {n} pairs: ours {out['sort_ours_ms']:.3f} ms, pyopencl.algorithm.RadixSort "
        f"{'n/a' if theirs_ms is None else f'{theirs_ms:.3f}'} ms")
    return out


def bench_sweep(rt, n: int, args, rays: dict, log) -> list[dict]:
    """Ray rates of grid n for every (leaf size, trace work-group size) pair; build times too."""
    from app.meshes import height_field_grid
    from raytrace import RayQuery, Scene
    from raytrace.bvh import HIT_DTYPE
    from raytrace.query import pack_rays

    vertices, triangles = height_field_grid(n)
    packed = {k: pack_rays(o, d, 0.0, 1e6) for k, (o, d) in rays.items()}
    rows = []
    for leaf in [int(x) for x in args.sweep_leaf.split(",")]:
        scene = Scene(rt, leaf_size=leaf, layout=args.layout, stage="sweep.bvh")
        scene.add_instance(scene.add_mesh(vertices, triangles, dynamic=True))
        scene.update()
        build, _, _ = timed(rt, scene.blas(0).rebuild, 3)
        sah = scene.blas(0).stats()["sah_cost"]
        for wg in [int(x) for x in args.sweep_wg.split(",")]:
            row = {"grid": n - 1, "leaf_size": leaf, "local_size": wg, "build_ms": build,
                   "sah_cost": sah}
            for kind, (ro, rd) in packed.items():
                hits = rt.buffer(HIT_DTYPE.itemsize * len(ro))
                q = RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits, len(ro),
                             stage="sweep.trace")
                wall, _, _ = timed(rt, lambda q=q, wg=wg: q.enqueue(wg), 3)
                row[f"{kind}_Mrays_s"] = len(ro) / wall / 1e3
            log(f"  sweep leaf {leaf} wg {wg}: build {build:.3f} ms, SAH {sah:.1f}, primary "
                f"{row['primary_Mrays_s']:.0f}, incoherent {row['incoherent_Mrays_s']:.0f} Mrays/s")
            rows.append(row)
        scene.check()
    return rows


def bench_mesh(rt, name: str, args, log) -> dict:
    from app.meshes import load_mesh
    from raytrace import Scene

    v, t = load_mesh(name)
    scene = Scene(rt, leaf_size=args.leaf_size, layout=args.layout, stage="bench.mesh")
    scene.add_instance(scene.add_mesh(v, t))
    scene.update()
    blas = scene.blas(0)
    row = {"mesh": name, "tris": len(t), "layout": scene.layout, "leaf_size": scene.leaf_size}
    row["build_ms"], row["build_gpu_ms"], _ = timed(rt, blas.rebuild, args.reps)
    row["refit_ms"], row["refit_gpu_ms"], _ = timed(rt, blas.refit, args.reps)
    blas.rebuild()
    blas.check()
    stats = blas.stats(reference_sah=args.reference_sah)
    row.update({f"tree_{k}": v for k, v in stats.items() if k != "n_triangles"})
    log(f"{name} ({len(t)} tris): build {row['build_ms']:.3f} ms (gpu {row['build_gpu_ms']:.3f})"
        f", refit {row['refit_ms']:.3f} ms, SAH {stats['sah_cost']:.1f}"
        + (f" (CPU binned SAH {stats['reference_sah_cost']:.1f})" if args.reference_sah else ""))
    return row


def add_arguments(p) -> None:
    p.add_argument("--sizes", default=",".join(map(str, GRID_SIZES)),
                   help="grid vertices per side, comma-separated (default: %(default)s)")
    p.add_argument("--meshes", default=",".join(MESHES),
                   help="meshes in scenes/models to time builds of ('' for none)")
    p.add_argument("--reps", type=int, default=20, help="timed repetitions (median)")
    p.add_argument("--layout", choices=["binary", "wide"], default=None,
                   help="BLAS layout (default: binary on a GPU, wide on a CPU)")
    p.add_argument("--leaf-size", type=int, default=None,
                   help="most triangles per BVH leaf (default: 1 binary, 4 wide)")
    p.add_argument("--local-size", type=int, default=64, help="work-group size of the trace kernel")
    p.add_argument("--check-rays", type=int, default=1000,
                   help="rays per set checked against the float64 reference")
    p.add_argument("--rays", choices=["full", "small"], default="full",
                   help="full: the anchor's 1920x1080 + 2^21 rays; small: 480x270 + 2^17 (CPU)")
    p.add_argument("--no-embree", dest="embree", action="store_false",
                   help="skip the embreex single-thread comparison")
    p.add_argument("--embree-max-tris", type=int, default=3_000_000,
                   help="skip Embree above this many triangles (its build is slow)")
    p.add_argument("--no-sort-compare", dest="sort_compare", action="store_false",
                   help="skip the radix sort vs pyopencl.algorithm.RadixSort comparison")
    p.add_argument("--sweep-leaf", default="",
                   help="leaf sizes to sweep on --sweep-size, e.g. 1,2,4,8 (off if empty)")
    p.add_argument("--sweep-size", type=int, default=1025,
                   help="grid vertices per side of the sweep (default: %(default)s)")
    p.add_argument("--sweep-wg", default="32,64,128,256",
                   help="trace work-group sizes for --sweep-leaf (default: %(default)s)")
    p.add_argument("--no-compare-layouts", dest="compare_layouts", action="store_false",
                   help="on a CPU device, skip timing the other BVH layout on the same rays")
    p.add_argument("--reference-sah", action="store_true",
                   help="also build a CPU binned-SAH tree of each mesh for its SAH cost (slow)")


def run(args) -> int:
    from app.io import write_csv, write_json
    from kernels import get_runtime

    if args.reps < 1:
        raise ValueError(f"--reps must be >= 1, got {args.reps}")
    try:
        sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"--sizes must be integers separated by commas, got {args.sizes!r}"
                         ) from None
    if any(s < 2 or s > 4097 for s in sizes):
        raise ValueError(f"--sizes must lie in [2, 4097], got {sizes}")
    rt = get_runtime(args.device)
    out = Path(args.out)

    def log(msg):
        print(msg, flush=True)

    meta = {"device": rt.name, "platform": rt.device.platform.name.strip(),
            "date": datetime.date.today().isoformat(), "command": " ".join(sys.argv),
            "python": platform.python_version(), "leaf_size": args.leaf_size, "layout": args.layout,
            "reps": args.reps, "rays": args.rays}
    log(f"bench bvh on {rt.name} ({meta['platform']})")
    if args.rays == "full":
        w, h, n_inc = 1920, 1080, 1 << 21
    else:
        w, h, n_inc = 480, 270, 1 << 17
    rays = {"primary": rays_primary(w, h), "incoherent": rays_incoherent(n_inc,
                                                                         np.random.default_rng(1))}
    rows = []
    for n in sizes:
        rows.append(bench_grid(rt, n, args, rays, log))
    mesh_rows = [bench_mesh(rt, m, args, log) for m in args.meshes.split(",") if m.strip()]
    sweep = bench_sweep(rt, args.sweep_size, args, rays, log) if args.sweep_leaf else []
    result = {"meta": meta, "grids": rows, "meshes": mesh_rows, "sweep": sweep}
    write_json(out / "bvh.json", result)
    write_csv(out / "bvh_grids.csv", rows)
    if mesh_rows:
        write_csv(out / "bvh_meshes.csv", mesh_rows)
    if sweep:
        write_csv(out / "bvh_sweep.csv", sweep)
    log(f"wrote {out / 'bvh.json'}")
    failed = [r["grid"] for r in rows if r["check"] != "ok"]
    if failed:
        print(f"bench bvh: hits disagree with the float64 reference on grids {failed}",
              file=sys.stderr)
        return 1
    json.dumps(result)  # fail loudly here if something is not serialisable
    return 0
