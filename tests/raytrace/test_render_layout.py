"""Every renderer device struct has the layout of its NumPy mirror, on the device in use."""

import pytest

from kernels.layout import check_struct
from raytrace.render_types import STRUCTS


@pytest.mark.parametrize("header,struct,dtype", STRUCTS, ids=[s[1] for s in STRUCTS])
def test_struct_layout(rt, header, struct, dtype):
    check_struct(rt, header, struct, dtype)


def test_ray_is_48_bytes():
    from raytrace.render_types import RAY
    assert RAY.itemsize == 48
