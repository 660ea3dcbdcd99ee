"""Measured device copy bandwidth, the denominator of every "% of ceiling" figure."""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime


def measure_copy_bandwidth(rt: Runtime, nbytes: int = 256 << 20, reps: int = 10) -> dict:
    """Read + write bytes per second of a device-to-device copy, median of ``reps`` after a warm-up.

    Two figures: ``enqueue_copy`` (the driver's copy) and ``copy_float4`` (a plain kernel with
    16-byte accesses). Each counts ``2 * nbytes`` moved per copy.
    """
    nbytes = min(int(nbytes), int(rt.device.max_mem_alloc_size) // 2) // 16 * 16
    n = nbytes // 16
    src = rt.buffer(nbytes)
    dst = rt.buffer(nbytes)
    cl.enqueue_fill_buffer(rt.queue, src, np.float32(1.0), 0, nbytes)
    kern = rt.kernel_launcher("bandwidth.cl", "copy_float4", stage="bandwidth.copy_kernel")
    kern.bind(src=src, dst=dst, n=n).set_size(n)
    result = {"bytes": nbytes}
    for label, enqueue in (
        ("enqueue_copy", lambda: cl.enqueue_copy(rt.queue, dst, src, byte_count=nbytes)),
        ("copy_kernel", kern),
    ):
        enqueue().wait()
        times = []
        for _ in range(reps):
            evt = enqueue()
            evt.wait()
            times.append((evt.profile.end - evt.profile.start) * 1e-9)
        t = float(np.median(times))
        result[f"{label}_GBps"] = 2 * nbytes / t / 1e9
    result["GBps"] = max(result["enqueue_copy_GBps"], result["copy_kernel_GBps"])
    return result
