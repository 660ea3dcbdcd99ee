"""`lbwater bench capture`: the bare frame loop and the capture path timed on one World; the
ratio and overhead are the columns' own, the video holds every frame at the asked size and the
PNGs (--png) the same pictures."""

import csv
import json

import imageio.v3 as iio
import numpy as np
import pytest

from app.cli import main
from tests.app.test_capture import SCENE, _decode


@pytest.fixture
def scene(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(SCENE)   # 24x24 cells, 48x32 pixels, a timeline drop
    return p


def test_bench_capture_writes_both_loops_and_their_ratio(scene, tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["bench", "capture", "--scene", str(scene), "--size", "32", "24",
                 "--frames", "8", "--warmup", "1", "--repeats", "2", "--fps", "10",
                 "--png", "--device", "cpu", "--out", str(out)]) == 0
    rows = json.loads((out / "bench_capture.json").read_text())
    assert len(rows) == 1
    r = rows[0]
    assert (r["width"], r["height"], r["frames"], r["cells"]) == (32, 24, 8, "24x24")
    assert r["frame_ms"] > 0 and r["capture_ms"] > 0 and r["write_ms"] > 0
    assert r["ratio"] == pytest.approx(r["capture_ms"] / r["frame_ms"], rel=1e-3)
    assert r["overhead_pct"] == pytest.approx(100 * (r["ratio"] - 1), abs=0.01)
    assert r["meets_goal"] == (r["ratio"] <= r["goal_ratio"]) and r["goal_ratio"] == 1.15
    assert r["frame_fps"] == round(1e3 / r["frame_ms"], 1)   # from the stored time
    assert r["write_ms"] < r["capture_ms"]            # the writers are part of the capture
    with open(out / "bench_capture.csv") as fh:
        assert next(csv.DictReader(fh))["ratio"] == str(r["ratio"])
    meta, frames = _decode(out / "bench_capture.mp4")
    assert tuple(meta["size"]) == (32, 24) and len(frames) == 8 == r["video_frames"]
    pngs = sorted((out / "bench_capture_frames").glob("frame_*.png"))
    assert [p.name for p in pngs] == [f"frame_{i:06d}.png" for i in range(8)]
    last = iio.imread(pngs[-1])[..., :3].astype(np.int16)    # the same image, lossless
    assert np.abs(last - frames[-1].reshape(24, 32, 3)).mean() < 8
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1 and "overhead" in lines[0] and "32x24" in lines[0]


def test_bench_capture_checks_its_numbers(scene, tmp_path, capsys):
    for bad in (["--size", "33", "24"], ["--frames", "1"], ["--repeats", "0"]):
        assert main(["bench", "capture", "--scene", str(scene), *bad, "--out",
                     str(tmp_path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and bad[0] in err[0]
