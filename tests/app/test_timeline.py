"""``[[timeline]]``: validated like every scene key (one line naming file, line and rule), and
turned into the right inputs for each frame: drops and rain in their frame, a drag spread over
its duration, camera keys passed through exactly and joined smoothly."""

from pathlib import Path

import numpy as np
import pytest

from app.errors import InputError
from app.scene import parse_scene
from app.timeline import Timeline

BASE = """
[camera]
eye = [0.0, 2.0, -3.0]
target = [0.0, 0.0, 0.0]
fov = 60

[water]
size = [2.0, 1.0]
cells = [20, 10]
depth = 0.3
"""


def _scene(extra: str):
    return parse_scene(BASE + extra, Path("t.toml"))


def _error(extra: str) -> str:
    with pytest.raises(InputError) as e:
        Timeline(_scene(extra), 10)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("t.toml")
    return msg


def test_bad_entries_are_one_line_errors():
    assert "exactly one of" in _error("[[timeline]]\ntime = 1\nrain = 3\ndrop = {x=1, y=0.5}\n")
    assert "exactly one of" in _error("[[timeline]]\ntime = 1\n")
    assert "out of range" in _error("[[timeline]]\ntime = -1\nrain = 3\n")
    msg = _error("[[timeline]]\ntime = 1\ndrop = { x = 1, y = 0.5, size = 2 }\n")
    assert "unknown key 'size'" in msg and "t.toml:" in msg
    assert "outside the pool" in _error("[[timeline]]\ntime = 1\ndrop = { x = 3, y = 0.5 }\n")
    assert "outside the pool" in _error(
        "[[timeline]]\ntime = 1\npush = { x = 1, y = 0.5, dx = 2, dy = 0 }\n")
    assert "boat 'b'" in _error("[[timeline]]\ntime = 1\nboat = { name = 'b' }\n")
    assert "target equals eye" in _error(
        "[[timeline]]\ntime = 1\ncamera = { eye = [1, 1, 1], target = [1, 1, 1] }\n")


def test_drops_and_rain_land_in_their_frames():
    tl = Timeline(_scene("""
[[timeline]]
time = 0.55
drop = { x = 1.0, y = 0.5, radius = 0.1, height = 0.02 }
[[timeline]]
time = 0.3
rain = 12.5
[[timeline]]
time = 0.9
rain = 0
"""), 10)
    got = {i: tl.frame_inputs(i) for i in range(12)}
    assert [i for i, f in got.items() if f.drops] == [5]
    assert got[5].drops == [(1.0, 0.5, 0.1, 0.02)]
    assert {i: f.rain for i, f in got.items() if f.rain is not None} == {3: 12.5, 9: 0.0}
    assert tl.duration == pytest.approx(0.9)


def test_a_drag_is_spread_over_its_duration():
    tl = Timeline(_scene("""
[[timeline]]
time = 0.2
push = { x = 0.2, y = 0.5, dx = 1.5, dy = 0.3, strength = 0.4, duration = 0.45 }
"""), 10)
    segs = [s for i in range(12) for s in tl.frame_inputs(i).pushes]
    assert len(segs) == 5                                     # frames 2..6 (0.2 .. 0.65 s)
    assert segs[0][:2] == pytest.approx((0.2, 0.5))
    assert sum(s[2] for s in segs) == pytest.approx(1.5)
    assert sum(s[3] for s in segs) == pytest.approx(0.3)
    for a, b in zip(segs, segs[1:], strict=False):           # contiguous: each starts where
        assert (b[0], b[1]) == pytest.approx((a[0] + a[2], a[1] + a[3]))   # the last ended


def test_camera_keys_are_passed_through_and_joined_smoothly():
    tl = Timeline(_scene("""
[[timeline]]
time = 0.0
camera = { eye = [0, 2, -3], target = [0, 0, 0], fov = 50 }
[[timeline]]
time = 1.0
camera = { eye = [3, 2, 0], target = [0, 0.2, 0], fov = 40 }
[[timeline]]
time = 3.0
camera = { eye = [0, 3, 3], target = [0, 0, 0] }
"""), 30)
    assert tl.camera_at(0.0)[0] == pytest.approx((0, 2, -3))
    assert tl.camera_at(1.0)[0] == pytest.approx((3, 2, 0))
    assert tl.camera_at(1.0)[3] == pytest.approx(40)
    assert tl.camera_at(3.0)[3] == pytest.approx(60)           # no fov: the scene's
    assert tl.camera_at(9.0) == tl.camera_at(3.0)              # the last key holds
    eps = 1e-5
    def vel(t):
        return (np.array(tl.camera_at(t + eps)[0]) - np.array(tl.camera_at(t - eps)[0])) / (2 * eps)
    left, right = vel(1.0 - 1e-3), vel(1.0 + 1e-3)
    assert np.abs(left - right).max() < 0.05 * np.abs(left).max()   # C1 at the inner key
    assert tl.frame_inputs(29).camera == tl.camera_at(1.0)     # frame i shows time (i+1)/fps


def test_the_shipped_timeline_scene_validates():
    from app.scene import load_scene

    root = Path(__file__).resolve().parents[2]
    scene = load_scene(root / "scenes" / "timeline.toml")
    tl = Timeline(scene, 30)
    kinds = {type(e).__name__ for e in scene.timeline}
    assert kinds == {"BoatEvent", "CameraKey", "Drop", "Push", "Rain"} and tl.duration >= 3.5
    assert [b.name for b in scene.boats] == ["sailboat"]
