"""The device layer: selection, builds with includes/defines, kernel reuse, errors, timing."""

import numpy as np
import pyopencl as cl
import pytest

import kernels.runtime as runtime_mod
from kernels import DeviceError, KernelBuildError, Runtime, list_devices, select_device
from kernels.bandwidth import measure_copy_bandwidth


def test_default_device_exists_and_lists():
    infos = list_devices()
    assert infos, "PoCL (pocl-binary-distribution) should always provide a device"
    dev = select_device()
    assert any(i.name == dev.name.strip() for i in infos)
    assert all(":" in i.spec and i.compute_units > 0 for i in infos)


def test_select_by_type_and_index():
    cpu = select_device("cpu")
    assert cpu.type & cl.device_type.CPU
    assert select_device("0:0").name == cl.get_platforms()[0].get_devices()[0].name


def test_unknown_spec_names_value_and_choices(monkeypatch):
    with pytest.raises(DeviceError, match=r"no-such-gpu.*available"):
        select_device("no-such-gpu")
    monkeypatch.setenv("LBWATER_DEVICE", "nope")
    with pytest.raises(DeviceError, match="LBWATER_DEVICE='nope'"):
        select_device()


def test_pyopencl_ctx_is_honoured(monkeypatch):
    monkeypatch.delenv("LBWATER_DEVICE", raising=False)
    monkeypatch.setenv("PYOPENCL_CTX", "99:0")
    with pytest.raises(DeviceError, match="PYOPENCL_CTX"):
        select_device()


def test_kernel_lookup_is_cached_and_copy_is_exact(rt):
    rt.timer.reset()  # the session runtime carries other tests' events
    k1 = rt.kernel("bandwidth.cl", "copy_float4")
    assert rt.kernel("bandwidth.cl", "copy_float4") is k1
    src = np.random.default_rng(0).random(64 * 4, dtype=np.float32)
    d_src = rt.to_device(src)
    d_dst = rt.buffer(src.nbytes)
    rt.kernel_launcher("bandwidth.cl", "copy_float4", stage="test.copy").bind(
        src=d_src, dst=d_dst, n=64).launch(64, 16)
    assert np.array_equal(rt.to_host(d_dst, np.float32, src.size), src)
    times = rt.timer.collect()
    assert set(times) == {"test.copy"} and times["test.copy"] >= 0
    assert rt.timer.collect() == {}


def test_defines_are_part_of_the_cache_key(rt):
    a = rt.program("bandwidth.cl", {"FOO": 1})
    b = rt.program("bandwidth.cl", {"FOO": 2})
    assert a is not b and rt.program("bandwidth.cl", {"FOO": 1}) is a


def test_build_error_names_file_and_carries_log(tmp_path, monkeypatch, rt):
    (tmp_path / "broken.cl").write_text("__kernel void k(__global float* x) { x[0] = y; }\n")
    monkeypatch.setattr(runtime_mod, "KERNEL_DIR", tmp_path)
    fresh = Runtime(rt.device)
    with pytest.raises(KernelBuildError, match="broken.cl") as info:
        fresh.program("broken.cl")
    assert "y" in str(info.value) and "\n" in str(info.value)
    with pytest.raises(KernelBuildError, match="does not exist"):
        fresh.program("missing.cl")


def test_copy_bandwidth_is_positive(rt):
    bw = measure_copy_bandwidth(rt, nbytes=1 << 20, reps=2)
    assert bw["GBps"] > 0 and bw["bytes"] == 1 << 20


def test_includes_resolve_to_the_kernel_folder_not_the_cwd(tmp_path, monkeypatch, rt):
    (tmp_path / "common.h").write_text('#error "a stray common.h in the cwd was included"\n')
    monkeypatch.chdir(tmp_path)
    nonce = int.from_bytes(tmp_path.name.encode()[-4:], "little")
    Runtime(rt.device).program("bandwidth.cl", {"LBWATER_TEST_NONCE": nonce})


def test_stage_times_are_the_sums_of_their_kernels_times(rt):
    """StageTimer: per stage the sum of (END - START) of its events, interleaved stages kept
    apart, read from a completed frame without waiting and from one still queued."""
    from kernels.timing import StageTimer

    timer = StageTimer(max_frames=4)
    k = rt.kernel_launcher("launch_probe.cl", "launch_probe", stage="x")
    out = rt.buffer(16 * 256)
    probe = np.dtype([("scale", "<f4"), ("bias", "<f4"), ("count", "<u4"), ("sign", "<i4")])
    k.bind(out=out, p=np.zeros(1, probe)[0], offset=(0, 0, 0, 0), n=256,
           scratch=cl.LocalMemory(64))
    frames = []
    for tag in range(3):
        evts = []
        for i in range(7):
            e = cl.enqueue_nd_range_kernel(rt.queue, k.kernel, (256,), (16,))
            evts.append(("ab"[i % 3 == 0], timer.record("ab"[i % 3 == 0], e)))
        timer.close_frame(tag)
        frames.append(evts)
    rt.finish()
    got = timer.completed() + timer.completed(wait=True)
    assert [t for t, _ in got] == [0, 1, 2]
    for (_, ms), evts in zip(got, frames, strict=True):
        want = {}
        for stage, e in evts:
            want[stage] = want.get(stage, 0.0) + (e.profile.end - e.profile.start) * 1e-6
        assert ms == want and set(ms) == {"a", "b"}
    # each frame's device span: its first event's start to its last one's end (no overlap on
    # one in-order queue, so at least the sum of its kernels' times)
    for (tag, ms), evts in zip(got, frames, strict=True):
        span = timer.take_span_ms(tag)
        want = (max(e.profile.end for _, e in evts) - min(e.profile.start for _, e in evts)) * 1e-6
        assert span == want and span >= sum(ms.values()) * (1 - 1e-9) > 0
        assert timer.take_span_ms(tag) == 0.0   # taken once
    timer.record("a", cl.enqueue_nd_range_kernel(rt.queue, k.kernel, (256,), (16,)))
    timer.close_frame(3)
    assert set(timer.completed(wait=True)[0][1]) == {"a"}   # waited for the queued frame
