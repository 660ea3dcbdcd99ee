"""Every BVH device struct matches its NumPy dtype (sizeof/offsetof read on the device)."""

import pytest

from kernels.layout import check_struct, device_layout
from raytrace.bvh import HIT_DTYPE, INFO_DTYPE, INSTANCE_DTYPE, NODE_DTYPE, TRI_DTYPE
from raytrace.bvh_wide import TRI_BLOCK_DTYPE, WIDE_INFO_DTYPE, WIDE_NODE_DTYPE


@pytest.mark.parametrize("header, struct, dtype, size", [
    ("bvh.h", "BvhNode", NODE_DTYPE, 64),
    ("bvh.h", "BvhTri", TRI_DTYPE, 48),
    ("bvh.h", "BvhInfo", INFO_DTYPE, 96),
    ("bvh.h", "Instance", INSTANCE_DTYPE, 64),
    ("scene.h", "Hit", HIT_DTYPE, 20),
    ("bvh.h", "WideNode", WIDE_NODE_DTYPE, 256),
    ("bvh.h", "TriBlock", TRI_BLOCK_DTYPE, 160),
    ("bvh.h", "WideInfo", WIDE_INFO_DTYPE, 272),
])
def test_struct_layout(rt, header, struct, dtype, size):
    assert dtype.itemsize == size  # the sizes the docs and the memory budget quote
    check_struct(rt, header, struct, dtype)


def _element_offset(dtype, field, index, lanes):
    """Byte offset of C element ``field[index...]`` whose items are vectors of ``lanes`` scalars
    (1: scalars), in the NumPy record: the sub-array's leading axes are the C array's."""
    sub, base = dtype.fields[field]
    shape = sub.shape[:-1] if lanes > 1 else sub.shape
    assert len(index) == len(shape) and (lanes == 1 or sub.shape[-1] == lanes)
    flat = 0
    for i, n in zip(index, shape, strict=True):
        flat = flat * n + i
    return base + flat * lanes * sub.base.itemsize


@pytest.mark.parametrize("struct, dtype, element, field, index, lanes", [
    ("WideNode", WIDE_NODE_DTYPE, "plane[1]", "plane", (1,), 8),  # plane[a]: a float8 across
    ("WideNode", WIDE_NODE_DTYPE, "plane[5]", "plane", (5,), 8),  # the 8 children
    ("TriBlock", TRI_BLOCK_DTYPE, "v[0][2]", "v", (0, 2), 4),     # v[vertex][axis]: a float4
    ("TriBlock", TRI_BLOCK_DTYPE, "v[2][1]", "v", (2, 1), 4),     # across the 4 lanes
    ("TriBlock", TRI_BLOCK_DTYPE, "v[1][0]", "v", (1, 0), 4),
    ("WideInfo", WIDE_INFO_DTYPE, "level_count[63]", "level_count", (63,), 1),
])
def test_wide_struct_element_order(rt, struct, dtype, element, field, index, lanes):
    """The NumPy sub-array axes are in the device's order ([vertex][axis] then lane, [plane]
    then child), not merely of the same size."""
    _, offsets = device_layout(rt, "bvh.h", struct, [element])
    assert offsets[element] == _element_offset(dtype, field, index, lanes)
