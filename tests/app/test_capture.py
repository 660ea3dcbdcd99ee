"""``lbwater capture``: frames of the asked size and count, the same bytes from the same seed, a
playable partial video after Ctrl-C, the timeline's drop in its frame, no silent overwrite and
no simulation before an unwritable output fails."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np
import pytest

from app.cli import main

ROOT = Path(__file__).resolve().parents[2]

SCENE = """
[render]
width = 48
height = 32
bounces = 2

[camera]
eye = [0.5, 0.6, -0.5]
target = [0.5, 0.0, 0.5]

[water]
size = [1.0, 1.0]
cells = [24, 24]
depth = 0.2

[[lights]]
kind = "directional"
direction = [-0.3, -1.0, 0.2]

[pool]
steps = 0
wall_height = 0.3

[[timeline]]
time = 0.5                # frame ceil(0.5 * 10) = 5 at 10 fps
drop = { x = 0.5, y = 0.5, radius = 0.12, height = 0.06 }
"""


@pytest.fixture
def scene(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(SCENE)
    return p


def _decode(path):
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    return meta, [np.frombuffer(f, np.uint8) for f in reader]


def test_ten_frames_decode_at_the_asked_size_and_runs_are_byte_identical(scene, tmp_path):
    a, b = tmp_path / "a.mp4", tmp_path / "b.mp4"
    for out in (a, b):
        assert main(["capture", str(scene), "-o", str(out), "--frames", "10", "--fps", "10",
                     "--width", "40", "--height", "30", "--seed", "3", "--quiet"]) == 0
    meta, frames = _decode(a)
    assert tuple(meta["size"]) == (40, 30) and len(frames) == 10
    assert all(f.size == 40 * 30 * 3 for f in frames)
    assert a.read_bytes() == b.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mp4", "b.mp4", "s.toml"]


def test_device_yuv_and_host_yuv_give_the_same_video(scene, tmp_path):
    """-o alone reads yuv420p planes made on the device; with --frames-dir the World reads RGBA
    and the writer converts on the host: the same integers, so the same bytes."""
    a, b = tmp_path / "device.mp4", tmp_path / "host.mp4"
    common = ["--frames", "6", "--fps", "10", "--seed", "5", "--quiet"]
    assert main(["capture", str(scene), "-o", str(a), *common]) == 0
    assert main(["capture", str(scene), "-o", str(b), "--frames-dir", str(tmp_path / "f"),
                 *common]) == 0
    assert a.read_bytes() == b.read_bytes()
    frames = [iio.imread(tmp_path / "f" / f"frame_{i:06d}.png").astype(int) for i in range(6)]
    _, decoded = _decode(a)
    rgb = decoded[-1].reshape(32, 48, 3).astype(int)   # BT.601 limited range back to RGB
    assert np.abs(rgb - frames[-1][..., :3]).mean() < 6, "colours as rendered"


def test_timeline_drop_lands_in_its_frame(scene, tmp_path):
    frames = tmp_path / "frames"
    assert main(["capture", str(scene), "--frames-dir", str(frames), "--frames", "7",
                 "--fps", "10", "--quiet"]) == 0
    imgs = [iio.imread(frames / f"frame_{i:06d}.png").astype(int) for i in range(7)]
    assert imgs[0].shape == (32, 48, 4)
    change = [int(np.abs(imgs[i] - imgs[i - 1]).max()) for i in range(1, 7)]
    assert change[:4] == [0, 0, 0, 0], "still water stays still before the drop"
    assert change[4] > 0 and change[5] > 0, "the drop shows from frame 5 on"


def test_existing_output_needs_force(scene, tmp_path, capsys):
    out = tmp_path / "v.mp4"
    out.write_bytes(b"keep me")
    assert main(["capture", str(scene), "-o", str(out), "--frames", "2", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--force" in err[0] and str(out) in err[0]
    assert out.read_bytes() == b"keep me"
    assert main(["capture", str(scene), "-o", str(out), "--frames", "2", "--quiet",
                 "--force"]) == 0
    assert len(_decode(out)[1]) == 2


def test_unwritable_output_fails_before_simulating(scene, tmp_path, capsys, monkeypatch):
    import app.frames

    def no_world(*a, **k):
        raise AssertionError("the World was made before the output was checked")

    monkeypatch.setattr(app.frames, "open_world", no_world)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    bad = blocker / "sub" / "v.mp4"
    assert main(["capture", str(scene), "-o", str(bad), "--frames", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(bad) in err[0]
    assert main(["capture", str(scene), "-o", str(tmp_path / "v.avi"), "--frames", "2"]) == 2
    assert main(["capture", str(scene), "-o", str(tmp_path / "v.mp4"), "--width", "33"]) == 2


def test_sigint_leaves_a_playable_partial_video(scene, tmp_path):
    out, frames = tmp_path / "v.mp4", tmp_path / "frames"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "capture", str(scene), "-o", str(out), "--frames-dir",
         str(frames), "--frames", "100000", "--fps", "10", "--quiet"],
        cwd=ROOT, env=env, stderr=subprocess.PIPE, text=True)
    # far more frames than any device renders before the signal (a GPU finished 400 first)
    try:
        deadline = time.time() + 120
        while not (frames / "frame_000003.png").exists():
            assert proc.poll() is None and time.time() < deadline, "capture never reached frame 3"
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    partial = tmp_path / "v.partial.mp4"
    assert str(partial) in err and not out.exists(), err
    _, decoded = _decode(partial)
    assert len(decoded) >= 2, err


class _Stream:
    def __init__(self, tty):
        self.tty, self.text = tty, ""

    def isatty(self):
        return self.tty

    def write(self, s):
        self.text += s

    def flush(self):
        pass


def test_progress_bar_only_on_a_terminal():
    from app.capture import Progress

    for tty in (True, False):
        s = _Stream(tty)
        bar = Progress(4, True, stream=s)
        for k in range(1, 5):
            bar._last = 0.0
            bar.update(k)
        bar.finish()
        if tty:
            assert "4/4" in s.text and "ETA" in s.text and s.text.endswith("\n")
        else:
            assert s.text == ""


def test_odd_scene_size_fails_before_anything_is_written(tmp_path, capsys):
    scene = tmp_path / "odd.toml"
    scene.write_text(SCENE.replace("width = 48", "width = 47"))
    assert main(["capture", str(scene), "-o", str(tmp_path / "v.mp4"), "--frames", "2"]) == 2
    assert "even" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["odd.toml"]


def test_a_failure_before_the_first_frame_leaves_no_partial_file(scene, tmp_path, capsys,
                                                                 monkeypatch):
    import app.frames

    def broken(*a, **k):
        raise KeyboardInterrupt   # Ctrl-C while the World is being built

    monkeypatch.setattr(app.frames, "open_world", broken)
    out = tmp_path / "v.mp4"
    assert main(["capture", str(scene), "-o", str(out), "--frames", "2", "--quiet"]) == 130
    assert not out.exists() and not (tmp_path / "v.partial.mp4").exists()
    assert list(tmp_path.iterdir()) == [scene]
