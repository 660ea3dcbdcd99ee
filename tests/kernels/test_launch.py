"""kernels.launch: arguments bound by name (device arg info and the source fallback), values
re-set only when their bytes change, launches timed under their stage."""

import re

import numpy as np
import pyopencl as cl
import pytest

from kernels import Runtime
from kernels.launch import (
    BUFFER,
    LOCAL,
    VALUE,
    Kernel,
    KernelArgError,
    device_kernel_args,
    parse_kernel_args,
)
from kernels.layout import check_struct
from kernels.runtime import KERNEL_DIR

#: Mirror of ProbeParams (kernels/launch_probe.h), 16 bytes.
PROBE_DTYPE = np.dtype([("scale", "<f4"), ("bias", "<f4"), ("count", "<u4"), ("sign", "<i4")])


def probe_params(scale, bias, count, sign):
    return np.array([(scale, bias, count, sign)], PROBE_DTYPE)[0]


def probe_reference(n, p, offset):
    """float64 reference of launch_probe."""
    i = np.arange(n, dtype=np.float64)
    out = np.zeros((n, 4))
    out[:, 0] = p["sign"] * (p["scale"] * i + p["bias"]) + offset[0]
    out[:, 1] = offset[1]
    out[:, 2] = p["count"]
    out[:, 3] = n
    return out


def test_probe_struct_layout(rt):
    check_struct(rt, "launch_probe.h", "ProbeParams", PROBE_DTYPE)


def run_probe(rt, k: Kernel, n, p, offset, ls=16):
    out = rt.buffer(16 * n)
    k.bind(out=out, p=p, offset=offset, n=n, scratch=cl.LocalMemory(4 * ls))
    k.launch(n, ls)
    return rt.to_host(out, np.float32, 4 * n).reshape(n, 4)


def test_bind_by_name_every_kind_and_stage_timing(rt):
    rt.timer.reset()
    k = rt.kernel_launcher("launch_probe.cl", "launch_probe", stage="test.probe")
    assert k.arg_names == ["out", "p", "offset", "n", "scratch"]
    assert [a.kind for a in k.args] == [BUFFER, VALUE, VALUE, VALUE, LOCAL]
    p = probe_params(0.5, 2.0, 7, -1)
    got = run_probe(rt, k, 37, p, (1.5, -3.0, 0, 0))
    np.testing.assert_allclose(got, probe_reference(37, p, (1.5, -3.0)), rtol=1e-6)
    # rebinding new values (a Python int for the uint, a new struct) takes effect
    p2 = probe_params(2.0, 0.0, 3, 1)
    got = run_probe(rt, k, 5, p2, np.array([0, 1, 0, 0], np.float32))
    np.testing.assert_allclose(got, probe_reference(5, p2, (0, 1)), rtol=1e-6)
    times = rt.timer.collect()
    assert set(times) == {"test.probe"}


def test_own_kernel_object_per_launcher(rt):
    a = rt.kernel_launcher("launch_probe.cl", "launch_probe", stage="a")
    b = rt.kernel_launcher("launch_probe.cl", "launch_probe", stage="b")
    assert a.kernel is not b.kernel  # two users never overwrite each other's arguments
    assert a.args is b.args          # the names are read once per program


def test_unknown_and_missing_names_list_the_valid_ones(rt):
    k = rt.kernel_launcher("launch_probe.cl", "launch_probe", stage="test.probe")
    with pytest.raises(KernelArgError, match=r"no argument 'outt'.*out, p, offset, n, scratch"):
        k.bind(outt=rt.buffer(16))
    k.bind(out=rt.buffer(16), n=1)
    with pytest.raises(KernelArgError, match=r"not bound: p, offset, scratch"):
        k.launch(1)
    with pytest.raises(KernelArgError, match="no launch size"):
        k.bind(p=probe_params(1, 0, 0, 1), offset=(0, 0, 0, 0),
               scratch=cl.LocalMemory(64))()


@pytest.mark.parametrize("name, value, rule", [
    ("out", np.uint32(3), "is a buffer"),
    ("n", -1, "cannot hold"),
    ("n", 2.5, "cannot hold"),
    ("n", None, "cannot hold"),
    ("p", np.uint32(3), "by value: give its NumPy record"),
    ("offset", (1.0, 2.0), "give 4 numbers"),
    ("scratch", 4, "local memory"),
])
def test_wrong_kind_of_value_is_refused(rt, name, value, rule):
    k = rt.kernel_launcher("launch_probe.cl", "launch_probe", stage="test.probe")
    with pytest.raises(KernelArgError, match=rule):
        k.bind(**{name: value})


class CountingKernel:
    """Stands in for the cl.Kernel to count set_arg calls."""

    def __init__(self, kernel):
        self.kernel, self.calls = kernel, []

    def set_arg(self, i, v):
        self.calls.append(i)
        self.kernel.set_arg(i, v)


def test_values_set_only_when_their_bytes_change(rt):
    k = rt.kernel_launcher("launch_probe.cl", "launch_probe", stage="test.probe")
    counter = CountingKernel(k.kernel)
    k.kernel = counter
    buf = rt.buffer(64)
    p = probe_params(1, 2, 3, 1)
    k.bind(out=buf, p=p, n=4)
    assert counter.calls == [0, 1, 3]
    k.bind(out=buf, p=probe_params(1, 2, 3, 1), n=np.uint32(4))  # same buffer, same bytes
    assert counter.calls == [0, 1, 3]
    k.bind(p=probe_params(1, 2, 4, 1), n=5, out=rt.buffer(64))
    assert counter.calls == [0, 1, 3, 1, 3, 0]


def test_a_record_changed_in_place_is_set_again_an_equal_scalar_is_not(rt):
    k = rt.kernel_launcher("launch_probe.cl", "launch_probe", stage="test.probe")
    counter = CountingKernel(k.kernel)
    k.kernel = counter
    recs = np.zeros(1, PROBE_DTYPE)
    k.bind(out=rt.buffer(16 * 4), p=recs[0], n=4, offset=(0, 0, 0, 0),
           scratch=cl.LocalMemory(64))
    assert counter.calls == [0, 1, 3, 2, 4]
    k.bind(p=recs[0], n=4, offset=(0, 0, 0, 0))      # same record bytes, same int: nothing
    assert counter.calls == [0, 1, 3, 2, 4]
    recs["count"] = 7                                 # the same record object, new bytes
    k.bind(p=recs[0], n=np.uint32(4))
    k.bind(n=True)                                    # == 1 but of another type: converted
    assert counter.calls == [0, 1, 3, 2, 4, 1, 3]
    k.bind(n=np.array(2))                             # a 0-d array (converted) in between...
    k.bind(n=True)                                    # ...so the equal bool is set again
    assert counter.calls == [0, 1, 3, 2, 4, 1, 3, 3, 3]
    k.kernel = counter.kernel
    k.launch(4, 16)
    k.launch(np.array([4]), 16)                       # unhashable sizes: converted each time
    got = rt.to_host(k._held[0], np.float32, 4 * 4).reshape(4, 4)
    assert got[0, 2] == 7 and got[0, 3] == 1


def test_set_size_prepares_rounded_sizes(rt):
    k = rt.kernel_launcher("launch_probe.cl", "launch_probe", stage="test.probe")
    k.set_size(37, 16)
    assert k.global_size == (48,) and k.local_size == (16,)
    out = rt.buffer(16 * 37)
    p = probe_params(1, 0, 1, 1)
    k.bind(out=out, p=p, offset=(0, 0, 0, 0), n=37, scratch=cl.LocalMemory(64))
    k()
    got = rt.to_host(out, np.float32, 4 * 37).reshape(37, 4)
    np.testing.assert_allclose(got, probe_reference(37, p, (0, 0)), rtol=1e-6)


# -- the source fallback ---------------------------------------------------------------------
#: Sources whose kernels need defines to build, with the ones the code uses.
DEFINES = {"sort_radix.cl": {"SCAN_WG": 256, "RADIX_BITS": 8}}


def all_kernels():
    for path in sorted(KERNEL_DIR.glob("*.cl")):
        text = re.sub(r"/\*.*?\*/|//[^\n]*", " ", path.read_text(), flags=re.S)
        for name in re.findall(r"\b__kernel\b[^;{}]*?\bvoid\s+(\w+)\s*\(", text):
            yield path.name, name


def test_parsed_signatures_equal_the_device_arg_info(rt):
    """The fallback reads every kernel of kernels/*.cl as the device does (names and kinds);
    macros such as SCENE_PARAMS and RENDER_GEOM_PARAMS expanded."""
    checked = 0
    for source, name in all_kernels():
        # the cooperative kernels exist in a TRACE_COOP=1 build (kernels/traverse_coop.h)
        defines = {**DEFINES.get(source, {}), **({"TRACE_COOP": 1} if name.endswith("_coop")
                                                 else {})}
        k = cl.Kernel(rt.program(source, defines or None), name)
        dev = device_kernel_args(k)
        assert dev is not None, "PoCL keeps argument info with -cl-kernel-arg-info"
        parsed = parse_kernel_args(source, name)
        assert [(a.name, a.kind) for a in parsed] == [(a.name, a.kind) for a in dev], name
        checked += 1
    assert checked >= 30
    assert "tlas_info" in [a.name for a in parse_kernel_args("render_trace.cl", "render_trace")]


def test_fallback_without_device_arg_info(rt):
    """A runtime built without -cl-kernel-arg-info: the device reports no names, the source
    parser supplies them, and the launch is still correct."""
    bare = Runtime(rt.device, kernel_arg_info=False)
    raw = cl.Kernel(bare.program("launch_probe.cl"), "launch_probe")
    assert device_kernel_args(raw) is None
    k = bare.kernel_launcher("launch_probe.cl", "launch_probe", stage="test.probe")
    assert k.arg_names == ["out", "p", "offset", "n", "scratch"]
    p = probe_params(3.0, -1.0, 9, 1)
    got = run_probe(bare, k, 20, p, (0.25, 0.5, 0, 0), ls=4)
    np.testing.assert_allclose(got, probe_reference(20, p, (0.25, 0.5)), rtol=1e-6)


def test_parse_errors_name_the_kernel():
    with pytest.raises(KernelArgError, match="no kernel named 'nope'"):
        parse_kernel_args("launch_probe.cl", "nope")
