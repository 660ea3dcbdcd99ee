"""``lbwater sweep``: a two-point sweep writes every column and all charts; a rerun skips both
points (no World is made) and leaves the rows as they were."""

import csv
import json

import pytest

from app.cli import main
from tests.app.test_capture import SCENE

COLUMNS = {"scene", "device", "cells", "width", "height", "bounces", "spp", "frames", "warmup",
           "water_cells", "fps", "frame_wall_ms", "kernel_ms", "triangles", "rays_per_frame",
           "device_mib", "lbm_ms", "bvh_ms", "primary_trace_ms", "shadows_ms", "other_ms"}


def test_two_point_sweep_then_a_rerun_that_skips(tmp_path, monkeypatch, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "sweep"
    argv = ["sweep", str(scene), "--cells", "12,20", "--size", "32x24", "--frames", "2",
            "--warmup", "2", "-o", str(out), "--quiet"]
    assert main(argv) == 0
    with open(out / "sweep.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 and COLUMNS <= set(rows[0])
    assert [r["water_cells"] for r in rows] == ["12x12", "20x20"]
    for r in rows:
        assert float(r["fps"]) > 0 and int(r["rays_per_frame"]) >= 32 * 24
        assert float(r["device_mib"]) > 0 and float(r["lbm_ms"]) > 0
        assert int(r["triangles"]) > 2 * 11 * 11
    stages = json.loads((out / "sweep.json").read_text())["rows"][0]["stages_ms"]
    assert "lbm.step" in stages and any(k.startswith("render.") for k in stages)
    for name in ("fps_vs_cells.png", "stages_by_cells.png", "frame_ms_vs_rays.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG"
    before = (out / "sweep.json").read_text()

    import app.frames

    def no_world(*a, **k):
        raise AssertionError("a done point was measured again")

    monkeypatch.setattr(app.frames, "open_world", no_world)
    capsys.readouterr()
    assert main(argv) == 0
    assert "0 points measured, 2 skipped" in capsys.readouterr().err
    assert (out / "sweep.json").read_text() == before


@pytest.mark.parametrize("bad", [["--cells", "1"], ["--size", "10by20"], ["--frames", "0"]])
def test_bad_options_are_one_line(tmp_path, capsys, bad):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    with pytest.raises(SystemExit) as e:
        status = main(["sweep", str(scene), "-o", str(tmp_path / "o"), *bad])
        raise SystemExit(status)
    assert e.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]   # argparse: usage, then one line
    assert "error" in last and bad[0] in last
