"""Device sorts and Morton keys against NumPy references."""

import numpy as np
import pytest

from raytrace.bvh import Blas, vertices_to_float4
from raytrace.sort import FUSED_SCAN_MAX_TILES, RADIX_TILE, LocalSorter, RadixSorter


@pytest.mark.parametrize("n", [1, 2, 3, 255, 2048, 2049, 70_000,
                               FUSED_SCAN_MAX_TILES * RADIX_TILE + 1])
def test_radix_sort_is_a_stable_sort(rt, n):
    rng = np.random.default_rng(n)
    keys = rng.integers(0, 2**32, n, dtype=np.uint64).astype(np.uint32)
    keys[rng.random(n) < 0.3] = 7            # many duplicates
    keys[: n // 10] = 0xFFFFFFFF             # the padding key itself
    vals = np.arange(n, dtype=np.uint32)
    sorters = [RadixSorter] + ([LocalSorter] if n <= 2048 else [])
    for cls in sorters:
        kb, vb = rt.to_device(keys), rt.to_device(vals)
        s = cls(rt, kb, vb, n)
        s.enqueue()
        order = np.argsort(keys, kind="stable")
        assert np.array_equal(rt.to_host(kb, np.uint32, n), keys[order]), cls.__name__
        assert np.array_equal(rt.to_host(vb, np.uint32, n), order), cls.__name__
    if n > FUSED_SCAN_MAX_TILES * RADIX_TILE:
        assert not s.fused_scan  # this size exercises the separate scan launch


def morton_reference(c, key_bits=32, max_axis_bits=21):
    """NumPy restatement of kernels/bvh_hierarchy.h morton_masks/morton_isotropic. The bit
    schedule is computed independently; the quantisation uses the device's float32 steps with a
    correctly rounded scale (at 21 bits per axis float64 would round the last bit differently)."""
    c = c.astype(np.float32)
    lo, hi = c.min(0), c.max(0)
    ext = np.maximum(hi - lo, np.float32(0))
    cell = ext.astype(np.float64)
    nb = [0, 0, 0]
    order = []
    for _ in range(key_bits):
        v = [cell[a] if nb[a] < max_axis_bits else 0.0 for a in range(3)]
        if max(v) <= 0:
            break
        a = int(np.argmax(v))  # first maximum: ties go to x, then y, then z
        order.append(a)
        cell[a] *= 0.5
        nb[a] += 1
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = [np.float32(2.0 ** nb[a] / np.float64(ext[a])) for a in range(3)]
        q = [np.clip(np.floor((c[:, a] - lo[a]) * scale[a]), 0, 2 ** nb[a] - 1).astype(np.uint64)
             if nb[a] else np.zeros(len(c), np.uint64) for a in range(3)]
    key = np.zeros(len(c), np.uint64)
    taken = [0, 0, 0]
    for a in order:
        bit = (q[a] >> np.uint64(nb[a] - 1 - taken[a])) & np.uint64(1)
        taken[a] += 1
        key = (key << np.uint64(1)) | bit
    return (key << np.uint64(key_bits - len(order))).astype(np.uint32), nb, order


def decode(keys, order, key_bits=32):
    """Per-axis cell indices back out of keys made with the bit schedule ``order``."""
    q = np.zeros((3, len(keys)), np.int64)
    for b, a in enumerate(order):
        q[a] = (q[a] << 1) | ((keys.astype(np.int64) >> (key_bits - 1 - b)) & 1)
    return q


@pytest.mark.parametrize("shape", ["cube", "flat", "line"])
def test_morton_keys_match_numpy(rt, shape):
    rng = np.random.default_rng(4)
    n = 4000
    # triangles whose three vertices coincide; the centroid in float32 as the device forms it
    p = rng.random((n, 3)).astype(np.float32)
    if shape == "flat":
        p[:, 1] *= 0.01
    if shape == "line":
        p[:, 1:] = 0.25
    v = np.repeat(p, 3, axis=0)
    t = np.arange(3 * n, dtype=np.uint32).reshape(n, 3)
    blas = Blas(rt, rt.to_device(vertices_to_float4(v)), rt.to_device(t), 3 * n, n)
    blas._reset_build()
    blas._bounds()
    blas._morton()
    got = rt.to_host(blas.keys, np.uint32, n)
    centroid = (p + p + p) * np.float32(1.0 / 3.0)
    want, nb, order = morton_reference(centroid)
    if rt.is_pocl:
        # IEEE float arithmetic on the CPU device: the very same keys
        assert np.array_equal(got, want)
    else:
        # Measured on NVIDIA's OpenCL (H100, 2026-11-23): at 21 bits per axis some points fall in
        # the neighbouring cell. The schedule is still exact and no point moves further than one
        # cell, which only changes which of two neighbours is sorted first.
        assert np.abs(decode(got, order) - decode(want, order)).max() <= 1
        assert np.mean(got == want) > 0.5
    if shape == "flat":
        assert nb[1] < nb[0] - 4 and nb[1] < nb[2] - 4   # the thin axis gets few bits
    if shape == "line":
        assert nb == [21, 0, 0]
