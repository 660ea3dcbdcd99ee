"""The host never waits on the device inside ``World.enqueue_frame`` (only for the oldest frame
when ``frames_in_flight`` are queued): frames queued behind a long kernel return at once."""

import time

import numpy as np
import pyopencl as cl
import pytest

from app.scene import parse_scene
from app.world import World
from kernels.events import EventKeeper
from tests.app.test_frame_pipeline import TINY

_SPIN = """__kernel void spin(__global float *a, int n) {
    float x = a[0];
    for (int i = 0; i < n; i++) x = x * 0.9999999f + 1e-7f;
    a[0] = x;
}"""


def _spinner(rt, seconds: float):
    """A one-work-item kernel that keeps the in-order queue busy for about ``seconds``."""
    prg = cl.Program(rt.context, _SPIN).build()
    k = cl.Kernel(prg, "spin")
    buf = rt.to_device(np.ones(1, np.float32))
    n = 1 << 20
    while True:
        k.set_args(buf, np.int32(n))
        t0 = time.perf_counter()
        cl.enqueue_nd_range_kernel(rt.queue, k, (1,), (1,)).wait()
        dt = time.perf_counter() - t0
        if dt > 0.05 or n >= 1 << 30:
            break
        n *= 4
    k.set_args(buf, np.int32(min(int(n * seconds / dt), 2**31 - 1)))
    return lambda: cl.enqueue_nd_range_kernel(rt.queue, k, (1,), (1,)), buf


def test_frames_queued_behind_a_long_kernel_do_not_wait_for_it(tmp_path, rt):
    w = World(parse_scene(TINY, tmp_path / "tiny.toml"), rt, frames_in_flight=3)
    seconds = 3.5 * w.sim.dt   # LBM steps, a guard check and its read each frame
    for _ in range(3):
        w.frame(seconds)
    spin, _buf = _spinner(rt, 1.5)
    rt.finish()
    evt = spin()
    t0 = time.perf_counter()
    for i in range(3):       # each frame replaces the last one's reads and uploads
        w.set_camera((0.5 + 0.1 * i, 1.2, -0.2), (0.5, 0.0, 0.5))
        w.add_drop(0.5, 0.5, 0.1, 0.005)
        w.enqueue_frame(seconds)
    host = time.perf_counter() - t0
    running = evt.command_execution_status != cl.command_execution_status.COMPLETE
    for _ in range(3):
        _, img = w.read_frame()
        assert img[..., 3].min() == 255
    assert running, f"enqueue_frame waited for the device ({host * 1e3:.0f} ms on the host)"
    w.close()


def test_event_keeper_holds_copies_until_they_complete(rt):
    spin, _buf = _spinner(rt, 0.5)
    keep = EventKeeper(limit=4)
    host = np.zeros(4, np.float32)
    src = rt.to_device(np.arange(4, dtype=np.float32))
    first = spin()
    copies = [keep.keep(cl.enqueue_copy(rt.queue, host, src, is_blocking=False))
              for _ in range(3)]
    del copies
    assert len(keep) == 3   # none complete yet: all held, and the host did not wait
    assert first.command_execution_status != cl.command_execution_status.COMPLETE
    rt.queue.finish()
    keep.keep(None)
    keep.keep(cl.enqueue_copy(rt.queue, host, src, is_blocking=False))
    assert len(keep) <= 1 and host.tolist() in ([0, 1, 2, 3], [0, 0, 0, 0])
    rt.queue.finish()
    assert host.tolist() == [0, 1, 2, 3]


@pytest.mark.parametrize("limit", [2])
def test_event_keeper_is_bounded(rt, limit):
    keep = EventKeeper(limit=limit)
    host = np.zeros(1, np.float32)
    src = rt.to_device(np.ones(1, np.float32))
    for _ in range(5):
        keep.keep(cl.enqueue_copy(rt.queue, host, src, is_blocking=False))
    assert len(keep) <= limit
    keep.clear()
    assert len(keep) == 0 and host[0] == 1.0
