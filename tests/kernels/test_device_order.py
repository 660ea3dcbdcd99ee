"""The default device order: GPUs first, then PoCL with the newest PoCL first (pyopencl's
bundled PoCL 3.0 fails every build on CPUs its LLVM 14 predates; Debian's 3.1 does not)."""

import types

import pyopencl as cl

from kernels.device import _default_order, pocl_version


def fake(spec, platform, version, gpu=False):
    p = types.SimpleNamespace(name=platform, version=version)
    d = types.SimpleNamespace(type=cl.device_type.GPU if gpu else cl.device_type.CPU)
    return (spec, p, d)


def test_newest_pocl_first_after_gpus():
    old = fake("0:0", "Portable Computing Language", "OpenCL 3.0 PoCL 3.0-rc2  Linux, Release")
    new = fake("1:0", "Portable Computing Language", "OpenCL 3.0 PoCL 3.1+debian  Linux")
    other = fake("2:0", "Intel(R) OpenCL", "OpenCL 3.0 LINUX")
    gpu = fake("3:0", "NVIDIA CUDA", "OpenCL 3.0 CUDA 13.0.88", gpu=True)
    assert [c[0] for c in _default_order([old, new, other, gpu])] == ["3:0", "1:0", "0:0", "2:0"]
    assert [c[0] for c in _default_order([new, old])] == ["1:0", "0:0"]


def test_pocl_version_parses_the_platform_version():
    assert pocl_version(types.SimpleNamespace(version="OpenCL 3.0 PoCL 3.1+debian  Linux")) \
        == (3, 1)
    assert pocl_version(types.SimpleNamespace(version="OpenCL 3.0 PoCL 6.0  Linux")) == (6, 0)
    assert pocl_version(types.SimpleNamespace(version="OpenCL 3.0 CUDA 13.0.88")) == (0, 0)
