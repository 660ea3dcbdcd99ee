"""Counts host<->device bytes at pyopencl's lowest level.

Every host transfer pyopencl can make goes through one of the ``pyopencl._cl`` functions in
:data:`HOST_PATHS` (``enqueue_copy`` dispatches to them, ``pyopencl.array`` get/set use
``enqueue_copy``), through a map, or through a buffer made from a host array, which this project
makes only in :class:`kernels.runtime.Runtime` (a source scan in the tests holds that). Functions
of ``_cl`` that move bytes only on the device are listed in :data:`DEVICE_ONLY`; a function in
neither list fails :func:`check_complete`, so a path pyopencl adds is never silently missed.
"""

from __future__ import annotations

import contextlib

import numpy as np
import pyopencl as cl
import pyopencl._cl as _cl

#: pyopencl._cl functions that move host bytes, and the argument holding the host object.
HOST_PATHS = {
    "_enqueue_read_buffer": 2, "_enqueue_write_buffer": 2,
    "_enqueue_read_buffer_rect": 2, "_enqueue_write_buffer_rect": 2,
    "_enqueue_read_image": 2, "_enqueue_write_image": 2,
    "_enqueue_svm_memcpy": None, "_enqueue_svm_memfill": None, "_enqueue_svm_map": None,
    "_enqueue_fill_buffer": 2, "enqueue_fill_image": 2,
    "enqueue_map_buffer": None, "enqueue_map_image": None,
}

#: pyopencl._cl enqueue functions that move no host bytes.
DEVICE_ONLY = {
    "_enqueue_barrier", "_enqueue_barrier_with_wait_list", "_enqueue_copy_buffer",
    "_enqueue_copy_buffer_rect", "_enqueue_copy_buffer_to_image", "_enqueue_copy_image",
    "_enqueue_copy_image_to_buffer", "_enqueue_marker", "_enqueue_marker_with_wait_list",
    "_enqueue_svm_migrate_mem", "_enqueue_svm_unmap", "_enqueue_wait_for_events",
    "enqueue_copy_buffer_p2p_amd", "enqueue_migrate_mem_objects", "enqueue_nd_range_kernel",
    "device_device_enqueue_capabilities",
}


def enqueue_functions() -> set[str]:
    return {n for n in dir(_cl) if "enqueue" in n}


def check_complete() -> None:
    """Raise AssertionError naming any pyopencl enqueue function this counter does not know."""
    unknown = enqueue_functions() - set(HOST_PATHS) - DEVICE_ONLY
    assert not unknown, f"transfer paths the counter does not classify: {sorted(unknown)}"


def _nbytes(args, kwargs, index) -> int:
    objs = list(args) + list(kwargs.values())
    if index is not None and index < len(args):
        objs = [args[index]]
    for o in objs:
        if isinstance(o, np.ndarray | np.generic | bytes | bytearray | memoryview):
            return int(np.asarray(o).nbytes) if not isinstance(o, bytes | bytearray) else len(o)
    # maps: the mapped size (shape argument) counts as moved
    for o in objs:
        if isinstance(o, tuple) and o and all(isinstance(x, int | np.integer) for x in o):
            return int(np.prod(o))
    return 0


class TransferCounter:
    """``with TransferCounter() as c:`` ... ``c.bytes``, ``c.calls`` (name, bytes) and
    ``c.buffers`` (host-initialised buffers made through kernels.runtime.Runtime)."""

    def __init__(self):
        check_complete()
        self.calls: list[tuple[str, int]] = []
        self.buffers: list[int] = []

    @property
    def bytes(self) -> int:
        return sum(b for _, b in self.calls) + sum(self.buffers)

    def reset(self) -> None:
        self.calls.clear()
        self.buffers.clear()

    def __enter__(self):
        self._stack = contextlib.ExitStack()
        for name, index in HOST_PATHS.items():
            real = getattr(_cl, name)
            self._patch(_cl, name, self._wrap(name, real, index))
            if getattr(cl, name, None) is real:  # re-exported names (enqueue_map_buffer)
                self._patch(cl, name, getattr(_cl, name))
        from kernels.runtime import Runtime

        real_to_device, real_buffer = Runtime.to_device, Runtime.buffer
        counter = self

        def to_device(rt, array, *a, **kw):
            counter.buffers.append(int(np.asarray(array).nbytes))
            return real_to_device(rt, array, *a, **kw)

        def buffer(rt, nbytes, flags=cl.mem_flags.READ_WRITE):
            if flags & (cl.mem_flags.COPY_HOST_PTR | cl.mem_flags.USE_HOST_PTR):
                counter.buffers.append(int(nbytes))
            return real_buffer(rt, nbytes, flags)

        self._patch(Runtime, "to_device", to_device)
        self._patch(Runtime, "buffer", buffer)
        return self

    def _patch(self, owner, name, value) -> None:
        old = getattr(owner, name)
        setattr(owner, name, value)
        self._stack.callback(setattr, owner, name, old)

    def _wrap(self, name, real, index):
        def counted(*args, **kwargs):
            self.calls.append((name, _nbytes(args, kwargs, index)))
            return real(*args, **kwargs)
        return counted

    def __exit__(self, *exc):
        self._stack.close()
