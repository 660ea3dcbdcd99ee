"""The one frame loop: water moves between frames, and per frame only the RGBA8 image and a
handful of scalars cross between host and device (DESIGN.md "One frame")."""

import numpy as np
import pytest

from app.scene import parse_scene
from app.world import World

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
    h0 = world.water_fields()["h"].copy()
    for _ in range(3):
        img = world.frame(0.1)
    assert world.sim_time > 0 and not np.allclose(world.water_fields()["h"], h0)
    assert np.abs(img.astype(int) - first.astype(int)).max() > 4, "the picture should change"
    assert np.isfinite(world.read_radiance()).all()
    assert world.stats.frame == 3
    assert world.stats.stage_ms.get("render.trace", 0) > 0 and "lbm.step" in world.stats.stage_ms


def test_inputs_reach_the_water_at_the_next_frame(world):
    world.frame(0.0)
    h0 = world.water_fields()["h"]
    world.add_drop(0.3, 0.3, 0.1, 0.02)
    assert np.array_equal(world.water_fields()["h"], h0), "queued, not applied yet"
    world.frame(0.0)
    h1 = world.water_fields()["h"]
    assert h1[7, 7] > h0[7, 7] + 0.01
    world.push(0.5, 0.5, 0.2, 0.0, 0.2)
    world.frame(0.0)
    assert world.water_fields()["u"][12, 12] > 0.05


def test_bad_inputs_are_one_line_errors(world):
    from app.errors import InputError

    with pytest.raises(InputError, match="rain rate"):
        world.set_rain(-1)
    with pytest.raises(InputError, match="target equals eye"):
        world.set_camera((0, 1, 0), (0, 1, 0))
    with pytest.raises(InputError, match="seconds"):
        world.frame(float("nan"))
    with pytest.raises(InputError, match="no frame in flight"):
        world.read_frame()
