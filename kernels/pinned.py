"""Non-blocking reads into pinned host memory: a small ring of mapped ``ALLOC_HOST_PTR`` buffers.

A read is queued (``enqueue_read``) and returns a :class:`ReadHandle` at once; the host collects
it later (a frame late) with ``handle.wait()``. Each slot is one device-visible host allocation
mapped once at creation (drivers copy into it by DMA, without a staging copy); ``slots`` reads
may be in flight, the next one reuses the oldest slot, and a handle whose slot was reused refuses
to read rather than return another frame's bytes.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime


class StaleReadError(RuntimeError):
    """A :class:`ReadHandle` was read after its pinned slot was reused by a later read."""


class ReadHandle:
    """One queued read: ``event`` completes when ``array`` holds the bytes."""

    __slots__ = ("event", "_ring", "_slot", "_gen")

    def __init__(self, event: cl.Event, ring: PinnedRing, slot: int, gen: int):
        self.event, self._ring, self._slot, self._gen = event, ring, slot, gen

    @property
    def valid(self) -> bool:
        """False once a later read reused this handle's slot."""
        return self._ring._gens[self._slot] == self._gen

    def ready(self) -> bool:
        """Whether the copy has finished (never waits)."""
        return self.event.command_execution_status == cl.command_execution_status.COMPLETE

    @property
    def array(self) -> np.ndarray:
        """The pinned host array (complete once ``event`` is; valid until the slot's reuse)."""
        if not self.valid:
            raise StaleReadError(f"pinned read slot {self._slot} was reused by a later read: "
                                 f"read a handle before {len(self._ring._arrays)} more reads")
        return self._ring._arrays[self._slot]

    def wait(self) -> np.ndarray:
        """Wait for the copy and return the pinned array (copy it to keep it past the slot's
        reuse)."""
        self.event.wait()
        return self.array


class PinnedRing:
    """``slots`` pinned host arrays of ``shape``/``dtype`` (``nbytes`` each), mapped once."""

    def __init__(self, rt: Runtime, nbytes: int, dtype, shape: tuple, slots: int = 2):
        dtype = np.dtype(dtype)
        if int(np.prod(shape)) * dtype.itemsize != nbytes:
            raise ValueError(f"PinnedRing: shape {shape} of {dtype} is not {nbytes} bytes")
        if slots < 1:
            raise ValueError(f"PinnedRing needs at least one slot, got {slots}")
        mf = cl.mem_flags
        self._bufs, self._arrays = [], []
        for _ in range(int(slots)):
            buf = cl.Buffer(rt.context, mf.READ_WRITE | mf.ALLOC_HOST_PTR, max(int(nbytes), 4))
            arr, evt = cl.enqueue_map_buffer(rt.queue, buf, cl.map_flags.READ | cl.map_flags.WRITE,
                                             0, shape, dtype)
            evt.wait()
            self._bufs.append(buf)   # the mapping stays for the ring's life
            self._arrays.append(arr)
        self._gens = [0] * len(self._arrays)
        self._next = 0

    @property
    def slots(self) -> int:
        return len(self._arrays)

    def enqueue_read(self, queue: cl.CommandQueue, src: cl.Buffer, src_offset: int = 0,
                     wait_for=None) -> ReadHandle:
        """Queue a copy of ``src`` (from byte ``src_offset``) into the next slot, after the
        events ``wait_for``; no wait."""
        slot = self._next
        self._next = (slot + 1) % len(self._arrays)
        self._gens[slot] += 1
        evt = cl.enqueue_copy(queue, self._arrays[slot], src, src_offset=src_offset,
                              is_blocking=False, wait_for=wait_for)
        return ReadHandle(evt, self, slot, self._gens[slot])
