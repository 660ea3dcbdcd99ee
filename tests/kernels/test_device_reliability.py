"""Device selection by vendor alias, the device fence each device gets, build failures and the
missing-platform case: each a one-line error or a checked fact."""

import numpy as np
import pyopencl as cl
import pytest

import kernels.device as device_mod
import kernels.runtime as runtime_mod
from kernels import DeviceError, KernelBuildError, Runtime, select_device
from kernels.device import ALIASES, cl_std_option, fence_kind


def test_pocl_alias_selects_pocls_device():
    dev = select_device("pocl")
    assert dev.platform.name == "Portable Computing Language"
    assert select_device("POCL").int_ptr == dev.int_ptr
    assert select_device("portable").int_ptr == dev.int_ptr


def test_every_alias_either_matches_or_names_the_choices():
    for alias in ALIASES:
        try:
            dev = select_device(alias)
        except DeviceError as exc:
            assert alias in str(exc) and "available" in str(exc) and "\n" not in str(exc)
        else:
            text = f"{dev.platform.name} {dev.platform.vendor} {dev.name}".lower()
            assert alias in text or any(t in text for t in ALIASES[alias])


def test_no_platform_is_one_line(monkeypatch):
    def none():
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(device_mod.cl, "get_platforms", none)
    with pytest.raises(DeviceError, match="no OpenCL platform found") as info:
        select_device()
    assert "\n" not in str(info.value)


def test_fence_the_compiler_saw_is_the_one_promised(rt):
    kind = fence_kind(rt.device)
    out = rt.buffer(12)
    k = rt.kernel("device_probe.cl", "device_probe")
    k.set_args(out)
    rt.launch("test.probe", k, 1)
    version, atomic_fence, membar = rt.to_host(out, np.int32, 3)
    assert atomic_fence == (kind == "atomic_fence")
    assert membar == (kind == "membar")
    std = cl_std_option(rt.device)
    assert version == {"-cl-std=CL1.2": 120, "-cl-std=CL2.0": 200, "-cl-std=CL3.0": 300}[std]
    if rt.is_pocl:  # PoCL 3+ has the acq_rel order and device scope features
        assert kind == "atomic_fence" and std == "-cl-std=CL3.0"


def test_build_failure_is_one_line_with_the_log_in_a_file(tmp_path, monkeypatch, rt):
    (tmp_path / "broken.cl").write_text("__kernel void k(__global float* x) { x[0] = yy; }\n")
    monkeypatch.setattr(runtime_mod, "KERNEL_DIR", tmp_path)
    with pytest.raises(KernelBuildError) as info:
        Runtime(rt.device).program("broken.cl")
    first = str(info.value).splitlines()[0]
    assert first.startswith("broken.cl: OpenCL build failed") and "build log: " in first
    log = first.split("build log: ")[1].rstrip(")")
    text = open(log).read()
    assert "yy" in text and "broken.cl" in text
