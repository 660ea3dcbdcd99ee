"""The host's cost of one kernel launch: microseconds per clEnqueueNDRangeKernel through
pyopencl, on a queue with and without profiling, for an empty kernel and a launch with its
event recorded by the frame's timer (``kernels.timing.StageTimer``). One JSON line.

    PYTHONPATH=. python bench/launch_cost.py [--launches 2000] [--device D]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

_EMPTY = "__kernel void empty(__global int* a) { if (get_global_id(0) == 0x7fffffff) a[0] = 1; }"


def per_launch_us(queue, kernel, n: int, record=None) -> float:
    """Median over 5 batches of n launches of the host's microseconds per launch (the queue
    drained between batches, not inside)."""
    import pyopencl as cl

    out = []
    for _ in range(5):
        queue.finish()
        t0 = time.perf_counter()
        for _ in range(n):
            evt = cl.enqueue_nd_range_kernel(queue, kernel, (65536,), (64,))
            if record is not None:
                record("probe", evt)
        out.append((time.perf_counter() - t0) / n * 1e6)
        queue.finish()
    return statistics.median(out)


def main(argv=None) -> int:
    import pyopencl as cl

    from kernels import get_runtime
    from kernels.timing import StageTimer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--launches", type=int, default=2000)
    ap.add_argument("--device")
    args = ap.parse_args(argv)
    rt = get_runtime(args.device)
    row = {"device": rt.name, "date": time.strftime("%Y-%m-%d"), "launches": args.launches}
    buf = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE, 4)
    for name, props in (("profiling", cl.command_queue_properties.PROFILING_ENABLE),
                        ("plain", 0)):
        q = cl.CommandQueue(rt.context, rt.device, properties=props)
        k = cl.Program(rt.context, _EMPTY).build().empty
        k.set_arg(0, buf)
        row[f"{name}_us"] = round(per_launch_us(q, k, args.launches), 2)
        timer = StageTimer(enabled=True, max_events=1 << 30)
        row[f"{name}_recorded_us"] = round(per_launch_us(q, k, args.launches, timer.record), 2)
    print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
