"""RGBA8 -> planar yuv420p for the video encoder (``kernels/video_yuv.cl``), and its NumPy twin.

BT.601 limited range (ffmpeg's default matrix for rgb -> yuv420p, so colours stay as they were
when ffmpeg converted), chroma the mean of each 2x2 block (the last column/row repeated at odd
sizes). Fixed-point integers: the device stage and :func:`rgba_to_yuv420p` give the same bytes,
so a video is the same whether the planes came from the device or from host RGBA (the cluster
path, or capture with PNGs too). The capture reads back w*h*3/2 bytes a frame instead of w*h*4.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime

#: BT.601 limited range, R G B in 0..255 -> offset + row . (R, G, B) / 255.
MATRIX = np.array([[65.481, 128.553, 24.966],
                   [-37.797, -74.203, 112.0],
                   [112.0, -93.786, -18.214]])
OFFSET = np.array([16.0, 128.0, 128.0])
#: the kernel's fixed-point coefficients: round(MATRIX / 255 * 2^16)
FIXED = np.rint(MATRIX / 255.0 * 65536).astype(np.int64)
#: ffmpeg output options that tag the stream with this conversion
FFMPEG_TAGS = ["-colorspace", "smpte170m", "-color_range", "tv"]


def plane_shapes(width: int, height: int) -> tuple[tuple, tuple]:
    """(Y shape, U/V shape) as (rows, columns)."""
    return (height, width), ((height + 1) // 2, (width + 1) // 2)


def yuv_bytes(width: int, height: int) -> int:
    (h, w), (ch, cw) = plane_shapes(width, height)
    return h * w + 2 * ch * cw


def _blocks(rgba: np.ndarray) -> np.ndarray:
    """Per 2x2 block the int64 RGB sum (ch, cw, 3), the last column/row repeated at odd sizes."""
    h, w = rgba.shape[:2]
    p = np.pad(rgba[..., :3].astype(np.int64), ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
    return p[0::2, 0::2] + p[0::2, 1::2] + p[1::2, 0::2] + p[1::2, 1::2]


def rgba_to_yuv420p(rgba: np.ndarray) -> np.ndarray:
    """The device stage on the host, bit for bit: (h, w, 4) uint8 -> flat uint8 Y, U, V planes."""
    rgb = rgba[..., :3].astype(np.int64)
    y = (rgb @ FIXED[0] + (16 << 16) + 32768) >> 16
    s = _blocks(rgba)
    u = (s @ FIXED[1] + (128 << 18) + (1 << 17)) >> 18
    v = (s @ FIXED[2] + (128 << 18) + (1 << 17)) >> 18
    return np.concatenate([y.ravel(), u.ravel(), v.ravel()]).astype(np.uint8)


class YuvConverter:
    """The device stage: :meth:`enqueue` converts an RGBA8 buffer of ``width`` x ``height`` into
    :attr:`yuv` (:func:`yuv_bytes` bytes), timed as stage ``video.yuv``."""

    def __init__(self, rt: Runtime, width: int, height: int):
        self.rt, self.width, self.height = rt, int(width), int(height)
        self.nbytes = yuv_bytes(self.width, self.height)
        self.yuv = rt.buffer(self.nbytes)
        self._k = rt.kernel_launcher("video_yuv.cl", "rgba_to_yuv420p", stage="video.yuv")
        self._k.bind(yuv=self.yuv, width=np.int32(self.width), height=np.int32(self.height))
        _, (ch, cw) = plane_shapes(self.width, self.height)
        lw, lh = 16, 8
        self._k.set_size((-(-cw // lw) * lw, -(-ch // lh) * lh), (lw, lh))

    def enqueue(self, rgba: cl.Buffer) -> cl.Event:
        return self._k.bind(rgba=rgba)()   # re-bound only when another buffer comes
