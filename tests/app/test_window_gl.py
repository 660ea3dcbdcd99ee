"""The window's GL parts in a headless EGL context (no display): the image reaches the
framebuffer unchanged through both upload paths, and the HUD draws text over it."""

import numpy as np
import pytest

from app.hud import Hud
from app.window import Presenter


@pytest.fixture(scope="module")
def ctx(gl_ctx):
    return gl_ctx


@pytest.mark.parametrize("upload", ["pbo", "direct"])
def test_presented_image_is_the_frame_exactly_row_0_on_top(ctx, upload):
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (48, 64, 4), dtype=np.uint8)
    img[..., 3] = 255
    p = Presenter(ctx, upload)
    p.upload(img)
    np.testing.assert_array_equal(p.snapshot((64, 48)), img)
    img2 = img[::2, ::2].copy()             # a new size re-creates the texture
    p.upload(img2)
    np.testing.assert_array_equal(p.snapshot((32, 24)), img2)
    big = p.snapshot((64, 48))              # scaled up: linear filtering, same picture
    assert np.abs(big[::2, ::2].astype(int) - img2.astype(int)).mean() < 40
    with pytest.raises(ValueError, match="uint8"):
        p.upload(img.astype(np.float32))


class _Spy:
    """Wraps a moderngl object; records what its ``write`` was handed."""

    def __init__(self, obj, log):
        self._obj, self._log = obj, log

    def write(self, data, *a, **k):
        self._log.append(data)
        return self._obj.write(data._obj if isinstance(data, _Spy) else data, *a, **k)

    def __getattr__(self, name):
        return getattr(self._obj, name)

    def __setattr__(self, name, value):
        if name in ("_obj", "_log"):
            object.__setattr__(self, name, value)
        else:
            setattr(self._obj, name, value)


@pytest.mark.parametrize("upload", ["pbo", "direct"])
def test_upload_hands_the_callers_array_to_gl_and_consumes_it_spilled(ctx, upload):
    """No per-frame copy in Python: GL is handed the caller's array itself (the pinned
    read-back buffer in the window), and the texture holds its exact bytes even after the
    caller reuses the array (the next frame's read) right after upload returns; the pbo path
    alternates its two buffers."""
    rng = np.random.default_rng(5)
    frames = [rng.integers(0, 256, (24, 40, 4), dtype=np.uint8) for _ in range(3)]
    for f in frames:
        f[..., 3] = 255
    pinned = np.empty_like(frames[0])
    p = Presenter(ctx, upload)
    p.upload(pinned)                        # creates the texture (and buffers) at this size
    handed = []
    p.texture = _Spy(p.texture, handed)
    p.pbos = [_Spy(b, handed) for b in p.pbos]
    for f in frames:
        pinned[...] = f
        p.upload(pinned)
        pinned[...] = 0                     # the slot reused by the next read
        np.testing.assert_array_equal(p.snapshot((40, 24)), f)
    arrays = [a for a in handed if isinstance(a, np.ndarray)]
    assert len(arrays) == 3 and all(a is pinned for a in arrays)
    if upload == "pbo":
        bufs = [a._obj for a in handed if isinstance(a, _Spy)]
        assert len(bufs) == 3 and bufs[0] is not bufs[1] and bufs[0] is bufs[2]
    strided = np.zeros((24, 80, 4), np.uint8)[:, ::2]   # not contiguous: copied once, same image
    strided[...] = frames[0]
    p.upload(strided)
    np.testing.assert_array_equal(p.snapshot((40, 24)), frames[0])


def test_hud_draws_text_over_the_image_only_where_it_is(ctx):
    fbo = ctx.simple_framebuffer((200, 100), components=4)
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 1.0)
    hud = Hud(ctx)
    hud.draw([(["FPS 60.0", "grid 32x24"], 4, 4), (["help"], -4, -4)], (200, 100))
    px = np.frombuffer(fbo.read(components=4), np.uint8).reshape(100, 200, 4)[::-1]
    top_left, top_right = px[:40, :90, :3], px[:40, 130:, :3]
    assert top_left.max() > 200            # white glyphs
    assert top_right.max() == 0            # nothing drawn there
    assert px[-25:, -60:, :3].max() > 200  # the block anchored at the bottom-right
    fbo.release()
