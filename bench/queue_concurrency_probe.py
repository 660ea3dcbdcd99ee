"""Do kernels of two in-order OpenCL queues run at once on this device? (A probe for the frame
pipeline: running the next frame's water stages beside this frame's latency-bound render tail
needs it.) A latency-bound kernel (one work-group chasing a pointer chain through a buffer) and
a bandwidth-bound one (a large copy kernel) are timed alone, back to back on one queue, and on
two queues at once (host wall from the first enqueue to both finished, median of repeats).
Prints one line per case and writes DIR/queue_concurrency.json.

    python3 bench/queue_concurrency_probe.py --out DIR
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SOURCE = """
__kernel void chase(__global const int* next, __global int* out, const int steps)
{
    int i = get_global_id(0);
    for (int s = 0; s < steps; ++s) i = next[i];
    out[get_global_id(0)] = i;
}
__kernel void stream(__global const float4* a, __global float4* b)
{
    const size_t i = get_global_id(0);
    b[i] = a[i] * 1.0001f + (float4)(1.0f);
}
"""


def main(argv=None) -> int:
    import pyopencl as cl

    from kernels import get_runtime

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None)
    p.add_argument("--steps", type=int, default=4000, help="pointer-chase steps (latency kernel)")
    p.add_argument("--mb", type=int, default=256, help="MB copied by the bandwidth kernel")
    p.add_argument("--repeats", type=int, default=15)
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    rt = get_runtime(args.device)
    ctx = rt.context
    q1 = cl.CommandQueue(ctx, rt.device)
    q2 = cl.CommandQueue(ctx, rt.device)
    prg = cl.Program(ctx, SOURCE).build()
    n_chase = 1 << 24   # 64 MB of links: a random cycle, every step a cache miss
    rng = np.random.default_rng(0)
    perm = rng.permutation(n_chase).astype(np.int32)
    nxt = np.empty(n_chase, np.int32)
    nxt[perm] = np.roll(perm, -1)
    mf = cl.mem_flags
    d_next = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=nxt)
    d_out = cl.Buffer(ctx, mf.WRITE_ONLY, 4 * 1024)
    n4 = args.mb * (1 << 20) // 16
    d_a = cl.Buffer(ctx, mf.READ_WRITE, n4 * 16)
    d_b = cl.Buffer(ctx, mf.READ_WRITE, n4 * 16)
    chase = cl.Kernel(prg, "chase")
    chase.set_args(d_next, d_out, np.int32(args.steps))
    stream = cl.Kernel(prg, "stream")
    stream.set_args(d_a, d_b)

    def run(case):
        t0 = time.perf_counter()
        if case in ("chase", "serial", "two_queues"):
            cl.enqueue_nd_range_kernel(q1, chase, (256,), (256,))
        if case in ("stream", "serial"):
            for _ in range(8):
                cl.enqueue_nd_range_kernel(q1, stream, (n4,), None)
        if case == "two_queues":
            for _ in range(8):
                cl.enqueue_nd_range_kernel(q2, stream, (n4,), None)
        q1.finish()
        q2.finish()
        return (time.perf_counter() - t0) * 1e3

    out = {"device": rt.name, "steps": args.steps, "mb": args.mb}
    for case in ("chase", "stream", "serial", "two_queues"):
        run(case)
        ms = statistics.median(run(case) for _ in range(args.repeats))
        out[f"{case}_ms"] = round(ms, 3)
        print(f"{case}: {ms:.3f} ms", flush=True)
    alone = out["chase_ms"] + out["stream_ms"]
    out["overlap"] = round((alone - out["two_queues_ms"]) / min(out["chase_ms"],
                                                               out["stream_ms"]), 3)
    print(f"two queues save {alone - out['two_queues_ms']:.3f} ms of the shorter kernel's "
          f"{min(out['chase_ms'], out['stream_ms']):.3f} (overlap {out['overlap']:.2f}; "
          "1 = fully hidden, 0 = none)")
    d = Path(args.out)
    d.mkdir(parents=True, exist_ok=True)
    (d / "queue_concurrency.json").write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
