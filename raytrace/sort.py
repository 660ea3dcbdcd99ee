"""Device sorts of (uint32 key, uint32 value) pairs for the LBVH builder.

* :class:`RadixSorter`: least-significant-digit radix sort, 4 bits per pass, three launches per
  pass (``kernels/sort_radix.cl``), scratch allocated once. Measured against
  ``pyopencl.algorithm.RadixSort`` by ``lbwater bench bvh`` (see BENCHMARKS.md).
* :class:`LocalSorter`: one work-group bitonic sort in local memory for n <= 2048 (one launch),
  used for the TLAS and small meshes.

Both sort ``keys``/``vals`` in place, are stable for values 0..n-1 given in order (which is how
the builder uses them), and only enqueue work: no host synchronisation.
"""

from __future__ import annotations

import enum

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime

RADIX_BITS = 4
RADIX_WG = 256
RADIX_ITEMS = 8
RADIX_TILE = RADIX_WG * RADIX_ITEMS
SCAN_WG = 256
LOCAL_MAX = 2048
LOCAL_WG = 256


class SortMethod(enum.IntEnum):
    """How the builder sorts its Morton keys."""

    AUTO = 0    #: local for n <= 2048, radix above
    RADIX = 1   #: always the multi-pass radix sort
    LOCAL = 2   #: the one-work-group sort (n <= 2048 only)

    @classmethod
    def from_str(cls, name: str) -> SortMethod:
        try:
            return cls[name.strip().upper()]
        except KeyError:
            valid = ", ".join(m.name.lower() for m in cls)
            raise ValueError(f"sort method {name!r} is unknown; valid: {valid}") from None


class LocalSorter:
    """Sorts ``n <= 2048`` pairs in one launch (bitonic network in local memory)."""

    def __init__(self, rt: Runtime, keys: cl.Buffer, vals: cl.Buffer, n: int, *,
                 stage: str = "sort"):
        if not 0 <= n <= LOCAL_MAX:
            raise ValueError(f"LocalSorter sorts at most {LOCAL_MAX} pairs, got n={n}")
        self.rt, self.n, self.stage = rt, int(n), stage
        self._k = cl.Kernel(rt.program("sort_local.cl"), "sort_local_pairs")
        self._k.set_args(np.uint32(n), keys, vals)

    def enqueue(self) -> None:
        if self.n > 1:
            self.rt.launch(self.stage, self._k, LOCAL_WG, LOCAL_WG)


class RadixSorter:
    """Sorts ``n`` pairs by the low ``key_bits`` bits of the key, in place.

    ``ceil(key_bits / 4)`` passes ping-pong between the caller's buffers and one scratch pair;
    an odd pass count ends with one copy back. Kernel objects are made and bound once per pass.
    """

    def __init__(self, rt: Runtime, keys: cl.Buffer, vals: cl.Buffer, n: int, *,
                 key_bits: int = 32, stage: str = "sort"):
        if not 1 <= key_bits <= 32:
            raise ValueError(f"key_bits must lie in [1, 32], got {key_bits}")
        self.rt, self.n, self.stage = rt, int(n), stage
        self.keys, self.vals = keys, vals
        self.n_tiles = max(1, -(-self.n // RADIX_TILE))
        self.passes = -(-key_bits // RADIX_BITS)
        self._alt_keys = rt.buffer(4 * self.n)
        self._alt_vals = rt.buffer(4 * self.n)
        self._counts = rt.buffer(4 * (1 << RADIX_BITS) * self.n_tiles)
        # one work-group scans all tile counts: as wide as the device allows on a GPU
        self.scan_wg = SCAN_WG if not rt.is_gpu else min(1024, rt.device.max_work_group_size)
        prg = rt.program("sort_radix.cl", {"SCAN_WG": self.scan_wg})
        self._scan = cl.Kernel(prg, "radix_scan")
        self._scan.set_args(np.uint32((1 << RADIX_BITS) * self.n_tiles), self._counts)
        self._passes = []
        src = (keys, vals)
        dst = (self._alt_keys, self._alt_vals)
        for p in range(self.passes):
            shift = np.uint32(RADIX_BITS * p)
            hist = cl.Kernel(prg, "radix_histogram")
            hist.set_args(np.uint32(self.n), shift, src[0], self._counts, np.uint32(self.n_tiles))
            scat = cl.Kernel(prg, "radix_scatter")
            scat.set_args(np.uint32(self.n), shift, src[0], src[1], dst[0], dst[1], self._counts,
                          np.uint32(self.n_tiles))
            self._passes.append((hist, scat))
            src, dst = dst, src
        self._result_in_alt = self.passes % 2 == 1

    def enqueue(self) -> None:
        if self.n <= 1:
            return
        rt, gs = self.rt, self.n_tiles * RADIX_WG
        for hist, scat in self._passes:
            rt.launch(self.stage, hist, gs, RADIX_WG)
            rt.launch(self.stage, self._scan, self.scan_wg, self.scan_wg)
            rt.launch(self.stage, scat, gs, RADIX_WG)
        if self._result_in_alt:
            for a, b in ((self._alt_keys, self.keys), (self._alt_vals, self.vals)):
                rt.record(self.stage, cl.enqueue_copy(rt.queue, b, a, byte_count=4 * self.n))


def make_sorter(rt: Runtime, keys: cl.Buffer, vals: cl.Buffer, n: int, *, key_bits: int = 32,
                method: SortMethod = SortMethod.AUTO, stage: str = "sort"):
    """The sorter for ``n`` pairs: :class:`LocalSorter` when it fits (AUTO/LOCAL), else radix."""
    if method == SortMethod.LOCAL or (method == SortMethod.AUTO and n <= LOCAL_MAX):
        return LocalSorter(rt, keys, vals, n, stage=stage)
    return RadixSorter(rt, keys, vals, n, key_bits=key_bits, stage=stage)
