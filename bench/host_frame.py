"""The host's own cost of a frame: ms of Python in ``World.enqueue_frame`` and in ``read_frame``
(stage times, stats) of a completed frame; then the pipelined loop.

    PYTHONPATH=. python bench/host_frame.py                   # PoCL: tiny sizes, few photons
    PYTHONPATH=. python bench/host_frame.py --cells 1024 --size 1920 1080 --photons 131072 \
        --caustic-resolution 256 --hold-ms 0                   # a GPU

``enqueue_ms``: the device is drained before each frame, then (``--hold-ms``, for a CPU
device whose kernels would compete with the host for the cores) held by a one-work-item
kernel of about that long, so the frame's kernels run only after the host has queued them; the
time is the host's work alone (``held_waits`` counts frames whose enqueue outlasted the hold:
the host waited on the device). ``read_ms``: the frame's completion (event timings, stats)
after the device finished. ``pipelined``: the frame loop of ``lbwater bench frame`` (two
frames in flight): ms of wall per frame and of the host inside ``enqueue_frame`` (which
includes any wait on the device). One JSON line.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


_SPIN = """__kernel void spin(__global float *a, int n) {
    float x = a[0];
    for (int i = 0; i < n; i++) x = x * 0.9999999f + 1e-7f;
    a[0] = x;
}"""


def _holder(rt, seconds: float):
    """A launcher of one work-item that keeps the in-order queue busy for about ``seconds``."""
    import numpy as np
    import pyopencl as cl

    k = cl.Kernel(cl.Program(rt.context, _SPIN).build(), "spin")
    buf = rt.to_device(np.ones(1, np.float32))
    n = 1 << 16
    while True:
        k.set_args(buf, np.int32(n))
        t0 = time.perf_counter()
        cl.enqueue_nd_range_kernel(rt.queue, k, (1,), (1,)).wait()
        dt = time.perf_counter() - t0
        if dt > 0.02 or n >= 1 << 30:
            break
        n *= 4
    k.set_args(buf, np.int32(min(int(n * seconds / dt), 2**31 - 1)))
    return lambda buf=buf: cl.enqueue_nd_range_kernel(rt.queue, k, (1,), (1,))  # buf: alive


class _Shims:
    """Times pyopencl's C entry points of the frame (launch, copy, set_arg, flush, event
    queries), so the host's Python cost is the rest."""

    FUNCS = ("enqueue_nd_range_kernel", "enqueue_copy")
    METHODS = (("Kernel", "set_arg"), ("CommandQueue", "flush"),
               ("Event", "get_profiling_info"), ("Event", "wait"))

    def __init__(self):
        import pyopencl as cl

        self.seconds, self.calls, self.on = 0.0, 0, False
        self._saved = [(cl, name, getattr(cl, name)) for name in self.FUNCS] + [
            (getattr(cl, cls), name, getattr(getattr(cl, cls), name))
            for cls, name in self.METHODS]
        for owner, name, f in self._saved:
            setattr(owner, name, self._wrap(f))

    def restore(self) -> None:
        for owner, name, f in self._saved:
            setattr(owner, name, f)

    def _wrap(self, f):
        clock = time.perf_counter

        def shim(*a, **k):
            if not self.on:
                return f(*a, **k)
            t = clock()
            try:
                return f(*a, **k)
            finally:
                self.seconds += clock() - t
                self.calls += 1
        return shim

    def take(self) -> tuple[float, int]:
        out = (self.seconds, self.calls)
        self.seconds, self.calls = 0.0, 0
        return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "pool.toml"))
    ap.add_argument("--cells", type=int, default=32)
    ap.add_argument("--size", type=int, nargs=2, default=[64, 48])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--steps", type=int, default=16, help="LBM steps per frame")
    ap.add_argument("--photons", type=int, default=256, help="caustic photons")
    ap.add_argument("--caustic-resolution", type=int, default=32)
    ap.add_argument("--hold-ms", type=float, default=60.0,
                    help="hold the device this long at each measured enqueue (0: off)")
    ap.add_argument("--device")
    ap.add_argument("--split", action="store_true",
                    help="also time pyopencl's C calls (launch, copy, set_arg, flush, event "
                         "queries): enqueue_py_ms and read_py_ms are the rest, Python's own")
    args = ap.parse_args(argv)
    shims = _Shims() if args.split else None
    try:
        return _run(args, shims)
    finally:
        if shims:
            shims.restore()


def _run(args, shims) -> int:
    global _COMPLETE
    import pyopencl as cl

    from app.scene import load_scene
    from app.world import World

    _COMPLETE = cl.command_execution_status.COMPLETE

    scene = load_scene(args.scene)
    if scene.shading is not None:
        scene = dataclasses.replace(scene, shading=dataclasses.replace(
            scene.shading, caustic_photons=args.photons,
            caustic_resolution=args.caustic_resolution))
    world = World(scene, args.device, width=args.size[0], height=args.size[1],
                  cells=args.cells)
    seconds = args.steps * world.sim.dt * (1 + 1e-6) if world.sim is not None else 1 / 60
    for _ in range(5):
        world.frame(seconds)
    rt = world.rt
    hold = _holder(rt, args.hold_ms * 1e-3) if args.hold_ms > 0 else None
    enq, read, events, waits, enq_c, read_c, ncalls = [], [], [], 0, [], [], []
    for _ in range(args.frames):
        world.drain()
        rt.finish()
        held = hold() if hold is not None else None
        if shims:
            shims.on = True
            shims.take()
        t0 = time.perf_counter()
        world.enqueue_frame(seconds)
        t1 = time.perf_counter()
        if shims:
            c, n = shims.take()
            enq_c.append(c)
            ncalls.append(n)
            shims.on = False
        waits += held is not None and held.command_execution_status == _COMPLETE
        events.append(rt.timer.pending())
        rt.finish()
        if shims:
            shims.on = True
        t2 = time.perf_counter()
        world.read_frame(copy=False)
        t3 = time.perf_counter()
        if shims:
            read_c.append(shims.take()[0])
            shims.on = False
        enq.append(t1 - t0)
        read.append(t3 - t2)
    inside = []
    t0 = time.perf_counter()
    for i in range(args.frames):
        t1 = time.perf_counter()
        world.enqueue_frame(seconds)
        inside.append(time.perf_counter() - t1)
        if i:
            world.read_frame(copy=False)
    world.read_frame(copy=False)
    wall = (time.perf_counter() - t0) / args.frames
    st = world.stats
    out = {"device": world.device_name, "date": time.strftime("%Y-%m-%d"),
           "cells": args.cells, "size": args.size, "lbm_steps": st.lbm_steps,
           "events_per_frame": statistics.median(events),
           "held_waits": waits, "enqueue_ms": round(statistics.median(enq) * 1e3, 3),
           "read_ms": round(statistics.median(read) * 1e3, 3),
           "pipelined_wall_ms": round(wall * 1e3, 3),
           "pipelined_enqueue_ms": round(statistics.median(inside) * 1e3, 3),
           "kernel_ms": round(st.kernel_ms, 3)}
    out["enqueue_min_ms"] = round(min(enq) * 1e3, 3)   # the least disturbed frame
    out["read_min_ms"] = round(min(read) * 1e3, 3)
    if shims:
        py_enq = [a - b for a, b in zip(enq, enq_c, strict=True)]
        py_read = [a - b for a, b in zip(read, read_c, strict=True)]
        out["enqueue_cl_calls"] = statistics.median(ncalls)
        out["enqueue_py_ms"] = round(statistics.median(py_enq) * 1e3, 3)
        out["enqueue_py_min_ms"] = round(min(py_enq) * 1e3, 3)
        out["read_py_ms"] = round(statistics.median(py_read) * 1e3, 3)
        out["read_py_min_ms"] = round(min(py_read) * 1e3, 3)
    print(json.dumps(out))
    world.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
