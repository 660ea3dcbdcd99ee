"""kernels/video_yuv.cl: RGBA8 -> yuv420p against a float64 BT.601 limited-range reference
(within one code, the fixed point differing only next to a .5 boundary) and bit for bit against
its NumPy twin, at an even and an odd size (odd: the last column/row's chroma)."""

import numpy as np
import pytest

from kernels.video_yuv import MATRIX, OFFSET, YuvConverter, plane_shapes, rgba_to_yuv420p


def _reference(rgba: np.ndarray) -> tuple:
    """Y, U, V planes in float64 (unrounded): chroma from the mean RGB of each 2x2 block, the
    last column/row repeated at odd sizes."""
    rgb = rgba[..., :3].astype(np.float64)
    y = OFFSET[0] + rgb @ MATRIX[0] / 255.0
    h, w = rgb.shape[:2]
    p = np.pad(rgb, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
    mean = (p[0::2, 0::2] + p[0::2, 1::2] + p[1::2, 0::2] + p[1::2, 1::2]) / 4.0
    return y, OFFSET[1] + mean @ MATRIX[1] / 255.0, OFFSET[2] + mean @ MATRIX[2] / 255.0


def _image(w: int, h: int) -> np.ndarray:
    rng = np.random.default_rng(w * 1000 + h)
    img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    img[0, :3] = [[0, 0, 0, 255], [255, 255, 255, 255], [255, 0, 0, 0]][: min(3, w)]
    return img


@pytest.mark.parametrize("size", [(38, 22), (37, 21)])
def test_device_planes_match_the_float64_reference_and_the_numpy_twin(rt, size):
    w, h = size
    img = _image(w, h)
    conv = YuvConverter(rt, w, h)
    src = rt.to_device(img)
    conv.enqueue(src)
    got = rt.to_host(conv.yuv, np.uint8, conv.nbytes)
    assert np.array_equal(got, rgba_to_yuv420p(img))
    (yh, yw), (ch, cw) = plane_shapes(w, h)
    assert (ch, cw) == ((h + 1) // 2, (w + 1) // 2)
    y = got[: yh * yw].reshape(yh, yw).astype(int)
    u = got[yh * yw: yh * yw + ch * cw].reshape(ch, cw).astype(int)
    v = got[yh * yw + ch * cw:].reshape(ch, cw).astype(int)
    for plane, ref in zip((y, u, v), _reference(img), strict=True):
        exact = np.floor(ref + 0.5)
        assert np.abs(plane - exact).max() <= 1
        near_half = np.abs(ref - np.floor(ref) - 0.5) < 0.01
        assert np.array_equal(plane[~near_half], exact[~near_half])
    assert y[0, 0] == 16 and y[0, 1] == 235, "black and white at the limited-range ends"
    assert (y.min(), y.max()) >= (16, 16) and y.max() <= 235
    assert u.min() >= 16 and u.max() <= 240 and v.min() >= 16 and v.max() <= 240
    if w % 2:   # the last chroma column comes from the last pixel column alone
        col = img[:, -1, :3].astype(float)
        col = np.pad(col, ((0, h % 2), (0, 0)), mode="edge")
        mean = (col[0::2] + col[1::2]) / 2.0
        assert np.abs(u[:, -1] - np.floor(128 + mean @ MATRIX[1] / 255 + 0.5)).max() <= 1
