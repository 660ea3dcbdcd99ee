"""The one frame loop: water moves between frames, and per frame only the RGBA8 image and a
handful of scalars cross between host and device (DESIGN.md "One frame")."""

import numpy as np
import pyopencl as cl
import pytest

from app.scene import parse_scene
from app.world import World
from kernels import Runtime

SCENE = """
[render]
width = 32
height = 24
bounces = 2

[camera]
eye = [0.5, 1.6, 0.1]
target = [0.5, 0.0, 0.5]

[water]
size = [1.0, 1.0]
cells = [24, 24]
depth = 0.2

[[water.drops]]
x = 0.5
y = 0.5
radius = 0.15
height = 0.04

[[lights]]
kind = "directional"
direction = [-0.3, -1.0, 0.2]

[pool]
steps = 0
wall_height = 0.3
"""


@pytest.fixture
def world(rt, tmp_path):
    return World(parse_scene(SCENE, tmp_path / "w.toml"), rt)


def test_water_moves_between_frames_and_images_stay_finite(world):
    first = world.frame().copy()
    h0 = world.sim.fields()["h"].copy()
    for _ in range(3):
        img = world.frame(water_steps=world.steps_for(0.1))
    assert world.sim.time > 0 and not np.allclose(world.sim.fields()["h"], h0)
    assert np.abs(img.astype(int) - first.astype(int)).max() > 4, "the picture should change"
    assert np.isfinite(world.renderer.read_framebuffer()).all()
    assert world.frames == 4
    assert world.last_stage_ms.get("render.trace", 0) > 0 and "lbm.step" in str(world.last_stage_ms)


def test_frame_transfers_only_image_and_scalars(world, monkeypatch):
    world.frame(water_steps=1)  # first frame may upload tables and build layouts
    world.rt.finish()
    moved = []
    real_copy = cl.enqueue_copy

    def counting_copy(queue, dest, src, **kw):
        host = [a for a in (dest, src) if isinstance(a, np.ndarray)]
        if host:
            moved.append(host[0].nbytes)
        return real_copy(queue, dest, src, **kw)

    created = []
    real_buffer, real_to_device = Runtime.buffer, Runtime.to_device

    def counting_buffer(self, nbytes, *a, **kw):
        created.append(nbytes)
        return real_buffer(self, nbytes, *a, **kw)

    def counting_to_device(self, array, *a, **kw):
        created.append(array.nbytes)
        return real_to_device(self, array, *a, **kw)

    monkeypatch.setattr(cl, "enqueue_copy", counting_copy)
    monkeypatch.setattr(Runtime, "buffer", counting_buffer)
    monkeypatch.setattr(Runtime, "to_device", counting_to_device)
    for _ in range(3):
        world.frame(water_steps=2)
    image = 32 * 24 * 4
    per_frame = sum(moved) / 3
    assert created == [], "no device allocation inside a frame"
    assert image <= per_frame <= image + 2048, f"{moved}"
    assert max(b for b in moved if b != image) <= 512, "only scalars besides the image"
