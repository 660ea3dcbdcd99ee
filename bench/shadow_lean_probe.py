"""What a shadow stage that traced a list of rays written by the shading would cost: a diagnosis
of issue 9's last speed goal (shadow rays no costlier than the primary trace), not a render path.

After a frame of two levels (``bounces = 1``: level 0's and level 1's rays and hits stay in the
renderer's buffers), each level's shadow rays run as the renderer runs them (``render_shadow``,
and ``render_shadow_binned`` where the renderer bins a level) and as the two launches of
kernels/render_shadow_lean_probe.cl: ``render_shadow_emit`` (render_shadow's shading and light
loop, writing each traced shadow ray to a list, crossing rays first) and ``render_shadow_lean``
(the list alone, traced with the same shadow_transmittance); level 0's primary trace runs beside
them for the ratio. Both ways must give the same radiance (checked each run); the medians of the
OpenCL event times go to ``--json``. Also timed: the renderer's own shadow kernels over the hits
of full light-buffer cells first (``render_shadow_ordered``, ``_binned``; the same radiance,
checked); with ``--full-first`` the list takes those rays first; with ``--all-levels`` every
level's list (0-5) is traced in one launch too (:func:`time_all_levels`).

    PYTHONPATH=$PWD python bench/shadow_lean_probe.py --scene bench/scenes/pool_static_boat.toml \\
        --cells 1024 --size 1920 1080 --repeats 20 --json lean.json
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def event_ms(evt) -> float:
    return (evt.profile.end - evt.profile.start) * 1e-6


class LeanShadowProbe:
    """The two probe kernels bound to one level of ``world``'s renderer."""

    def __init__(self, world, depth: int, full_first: bool = False, shared: tuple | None = None):
        """``shared``: (list, list_counts, capacity) of a list several levels write
        (:func:`time_all_levels`) instead of one of its own."""
        import pyopencl as cl

        from kernels.errors import InputError
        from raytrace.render_types import RAY

        r, rt = world.renderer, world.rt
        if len(r.scene.lights) != 1:
            raise InputError(f"{world.scene.path}: the probe takes a scene of one light, it has "
                             f"{len(r.scene.lights)}")
        self.rt = rt
        ks = r._depth_kernels(depth)
        self.shadow = ks["shadow"]
        self.shadow_binned = ks.get("shadow_binned")
        self.trace = ks["trace"] if depth == 0 else None
        self.n = int(rt.to_host(r.counts, np.uint32, 1, first=depth)[0])
        self.radiance = r.radiance[depth % 2]
        self.size = self.radiance.size
        self.saved = rt.buffer(self.size)
        cl.enqueue_copy(rt.queue, self.saved, self.radiance)
        self.capacity = max(self.n, 1)
        if shared:
            self.list, self.list_counts, self.capacity = shared
        else:   # the list, then the rays of full cells (LEAN_FULL_FIRST)
            self.list = rt.buffer(2 * self.capacity * RAY.itemsize)
            self.list_counts = rt.buffer(12)
        self.local = r.settings.local_size
        scene = r.scene.scene.trace_bindings()
        geom = r.scene.shade_bindings()
        common = {**geom, "prm": r.params_buf}
        defines = {"LEAN_FULL_FIRST": int(full_first)}
        self.emit = rt.kernel_launcher("render_shadow_lean_probe.cl", "render_shadow_emit",
                                       stage="probe.emit", defines=defines)
        self.emit.bind(**common, lights=r.scene.light_buf, rays=r.rays[depth % 2],
                       hits=r.hits[depth % 2], counts=r.counts, depth=depth,
                       radiance=self.radiance, caustic_map=r.caustic_map,
                       cprm=r.caustic_params, list=self.list, list_counts=self.list_counts,
                       capacity=self.capacity, **r.light_buffer.bindings())
        self.lean = rt.kernel_launcher("render_shadow_lean_probe.cl", "render_shadow_lean",
                                       stage="probe.lean", defines=defines)
        self.lean.bind(**scene, **common, **r.light_buffer.bindings(), list=self.list,
                       list_counts=self.list_counts, capacity=self.capacity,
                       radiance=self.radiance)
        # the renderer's shadow kernels over the hits of full light-buffer cells first
        self.first_flags = rt.buffer(self.capacity)
        self.first_list = rt.buffer(4 * self.capacity)
        self.first_count = rt.buffer(4)
        first = {"first_flags": self.first_flags, "first_list": self.first_list,
                 "first_count": self.first_count}
        level = {"rays": r.rays[depth % 2], "hits": r.hits[depth % 2], "counts": r.counts,
                 "depth": depth, "cprm": r.caustic_params, **r.light_buffer.bindings()}
        self.classify = rt.kernel_launcher("render_shadow_lean_probe.cl",
                                           "render_shadow_classify", stage="probe.classify")
        self.classify.bind(**common, **level, **first)
        self.ordered = {}
        for name in ("render_shadow_ordered", "render_shadow_ordered_binned"):
            k = rt.kernel_launcher("render_shadow_lean_probe.cl", name, stage="probe.ordered")
            k.bind(**scene, **common, **level, **first, lights=r.scene.light_buf,
                   radiance=self.radiance, caustic_map=r.caustic_map)
            self.ordered[name.endswith("binned")] = k

    def _size(self, n: int, local: int) -> tuple:
        return (-(-max(n, 1) // local) * local,)

    def restore(self) -> None:
        import pyopencl as cl

        cl.enqueue_copy(self.rt.queue, self.radiance, self.saved)

    def run_production(self, binned: bool = False):
        from raytrace.render import BIN_WG

        if binned:
            return self.shadow_binned.launch(self._size(self.n, BIN_WG), (BIN_WG,))
        return self.shadow.launch(self._size(self.n, self.local), (self.local,))

    def run_lean(self) -> tuple:
        """(emit event, lean event, crossing rays, other rays)."""
        import pyopencl as cl

        q = self.rt.queue
        cl.enqueue_fill_buffer(q, self.list_counts, np.uint32(0), 0, 12)
        e1 = self.emit.launch(self._size(self.n, self.local), (self.local,))
        counts = self.rt.to_host(self.list_counts, np.uint32, 3)
        self.full_rays = int(counts[2])
        e2 = self.lean.launch(self._size(int(counts.sum()), self.local), (self.local,))
        return e1, e2, int(counts[0]), int(counts[1])

    def run_ordered(self, binned: bool = False) -> tuple:
        """(classify event, ordered shadow event, hits taken first)."""
        import pyopencl as cl

        from raytrace.render import BIN_WG

        cl.enqueue_fill_buffer(self.rt.queue, self.first_count, np.uint32(0), 0, 4)
        e1 = self.classify.launch(self._size(self.n, self.local), (self.local,))
        n_first = int(self.rt.to_host(self.first_count, np.uint32, 1)[0])
        local = BIN_WG if binned else self.local
        e2 = self.ordered[binned].launch(self._size(self.n + n_first, local), (local,))
        return e1, e2, n_first

    def radiance_now(self) -> np.ndarray:
        return self.rt.to_host(self.radiance, np.float32, self.size // 4).reshape(-1, 4)


def compare(probe: LeanShadowProbe) -> dict:
    """The production kernel's radiance against the two launches' (from the same start)."""
    probe.restore()
    probe.run_production()
    want = probe.radiance_now()[: probe.n]
    probe.restore()
    *_, n_cross, n_other = probe.run_lean()
    got = probe.radiance_now()[: probe.n]
    probe.restore()
    scale = max(float(np.abs(want).max()), 1e-30)
    ordered = {}
    for binned in (False, True):
        *_, n_first = probe.run_ordered(binned)
        ordered[binned] = probe.radiance_now()[: probe.n]
        probe.restore()
    return {"max_abs_diff": float(np.abs(got - want).max()), "radiance_max": scale,
            "list_crossing": n_cross, "list_other": n_other, "first_hits": n_first,
            "ordered_equal": all(np.array_equal(v, want) for v in ordered.values())}


def time_level(probe: LeanShadowProbe, repeats: int) -> dict:
    """Median ms of each launch over ``repeats`` rounds (one warm-up round first)."""
    times: dict[str, list] = {}
    for rep in range(repeats + 1):
        evts = {"shadow": probe.run_production()}
        if probe.shadow_binned is not None:
            evts["shadow_binned"] = probe.run_production(binned=True)
        evts["emit"], evts["lean"], *_ = probe.run_lean()
        evts["classify"], evts["ordered"], _ = probe.run_ordered()
        _, evts["ordered_binned"], _ = probe.run_ordered(binned=True)
        if probe.trace is not None:
            evts["primary_trace"] = probe.trace.launch(probe._size(probe.n, probe.local),
                                                       (probe.local,))
        probe.rt.queue.finish()
        if rep:
            for k, e in evts.items():
                times.setdefault(k, []).append(event_ms(e))
    probe.restore()
    out = {f"{k}_ms": float(np.median(v)) for k, v in times.items()}
    out["emit_plus_lean_ms"] = out["emit_ms"] + out["lean_ms"]
    return out


def time_all_levels(args) -> dict:
    """Every level's shadow rays (0-5: frames of 1, 3 and 5 bounces on the same water, each
    leaving its last two levels in the renderer's buffers) written to one list and traced in
    one launch, against each level's list traced alone: what a stage would cost that traced
    every level's list once after the last trace. Timing only (the merged launch adds into a
    level-0 radiance buffer)."""
    import pyopencl as cl

    from app.world import World
    from raytrace.render_types import RAY

    lb = {} if args.light_buffer is None else {"light_buffer": args.light_buffer}
    worlds, rt = [], None
    for bounces in (1, 3, 5):
        w = World(args.scene, rt or args.device, width=args.size[0], height=args.size[1],
                  cells=args.cells, bounces=bounces, **lb)
        rt = w.rt
        for _ in range(args.settle):
            w.frame(1 / 60)
        w.frame(0.0)
        rt.queue.finish()
        worlds.append((w, (bounces - 1, bounces)))
    probes = [LeanShadowProbe(w, d, args.full_first) for w, ds in worlds for d in ds]
    total = sum(max(p.n, 1) for p in probes)
    shared = (rt.buffer(2 * total * RAY.itemsize), rt.buffer(12), total)
    merged = [LeanShadowProbe(w, d, args.full_first, shared) for w, ds in worlds for d in ds]
    times: dict[str, list] = {}
    for rep in range(args.repeats + 1):
        alone = [p.run_lean() for p in probes]
        cl.enqueue_fill_buffer(rt.queue, shared[1], np.uint32(0), 0, 12)
        for m in merged:
            m.emit.launch(m._size(m.n, m.local), (m.local,))
        n = int(rt.to_host(shared[1], np.uint32, 3).sum())
        lean = merged[0].lean.launch(merged[0]._size(n, merged[0].local), (merged[0].local,))
        trace = probes[0].trace.launch(probes[0]._size(probes[0].n, probes[0].local),
                                       (probes[0].local,))
        rt.queue.finish()
        if rep:
            for d, (_, e, *_) in enumerate(alone):
                times.setdefault(f"lean_d{d}", []).append(event_ms(e))
            times.setdefault("lean_all_one_launch", []).append(event_ms(lean))
            times.setdefault("primary_trace", []).append(event_ms(trace))
    out = {f"{k}_ms": float(np.median(v)) for k, v in times.items()}
    out["lean_levels_sum_ms"] = sum(out[f"lean_d{d}_ms"] for d in range(6))
    out["hits"] = [p.n for p in probes]
    out["list"] = n
    return out


def kernel_registers(rt) -> dict:
    """Registers and spills of the probe's and the shadow stage's kernels from the compiler's
    report (NVIDIA, with LBWATER_CL_OPTIONS=-cl-nv-verbose); empty elsewhere."""
    import pyopencl as cl

    from bench.kernel_resources import parse_log

    out = {}
    for source in ("render_shadow_lean_probe.cl", "render_shade.cl", "render_trace.cl"):
        log = rt.program(source).get_build_info(rt.device, cl.program_build_info.LOG)
        out.update(parse_log(log or ""))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=str(ROOT / "bench" / "scenes" / "pool_static_boat.toml"))
    p.add_argument("--cells", type=int, default=256, help="water cells along the longer side")
    p.add_argument("--size", type=int, nargs=2, default=[320, 180], metavar=("W", "H"))
    p.add_argument("--settle", type=int, default=30, help="frames of 1/60 s before measuring")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--device", help="OpenCL device (default: lbwater's choice)")
    p.add_argument("--json", help="write the numbers here")
    p.add_argument("--light-buffer", type=int, metavar="CELLS",
                   help="the light buffer's cells (default: the device's choice)")
    p.add_argument("--full-first", action="store_true",
                   help="trace the rays from full light-buffer cells first (LEAN_FULL_FIRST)")
    p.add_argument("--all-levels", action="store_true",
                   help="also every level's lists traced in one launch (time_all_levels)")
    args = p.parse_args(argv)

    from kernels.errors import InputError

    try:
        return measure(args)
    except InputError as exc:   # a user's mistake: one line, no traceback
        print(f"shadow_lean_probe: {exc}", file=sys.stderr)
        return 2


def measure(args) -> int:
    """Render, probe levels 0 and 1, print a line each and write the JSON."""
    from app.world import World

    lb = {} if args.light_buffer is None else {"light_buffer": args.light_buffer}
    world = World(args.scene, args.device, width=args.size[0], height=args.size[1],
                  cells=args.cells, bounces=1, **lb)
    for _ in range(args.settle):
        world.frame(1 / 60)
    world.frame(0.0)
    world.rt.queue.finish()
    result = {"device": world.rt.name, "date": datetime.date.today().isoformat(),
              "scene": args.scene, "size": args.size, "cells": args.cells,
              "settle_frames": args.settle, "repeats": args.repeats,
              "full_first": args.full_first, "levels": []}
    for depth in (0, 1):
        probe = LeanShadowProbe(world, depth, args.full_first)
        level = {"depth": depth, "hits": probe.n, **compare(probe),
                 "list_full_first": probe.full_rays, **time_level(probe, args.repeats)}
        if level["max_abs_diff"] > 1e-4 * level["radiance_max"]:
            raise RuntimeError(f"level {depth}: the two launches' radiance differs from "
                               f"render_shadow's by {level['max_abs_diff']:.3g}")
        if not level["ordered_equal"]:
            raise RuntimeError(f"level {depth}: the ordered shadow kernels' radiance differs "
                               "from render_shadow's")
        result["levels"].append(level)
        print(f"level {depth}: {probe.n} hits, list {level['list_full_first']} full-cell first + "
              f"{level['list_crossing']} crossing + {level['list_other']} other, "
              f"{level['first_hits']} hits first; " + ", ".join(
                  f"{k[:-3]} {v:.4f}" for k, v in level.items() if k.endswith("_ms")) + " ms",
              flush=True)
    if args.all_levels:
        result["all_levels"] = time_all_levels(args)
        print("all levels: " + ", ".join(f"{k[:-3]} {v:.4f}" for k, v in
                                         result["all_levels"].items() if k.endswith("_ms"))
              + f" ms; hits {result['all_levels']['hits']}", flush=True)
    result["registers"] = kernel_registers(world.rt)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
