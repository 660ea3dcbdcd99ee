"""Timeline ``boat`` entries: validated against the scene (one line naming file and entry), and
applied at the start of their frame through the World (lbm.bodies.Boats.place / release): a held
boat stays exactly where it was put, a released one falls, a boat placed with a velocity moves."""

import math
from pathlib import Path

import numpy as np
import pytest

from app.boats import rotation_matrix
from app.errors import InputError
from app.scene import load_scene, parse_scene
from app.timeline import Timeline
from lbm.bodies import quat_from_matrix
from tests.lbm.test_cmd_simulate import BOAT_SCENE, BOX_OBJ

SCENE = BOAT_SCENE + """
[camera]
eye = [0.8, 1.5, -1.5]
target = [0.8, 0.3, 0.5]
fov = 50
"""   # the boat is named "box" after its file


def _scene(tmp_path, timeline=""):
    (tmp_path / "box.obj").write_text(BOX_OBJ)
    path = tmp_path / "t.toml"
    path.write_text(SCENE + timeline)
    return load_scene(path)


def _error(tmp_path, timeline) -> str:
    with pytest.raises(InputError) as e:
        Timeline(_scene(tmp_path, timeline), 10)
    msg = str(e.value)
    assert "\n" not in msg and "t.toml" in msg
    return msg


def test_bad_boat_entries_are_one_line_errors(tmp_path):
    entry = "[[timeline]]\ntime = 1\nboat = {{ {} }}\n"
    assert "boat 'nope' is not in the scene (boats: box)" in _error(
        tmp_path, entry.format("name = 'nope', position = [0.5, 0.5]"))
    msg = _error(tmp_path, entry.format("name = 'box', position = [1.7, 0.5]"))
    assert "position (1.7, 0.5) m is outside the pool [0, 1.6] x [0, 1] m" in msg
    assert "time = 1" in msg
    assert "place needs a position" in _error(tmp_path, entry.format("name = 'box'"))
    assert "released but not held" in _error(
        tmp_path, entry.format("name = 'box', action = 'release'"))
    assert "release takes no position" in _error(
        tmp_path, entry.format("name = 'box', action = 'release', position = [1, 1]"))
    assert "unknown key 'speed'" in _error(
        tmp_path, entry.format("name = 'box', position = [1, 1], speed = 2"))


def test_boat_names_default_to_the_file_stem_and_must_differ():
    base = "[water]\nsize = [1.6, 1.0]\ncells = [8, 5]\ndepth = 0.3\n"
    root = Path(__file__).resolve().parents[2] / "scenes"
    boat = '[[boats]]\nfile = "sailboat_15k.obj"\nmass = 40.0\n'
    s = parse_scene(base + boat, root / "x.toml")
    assert [b.name for b in s.boats] == ["sailboat_15k"]
    s = parse_scene(base + boat + boat + 'name = "b"\n', root / "x.toml")
    assert [b.name for b in s.boats] == ["sailboat_15k_1", "b"]
    with pytest.raises(InputError, match="two boats are named 'b'"):
        parse_scene(base + boat + 'name = "b"\n' + boat + 'name = "b"\n', root / "x.toml")


def test_a_held_placement_lands_in_its_frame_and_a_release_lets_it_fall(tmp_path):
    from app.world import World

    scene = _scene(tmp_path, """
[[timeline]]
time = 0.25                  # frame 2 at 10 fps
boat = { name = "box", position = [0.5, 0.45], height = 0.15, heading = 90, hold = true }
[[timeline]]
time = 0.45                  # frame 4
boat = { name = "box", action = "release" }
[[timeline]]
time = 0.6                   # frame 6: afloat, moving along the pool's x
boat = { name = "box", position = [0.6, 0.5], velocity = [0.3, 0.0] }
""")
    tl = Timeline(scene, 10)
    assert [i for i in range(8) if tl.frame_inputs(i).boats] == [2, 4, 6]
    with World(scene, "cpu", width=16, height=12, spp=1) as world:
        start = world.boat_poses()[0][0].copy()
        keel = world.boats.hull(0).bottom
        level = world.boats.rest_position(0, 0.0, 0.0, 0.0)[1] + keel   # the still water
        poses = []
        for i in range(8):
            tl.apply(world, i)
            world.frame(0.1)
            pos, quat = world.boat_poses()
            poses.append((pos[0].copy(), quat[0].copy()))
    # frames 0, 1: where the scene put it (afloat, drifting at most a little)
    for i in (0, 1):
        assert np.abs(poses[i][0][[0, 2]] - start[[0, 2]]).max() < 0.02
    # frames 2, 3: held exactly over pool (0.5, 0.45), keel 0.15 m above the still water,
    # turned as [[boats]] rotation = [0, 90, 0] turns a boat
    want = np.array([0.5, level + 0.15 - keel, 0.45])
    q_want = quat_from_matrix(rotation_matrix((0.0, 90.0, 0.0)))
    for i in (2, 3):
        assert poses[i][0] == pytest.approx(want, abs=1e-5)
        assert poses[i][1] == pytest.approx(q_want, abs=1e-5)
    # frame 4: released, it falls through the air: 0.1 s of free fall is g t^2 / 2 = 4.9 cm
    drop = poses[3][0][1] - poses[4][0][1]
    assert 0.03 < drop < 0.06
    assert poses[4][0][[0, 2]] == pytest.approx(want[[0, 2]], abs=1e-3)
    # frame 6: put back afloat at (0.6, 0.5) moving at 0.3 m/s along x; heading kept
    assert poses[5][0][0] == pytest.approx(0.5, abs=0.01)
    x6 = poses[6][0][0]
    assert 0.6 + 0.01 < x6 < 0.6 + 0.04
    assert poses[6][1] == pytest.approx(poses[5][1], abs=0.02)
    assert math.isfinite(poses[7][0][1])


def test_the_snapshot_stepper_applies_boat_entries_too(tmp_path):
    """``capture --workers`` steps the water with World.snapshot_frame: the snapshot's
    transform rows carry the held boat where the frame loop puts it."""
    from app import snapshot
    from app.world import World

    scene = _scene(tmp_path, """
[[timeline]]
time = 0.15
boat = { name = "box", position = [0.5, 0.45], height = 0.15, hold = true }
""")
    tl = Timeline(scene, 10)
    rows = []
    for snap_mode in (False, True):
        with World(scene, "cpu", width=8, height=8, spp=1) as world:
            inst = next(k for k, v in world.instances.items() if v == "box.obj")
            row = world.render_scene.scene.transform_row(inst)
            before = world.render_scene.scene.read_transforms()[row]
            for i in range(3):
                tl.apply(world, i)
                if snap_mode:
                    snap = world.snapshot_frame(0.1)
                else:
                    world.frame(0.1)
            rows.append(world.render_scene.scene.read_transforms()[row])
            assert world.boat_poses()[0][0][[0, 2]] == pytest.approx((0.5, 0.45), abs=1e-6)
    assert np.array_equal(rows[0], rows[1])
    assert np.array_equal(snapshot.decode(snap).arrays["transforms"][row], rows[1])
    # the row moved with the boat: 0.3 m along -x, 0.05 m along -z (heading kept: R the same)
    assert rows[1][[0, 2], 3] - before[[0, 2], 3] == pytest.approx((-0.3, -0.05), abs=0.01)
