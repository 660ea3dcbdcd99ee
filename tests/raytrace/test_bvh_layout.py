"""Every BVH device struct matches its NumPy dtype (sizeof/offsetof read on the device)."""

import pytest

from kernels.layout import check_struct
from raytrace.bvh import HIT_DTYPE, INFO_DTYPE, INSTANCE_DTYPE, NODE_DTYPE, TRI_DTYPE


@pytest.mark.parametrize("header, struct, dtype, size", [
    ("bvh.h", "BvhNode", NODE_DTYPE, 64),
    ("bvh.h", "BvhTri", TRI_DTYPE, 48),
    ("bvh.h", "BvhInfo", INFO_DTYPE, 80),
    ("bvh.h", "Instance", INSTANCE_DTYPE, 64),
    ("scene.h", "Hit", HIT_DTYPE, 20),
])
def test_struct_layout(rt, header, struct, dtype, size):
    assert dtype.itemsize == size  # the sizes the docs and the memory budget quote
    check_struct(rt, header, struct, dtype)
