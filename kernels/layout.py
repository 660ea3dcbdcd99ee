"""Proving a device struct's layout: sizeof and offsetof read off the device itself.

Each struct is declared once in a ``kernels/*.h`` header and mirrored by one NumPy dtype; tests
call :func:`check_struct` to compare the two on the device in use.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from kernels.runtime import KERNEL_DIR, Runtime


def device_layout(rt: Runtime, header: str, struct: str, fields: list[str]
                  ) -> tuple[int, dict[str, int]]:
    """``(sizeof(struct), {field: offsetof(struct, field)})`` as the device compiler sees it."""
    lines = [f'#include "{header}"',
             "__kernel void probe(__global ulong* out) {",
             f"  out[0] = sizeof({struct});"]
    lines += [f"  out[{i + 1}] = (ulong)&((({struct}*)0)->{f});" for i, f in enumerate(fields)]
    lines.append("}")
    prg = cl.Program(rt.context, "\n".join(lines)).build(options=[f"-I{KERNEL_DIR}"])
    out = np.zeros(len(fields) + 1, np.uint64)
    buf = cl.Buffer(rt.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg.probe(rt.queue, (1,), None, buf)
    cl.enqueue_copy(rt.queue, out, buf)
    return int(out[0]), {f: int(out[i + 1]) for i, f in enumerate(fields)}


def check_struct(rt: Runtime, header: str, struct: str, dtype: np.dtype) -> None:
    """Raise AssertionError naming the field when ``dtype`` and the device struct differ."""
    dtype = np.dtype(dtype)
    size, offsets = device_layout(rt, header, struct, list(dtype.names))
    assert size == dtype.itemsize, f"sizeof({struct}) = {size} on device, dtype {dtype.itemsize}"
    for name in dtype.names:
        got, want = offsets[name], dtype.fields[name][1]
        assert got == want, f"offsetof({struct}, {name}) = {got} on device, dtype {want}"
