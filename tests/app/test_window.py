"""The window under a display (Xvfb, started here when DISPLAY is unset): frames, screenshots
equal to the offscreen render, input through the callbacks a user triggers, replay, picking,
resizing, and the no-display exit. Tiny sizes: 64x48 images over a 32x24 water grid."""

import contextlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.controls import Action, Button
from app.quality import Quality
from app.scene import parse_scene
from app.window import EventLog, Viewer, make_world

SCENE = """
[render]
width = 64
height = 48
bounces = 1

[camera]
eye = [0.5, 0.9, 1.25]
target = [0.5, 0.15, 0.35]
fov = 55

[water]
size = [1.0, 0.75]
cells = [32, 24]
depth = 0.15

[[water.drops]]
x = 0.3
y = 0.3
radius = 0.1
height = 0.02

[water.rain]
radius = 0.05              # m
height = 0.01              # m
seed = 3

[[lights]]
kind = "directional"
direction = [-0.3, -1.0, 0.2]

[pool]
steps = 0
wall_height = 0.25
"""

ROOT = Path(__file__).resolve().parents[2]
FRAME_TIME = 0.02
SIZE = (64, 48)
QUALITY = Quality(32, 1.0, 1, "fixed")


@pytest.fixture(scope="module")
def display():
    """A display: the one in DISPLAY, else a private Xvfb (an error if it is not installed)."""
    if os.environ.get("DISPLAY"):
        yield os.environ["DISPLAY"]
        return
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.fail("the window tests need a display: install Xvfb (apt-get install xvfb xauth; "
                    ".ci/run does) or set DISPLAY")
    proc = subprocess.Popen([xvfb, "-displayfd", "1", "-screen", "0", "320x240x24",
                             "-nolisten", "tcp"], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL)
    try:
        number = proc.stdout.readline().decode().strip()
        if not number:
            pytest.fail("Xvfb did not start (no display number on -displayfd)")
        os.environ["DISPLAY"] = f":{number}"
        yield os.environ["DISPLAY"]
    finally:
        os.environ.pop("DISPLAY", None)
        proc.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(5)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return parse_scene(SCENE, tmp_path_factory.mktemp("scene") / "tiny.toml")


@pytest.fixture
def viewer(display, scene, rt):
    v = Viewer(scene, rt, window_size=SIZE, quality=QUALITY, frame_time=FRAME_TIME,
               vsync=False, record=True)
    yield v
    v.close()


def fields(world):
    return world.water_fields()


def water_pixel(world):
    """An image pixel (centre) whose ray meets the water, near the image centre."""
    w, h = world.size
    for dy in range(0, h // 2, 2):
        p = (w / 2 + 0.5, h / 2 + dy + 0.5)
        if world.pick(*p) is not None:
            return p
    raise AssertionError("no water under the image centre")


def test_window_renders_frames_and_its_screenshot_is_the_offscreen_render(display, scene, rt,
                                                                          tmp_path):
    from imageio.v3 import imread

    from app.cli import main

    path = scene.path.parent / "tiny.toml"
    path.write_text(SCENE)
    shot = tmp_path / "shot.png"
    frames = 5
    status = main(["window", str(path), "--size", "64x48", "--quality", "low", "--cells", "32",
                   "--scale", "1", "--bounces", "1", "--frames", str(frames), "--no-vsync",
                   "--frame-time", str(FRAME_TIME), "--screenshot", str(shot)])
    assert status == 0
    img = imread(shot)
    assert img.shape == (48, 64, 4)
    assert img[..., :3].std() > 5            # not blank
    world = make_world(scene, rt, size=SIZE, spp=1, bounces=1, cells=32)
    for _ in range(frames):
        ref = world.frame(FRAME_TIME)
    diff = np.abs(img.astype(int) - ref.astype(int)).max(axis=2)
    assert (diff <= 1).mean() >= 0.99, f"max diff {diff.max()}"


def test_auto_quality_probes_in_the_window_and_its_choice_meets_the_target(display, scene,
                                                                          tmp_path, monkeypatch):
    """--quality auto with traced caustics: the probe's frames are shown in the window (its
    display cost is measured), the choice and its caustics are reported, and the frames at the
    chosen settings meet the target frame time that the model predicted they would."""
    import json

    from app.cli import main
    from app.window import Viewer

    path = tmp_path / "caustic.toml"
    path.write_text(SCENE + '[shading]\ncaustics = "traced"\ncaustic_photons = 4096\n'
                    'caustic_resolution = 32\n')
    import glfw

    shown, interval = [], [None]
    real = Viewer.present_probe
    monkeypatch.setattr(Viewer, "present_probe", lambda self, world, img: (
        shown.append((img.shape, interval[0])), real(self, world, img)))
    # vsync is asked for (no --no-vsync), but a probe that waited for the display's refresh
    # would time the refresh: the probe's frames are swapped at interval 0
    monkeypatch.setattr(glfw, "swap_interval", lambda n: interval.__setitem__(0, n))
    report = tmp_path / "run.json"
    status = main(["window", str(path), "--size", "96x72", "--quality", "auto",
                   "--target-fps", "5", "--frames", "12", "--frame-time", str(FRAME_TIME),
                   "--report", str(report)])
    assert status == 0
    assert shown == [((36, 48, 4), 0)] * 6  # warm-up and timed probe frames, at scale 0.5
    assert interval[0] == 1                 # then vsync, as asked
    r = json.loads(report.read_text())
    assert r["source"] == "auto" and r["frames"] == 12 and r["window"] == [96, 72]
    assert r["fps"] == pytest.approx(r["frames"] / r["seconds"], rel=0.01)
    assert r["caustics"] in ("traced", "off") and r["photons"] in (4096, 1024)
    assert ("caustics" in r["quality"]) and r["image"] == [round(96 * r["scale"]),
                                                           round(72 * r["scale"])]
    assert r["predicted_ms"] <= 200.0 and r["frame_ms"] <= 200.0   # 5 FPS: 200 ms a frame


def test_drag_on_the_water_changes_heights_only_near_the_picked_points(viewer):
    v = viewer
    v.step()
    v.on_action(Action.PAUSE)                # freeze the water so only the drag changes it
    v.step()
    v.step()
    h0 = fields(v.world)["h"].copy()
    picks = []
    real_pick = v.world.pick
    v.world.pick = lambda px, py: picks.append(real_pick(px, py)) or picks[-1]
    x, y = water_pixel(v.world)
    v.on_cursor(x, y)
    v.on_button(Button.LEFT, True)
    v.on_cursor(x + 6, y)
    v.on_button(Button.LEFT, False)
    for _ in range(3):
        v.step()
    h1 = fields(v.world)["h"]
    changed = np.abs(h1 - h0) > 1e-6
    assert changed.any() and v.controls.drops >= 1
    w = v.controls.water
    radius = v.controls._ripple_radius()
    js, is_ = np.nonzero(changed)
    cx, cz = (is_ + 0.5) * w.dx, (js + 0.5) * w.dx
    pts = np.array([p.pool_xy for p in picks if p is not None and p.water])
    dist = np.min(np.hypot(cx[:, None] - pts[None, :, 0], cz[:, None] - pts[None, :, 1]), axis=1)
    assert dist.max() <= radius + 1.5 * w.dx
    assert changed.mean() < 0.5              # and not everywhere


def test_drag_elsewhere_moves_the_camera_and_wheel_zooms(viewer):
    v = viewer
    v.step()
    eye0 = np.array(v.world.camera[0])
    v.on_cursor(1, 1)                        # the top-left corner: sky, no water
    assert v.world.pick(*v.controls.image_point(1, 1)) is None
    v.on_button(Button.LEFT, True)
    v.on_cursor(20, 3)
    v.on_button(Button.LEFT, False)
    v.step()
    eye1 = np.array(v.world.camera[0])
    assert np.linalg.norm(eye1 - eye0) > 1e-3
    np.testing.assert_allclose(v.world.camera[1], v.scene.camera.target, atol=1e-9)
    v.on_scroll(2)
    v.step()
    d1 = np.linalg.norm(np.array(v.world.camera[0]) - np.array(v.world.camera[1]))
    assert d1 == pytest.approx(0.81 * np.linalg.norm(eye1 - np.array(v.world.camera[1])))


def test_rain_adds_volume_and_pause_freezes_the_fields(viewer):
    v = viewer
    v.step()
    v.step()
    w = v.controls.water
    g0 = dict(v.world.stats.guard)
    mass0 = fields(v.world)["h"].astype(np.float64).sum() * w.dx ** 2
    for _ in range(4):
        v.on_action(Action.RAIN_MORE)        # 20 -> 101 drops/s
    v.on_action(Action.TOGGLE_RAIN)
    for _ in range(15):
        v.step()
    v.on_action(Action.PAUSE)
    v.step()
    v.step()
    v.world.drain()
    g1 = v.world.stats.guard
    f1 = fields(v.world)["h"].copy()
    mass1 = f1.astype(np.float64).sum() * w.dx ** 2
    # the volume grows by what the sources added, less what the limiter clipped
    budget = ((g1["volume_sources"] - g0["volume_sources"])
              - (g1["volume_clipped"] - g0["volume_clipped"])
              + (g1["volume_created"] - g0["volume_created"]))
    assert mass1 - mass0 == pytest.approx(budget, rel=1e-3)
    # and the sources are the rain: about rate x time drops of the scene's [water.rain] size
    r, height = 0.05, 0.01
    per_drop = height * r * r * (np.pi / 2 - 2 / np.pi)  # volume of the cosine bump
    expected = v.controls.rain_rate * 15 * FRAME_TIME * per_drop
    assert budget == pytest.approx(expected, rel=0.6)
    for _ in range(3):
        v.step()
    np.testing.assert_array_equal(fields(v.world)["h"], f1)   # paused: nothing moves


def test_replayed_events_give_the_same_final_frame(viewer, display, scene, rt, tmp_path):
    v = viewer
    v.step()
    x, y = water_pixel(v.world)
    v.on_cursor(x, y)
    v.on_button(Button.LEFT, True)
    v.step()
    v.on_cursor(x + 8, y - 2)
    v.step()
    v.on_button(Button.LEFT, False)
    v.on_action(Action.TOGGLE_RAIN)
    v.on_cursor(2, 2)
    v.on_button(Button.LEFT, True)
    v.on_cursor(12, 4)
    v.on_button(Button.LEFT, False)
    v.run(8)
    live = v.snapshot()
    log_path = tmp_path / "events.jsonl"
    v.event_log().write(log_path)
    log = EventLog.load(log_path)
    assert {e["kind"] for e in log.events} >= {"button", "cursor", "action", "tick"}
    r = Viewer(scene, rt, window_size=SIZE, quality=QUALITY, vsync=False, replay=log)
    try:
        r.run(8)
        np.testing.assert_array_equal(r.snapshot(), live)
        assert r.controls.rain_on and r.world.camera == v.world.camera
    finally:
        r.close()


def test_pick_meets_the_water_where_the_tracer_says(viewer):
    import lbm
    from app.controls import pixel_ray
    from raytrace.query import intersect

    v = viewer
    for _ in range(3):
        v.step()
    world = v.world
    f = fields(world)
    sc = v.scene.water
    ny, nx = f["h"].shape
    dx = v.controls.water.dx
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny))
    verts = np.stack([sc.origin[0] + (ii + 0.5) * dx, sc.origin[1] + f["bed"] + f["h"],
                      sc.origin[2] + (jj + 0.5) * dx], -1).reshape(-1, 3)
    eye, target, up, fov = world.camera
    W, H = world.size
    pix = [(W / 2 + 0.5, H / 2 + 0.5), (W / 3 + 0.5, 2 * H / 3 + 0.5), (0.5, 0.5)]
    rays = [pixel_ray(eye, target, up, fov, W, H, px, py) for px, py in pix]
    ref = intersect(verts, lbm.grid_triangles(nx, ny), np.array([o for o, _ in rays]),
                    np.array([d for _, d in rays]))
    for (px, py), (o, d), hit, t in zip(pix, rays, ref["hit"], ref["t"], strict=True):
        got = world.pick(px, py)
        if not hit:
            assert got is None or not got.water
            continue
        assert got.water
        np.testing.assert_allclose(got.point, o + t * d, atol=2e-4)
    assert ref["hit"][:2].all()


def test_resize_mid_run_rebuilds_at_the_new_size(viewer):
    v = viewer
    for _ in range(2):
        v.step()
    w0 = v.world
    v.on_resize(80, 60)                      # a drag-resize: sizes change from frame to frame
    v.step()
    v.on_resize(96, 72)
    v.step()
    assert v.world is w0                     # not rebuilt while the size keeps changing
    v.step()
    assert v.world is not w0 and tuple(v.world.size) == (96, 72)
    v.glfw.set_window_size(v.win, 80, 60)    # and through glfw, as a user's resize arrives
    for _ in range(50):                      # X applies the size asynchronously
        v.step()
        if tuple(v.world.size) == (80, 60):
            break
    assert tuple(v.world.size) == (80, 60)
    v.step()
    v.step()
    assert v.snapshot().shape == (60, 80, 4)
    assert [e["width"] for e in v.recording if e["kind"] == "resize"][-1] == 80


def test_keys_that_rebuild_keep_the_camera_and_fullscreen_toggles(viewer):
    v = viewer
    v.step()
    v.on_cursor(1, 1)
    v.on_button(Button.LEFT, True)
    v.on_cursor(9, 1)                        # orbit a little first
    v.on_button(Button.LEFT, False)
    v.step()
    camera = v.world.camera
    assert v.world.caustics == "off" and v.controls.caustics is None   # the scene's
    v.on_action(Action.TOGGLE_CAUSTICS)
    assert v.world.caustics == "traced" == v.controls.caustics
    v.step()
    assert "caustics traced" in "\n".join(v.hud_text())
    for a in (Action.GRID_DOWN, Action.BOUNCES_UP, Action.SPP_2):
        v.on_action(a)
    v.step()
    v.step()
    assert v.world.stats.water_cells == (21, 16)         # 32 / 1.5 along the longer side
    assert (v.world.bounces, v.world.spp) == (2, 2)
    assert v.world.camera == camera and v.world.caustics == "traced"   # kept by the rebuild
    v.on_action(Action.TOGGLE_CAUSTICS)
    v.on_action(Action.GRID_UP)
    v.step()
    assert v.world.caustics == "off" and "caustics off" in "\n".join(v.hud_text())
    v.on_action(Action.TOGGLE_CAUSTICS)
    v.step()
    v.step()
    assert any(k.startswith("caustics.") for k in v.world.stats.stage_ms)
    v.on_action(Action.FULLSCREEN)
    for _ in range(30):
        v.step()
        if v.glfw.get_window_monitor(v.win) and tuple(v.world.size) != SIZE:
            break
    mon = v.glfw.get_window_monitor(v.win)
    mode = v.glfw.get_video_mode(mon).size
    assert tuple(v.world.size) == (mode.width, mode.height)   # the screen's size
    v.on_action(Action.FULLSCREEN)
    for _ in range(30):
        v.step()
        if tuple(v.world.size) == SIZE:
            break
    assert not v.glfw.get_window_monitor(v.win) and tuple(v.world.size) == SIZE


def test_hud_is_drawn_over_the_image_but_not_into_the_plain_screenshot(viewer, tmp_path,
                                                                      monkeypatch):
    from imageio.v3 import imread

    v = viewer
    for _ in range(3):
        v.step()
    plain, with_hud = v.snapshot(), v.snapshot_with_hud()
    assert plain.shape == with_hud.shape == (48, 64, 4)
    assert (plain != with_hud).any(axis=2).mean() > 0.1
    v.on_action(Action.TOGGLE_HUD)
    v.on_action(Action.TOGGLE_HELP)          # help was showing at start: now off
    v.step()
    np.testing.assert_array_equal(v.snapshot_with_hud(), v.snapshot())
    monkeypatch.chdir(tmp_path)
    v.on_action(Action.SCREENSHOT)           # S: a PNG named by time, in the working folder
    v.step()
    (shot,) = tmp_path.glob("lbwater-*.png")
    assert imread(shot).shape == (48, 64, 4) and not list(tmp_path.glob(".*partial"))
    assert (v.snapshot_with_hud() != v.snapshot()).any()   # "saved ..." shows for a while


def test_no_display_is_one_line_and_status_2():
    env = {k: val for k, val in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    p = subprocess.run([sys.executable, "-m", "app.cli", "window", "--frames", "1"], env=env,
                       capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "no display" in lines[0] and "lbwater capture" in lines[0]
    assert "Traceback" not in p.stderr and p.stdout == ""


def test_auto_quality_measures_a_probe_and_aims_lower_for_a_higher_target(scene, rt):
    import argparse

    from app.quality import ladder
    from app.window import decide_quality

    def pick(fps):
        args = argparse.Namespace(quality="auto", target_fps=fps, cells=None, scale=None,
                                  bounces=None, spp=None)
        return decide_quality(args, scene, rt, (64, 48), FRAME_TIME)

    easy, hard = pick(0.5), pick(1e5)
    rungs = ladder(32, 1)                     # the tiny scene traces no caustics
    assert (easy.cells, easy.scale, easy.bounces, False) == rungs[0]    # 2 s a frame: the best
    assert (hard.cells, hard.scale, hard.bounces, False) == rungs[-1]   # 10 us: the least
    assert 0 < easy.predicted_ms <= 2000      # fits its budget
    assert hard.predicted_ms > 1000 / 1e5     # nothing fits: the last rung, said so
    assert "auto" in easy.describe() and "predicted" in hard.describe()
