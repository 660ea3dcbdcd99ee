"""Frame snapshots (app.snapshot, World.snapshot_frame / render_snapshot): a World that only
renders snapshots from another World that only steps gives, frame for frame and in any order,
the bytes the first World's own frames give (drops, rain, a camera move, caustics); snapshots of
another scene are refused; the codec round-trips and rejects what is not a snapshot."""

import numpy as np
import pytest

from app import snapshot
from app.scene import parse_scene
from app.timeline import Timeline
from app.world import World

SCENE = """
[render]
width = 40
height = 30
bounces = 2

[camera]
eye = [0.5, 0.6, -0.5]
target = [0.5, 0.0, 0.5]

[shading]
caustics = "{caustics}"
caustic_photons = 2048
caustic_resolution = 16
caustic_filter = 1
caustic_blend = 0.5

[water]
size = [1.0, 1.0]
cells = [20, 20]
depth = 0.2

[[lights]]
kind = "directional"
direction = [-0.3, -1.0, 0.2]

[pool]
steps = 0
wall_height = 0.3

[[timeline]]
time = 0.1
drop = {{ x = 0.5, y = 0.5, radius = 0.15, height = 0.06 }}

[[timeline]]
time = 0.2
rain = 40.0

[[timeline]]
time = 0.0
camera = {{ eye = [0.5, 0.6, -0.5], target = [0.5, 0.0, 0.5] }}

[[timeline]]
time = 0.8
camera = {{ eye = [1.2, 0.7, -0.3], target = [0.5, 0.0, 0.5], fov = 50 }}
"""
FPS, N = 10.0, 6


def _scene(tmp_path, caustics):
    return parse_scene(SCENE.format(caustics=caustics), tmp_path / "s.toml")


@pytest.mark.parametrize("caustics", ["off", "traced"])
def test_snapshots_rendered_elsewhere_in_any_order_equal_the_frames(tmp_path, rt, caustics):
    scene = _scene(tmp_path, caustics)
    tl = Timeline(scene, FPS)
    own, stepper = World(scene, rt, seed=3), World(scene, rt, seed=3)
    frames, snaps = [], []
    for i in range(N):
        tl.apply(own, i)
        frames.append(own.frame(1 / FPS))
        tl.apply(stepper, i)
        snaps.append(stepper.snapshot_frame(1 / FPS))
    assert [snapshot.peek(s)["frame"] for s in snaps] == list(range(N))
    assert snapshot.peek(snaps[-1])["sim_time"] == pytest.approx(own.sim_time)
    assert (snapshot.decode(snaps[-1]).caustics == "traced") == (caustics == "traced")
    # the water moved and the camera turned: frames differ, so equality below means something
    assert not np.array_equal(frames[0], frames[-1])
    assert not np.array_equal(frames[2], frames[3])

    painter = World(scene, rt, seed=3)
    assert painter.render_snapshot(snaps[0], image=False) is None
    for i in (4, 1, 5, 0, 3, 2, 5):
        img = painter.render_snapshot(snaps[i])
        assert img.shape == (30, 40, 4)
        assert np.array_equal(img, frames[i]), (i, np.abs(img.astype(int) - frames[i]).max())


def test_a_snapshot_of_another_scene_is_refused(tmp_path, rt):
    snap = World(_scene(tmp_path, "off"), rt).snapshot_frame(0.1)
    other = parse_scene(SCENE.format(caustics="off").replace("cells = [20, 20]",
                                                             "cells = [16, 16]"),
                        tmp_path / "o.toml")
    with pytest.raises(snapshot.SnapshotError, match="another scene"):
        World(other, rt).render_snapshot(snap)


def test_codec_round_trips_and_rejects_other_bytes():
    eta = np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4)
    rows = np.arange(24, dtype=np.float32).reshape(2, 3, 4)
    cam = ((1.0, 2.0, 3.0), (0.1, 0.2, 0.30000000000000004), (0.0, 1.0, 0.0), 47.5)
    b = snapshot.encode(frame=7, sim_time=0.7, lbm_steps=12, guard={"acted": True},
                        camera=cam, caustics="off", arrays={"eta": eta, "transforms": rows})
    s = snapshot.decode(b)
    assert (s.frame, s.sim_time, s.lbm_steps, s.camera, s.caustics) == (7, 0.7, 12, cam, "off")
    assert s.guard == {"nan": False, "acted": True, "report": "ok"}
    assert np.array_equal(s.arrays["eta"], eta) and s.arrays["eta"].dtype == np.float32
    assert np.array_equal(s.arrays["transforms"], rows)
    assert snapshot.peek(b)["frame"] == 7
    for bad in (b"", b"PNG\x89" + b[4:], b[:-3]):
        with pytest.raises(snapshot.SnapshotError):
            snapshot.decode(bad)
