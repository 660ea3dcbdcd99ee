"""Device sorts of (uint32 key, uint32 value) pairs for the LBVH builder.

* :class:`RadixSorter`: least-significant-digit radix sort, 8 or 4 bits per pass, three launches
  per pass, two when the input has at most 256 tiles (``kernels/sort_radix.cl``), scratch
  allocated once. Measured against ``pyopencl.algorithm.RadixSort`` by ``lbwater bench bvh`` (see
  BENCHMARKS.md).
* :class:`LocalSorter`: one work-group bitonic sort in local memory for n <= 2048 (one launch),
  used for the TLAS and small meshes.

Both sort ``keys``/``vals`` in place, are stable for values 0..n-1 given in order (which is how
the builder uses them), and only enqueue work: no host synchronisation.
"""

from __future__ import annotations

import enum

import pyopencl as cl

from kernels.runtime import Runtime

#: Digit widths the kernels support; see :func:`default_radix_bits` for the choice.
RADIX_BITS_CHOICES = (4, 8)
RADIX_WG = 256
RADIX_ITEMS = 8
RADIX_TILE = RADIX_WG * RADIX_ITEMS
SCAN_WG = 256
LOCAL_MAX = 2048
LOCAL_WG = 256
#: Up to this many tiles the scatter sums the tile counts itself (no scan launch).
FUSED_SCAN_MAX_TILES = 256


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
        self._launch = rt.kernel_launcher("sort_local.cl", "sort_local_pairs", stage=stage)
        self._launch.bind(n=n, keys=keys, vals=vals).set_size(LOCAL_WG, LOCAL_WG)

    def enqueue(self) -> None:
        if self.n > 1:
            self._launch()


def n_tiles(n: int) -> int:
    """Tiles (work-groups) a radix pass over ``n`` keys uses."""
    return max(1, -(-int(n) // RADIX_TILE))


def default_radix_bits(n: int, gpu: bool = True) -> int:
    """8-bit digits (half the passes, so half the launches) on a CPU device, and on a GPU while
    the scatter sums the tile counts itself; 4-bit on a GPU above that, where the scan over 256
    counts per tile costs more than the passes it saves (both measured in BENCHMARKS.md)."""
    return 8 if not gpu or n_tiles(n) <= FUSED_SCAN_MAX_TILES else 4


class RadixSorter:
    """Sorts ``n`` pairs by the low ``key_bits`` bits of the key, in place.

    ``ceil(key_bits / radix_bits)`` passes ping-pong between the caller's buffers and one scratch
    pair; an odd pass count ends with one copy back. ``radix_bits``: 4 or 8 bits per pass, None
    for :func:`default_radix_bits` on this device. Kernel objects are made and bound once per pass.
    """

    def __init__(self, rt: Runtime, keys: cl.Buffer, vals: cl.Buffer, n: int, *,
                 key_bits: int = 32, radix_bits: int | None = None, stage: str = "sort"):
        if not 1 <= key_bits <= 32:
            raise ValueError(f"key_bits must lie in [1, 32], got {key_bits}")
        if radix_bits is None:
            radix_bits = default_radix_bits(n, rt.is_gpu)
        if radix_bits not in RADIX_BITS_CHOICES:
            raise ValueError(f"radix_bits must be one of {RADIX_BITS_CHOICES}, got {radix_bits}")
        self.rt, self.n, self.stage = rt, int(n), stage
        self.keys, self.vals = keys, vals
        self.radix_bits = int(radix_bits)
        self.n_tiles = n_tiles(self.n)
        self.passes = -(-key_bits // self.radix_bits)
        self._alt_keys = rt.buffer(4 * self.n)
        self._alt_vals = rt.buffer(4 * self.n)
        n_counts = (1 << self.radix_bits) * self.n_tiles
        self._counts = rt.buffer(4 * n_counts)
        # one work-group scans all tile counts: as wide as the device allows on a GPU
        self.scan_wg = SCAN_WG if not rt.is_gpu else min(1024, rt.device.max_work_group_size)
        defines = {"SCAN_WG": self.scan_wg, "RADIX_BITS": self.radix_bits}

        def kernel(name):
            return rt.kernel_launcher("sort_radix.cl", name, stage=stage, defines=defines)

        self.fused_scan = self.n_tiles <= FUSED_SCAN_MAX_TILES
        self._scan = kernel("radix_scan").bind(len=n_counts, counts=self._counts)
        self._scan.set_size(self.scan_wg, self.scan_wg)
        self._passes = []
        gs = self.n_tiles * RADIX_WG
        src = (keys, vals)
        dst = (self._alt_keys, self._alt_vals)
        for p in range(self.passes):
            shift = self.radix_bits * p
            hist = kernel("radix_histogram").bind(n=self.n, shift=shift, keys=src[0],
                                                  counts=self._counts, n_tiles=self.n_tiles)
            scat = kernel("radix_scatter").bind(
                n=self.n, shift=shift, keys_in=src[0], vals_in=src[1], keys_out=dst[0],
                vals_out=dst[1], offsets=self._counts, n_tiles=self.n_tiles,
                fused=int(self.fused_scan))
            self._passes.append((hist.set_size(gs, RADIX_WG), scat.set_size(gs, RADIX_WG)))
            src, dst = dst, src
        self._result_in_alt = self.passes % 2 == 1

    def enqueue(self) -> None:
        if self.n <= 1:
            return
        rt = self.rt
        for hist, scat in self._passes:
            hist()
            if not self.fused_scan:
                self._scan()
            scat()
        if self._result_in_alt:
            for a, b in ((self._alt_keys, self.keys), (self._alt_vals, self.vals)):
                rt.record(self.stage, cl.enqueue_copy(rt.queue, b, a, byte_count=4 * self.n))


def make_sorter(rt: Runtime, keys: cl.Buffer, vals: cl.Buffer, n: int, *, key_bits: int = 32,
                method: SortMethod = SortMethod.AUTO, radix_bits: int | None = None,
                stage: str = "sort"):
    """The sorter for ``n`` pairs: :class:`LocalSorter` when it fits (AUTO/LOCAL), else radix."""
    if method == SortMethod.LOCAL or (method == SortMethod.AUTO and n <= LOCAL_MAX):
        return LocalSorter(rt, keys, vals, n, stage=stage)
    return RadixSorter(rt, keys, vals, n, key_bits=key_bits, radix_bits=radix_bits, stage=stage)
