"""`lbwater bench window` at a tiny size: rows with the bare frame, the window's loop and the
upload + draw, and its in-run check that the drawn frame equals the image."""

import json

from app.cli import main
from tests.app.test_window import SCENE


def test_bench_window_writes_rows_for_each_size(tmp_path):
    out = tmp_path / "bench"
    scene = tmp_path / "tiny.toml"
    scene.write_text(SCENE)
    status = main(["bench", "window", "--scene", str(scene), "--sizes", "64x48", "48x32",
                   "--frames", "2", "--warmup", "1", "--out", str(out)])
    assert status == 0
    rows = json.loads((out / "bench_window.json").read_text())
    assert [(r["width"], r["height"]) for r in rows] == [(64, 48), (48, 32)]
    for r in rows:
        assert r["bare_frame_ms"] > 0 and r["window_frame_ms"] > 0
        assert 0 < r["upload_draw_ms"] < r["window_frame_ms"] + 1e-9
        assert r["ratio"] == round(r["window_frame_ms"] / r["bare_frame_ms"], 3)
        assert "copy" in r["display_path"] and r["gl_renderer"]
    assert (out / "bench_window.csv").read_text().startswith("device,")


def test_bench_window_with_auto_quality_reports_the_windows_choice(tmp_path):
    out = tmp_path / "bench"
    scene = tmp_path / "tiny.toml"
    scene.write_text(SCENE)
    status = main(["bench", "window", "--scene", str(scene), "--sizes", "96x72", "--quality",
                   "auto", "--target-fps", "1", "--frames", "2", "--warmup", "1",
                   "--out", str(out)])
    assert status == 0
    (r,) = json.loads((out / "bench_window.json").read_text())
    assert r["window"] == "96x72" and r["source"] == "auto" and r["target_fps"] == 1.0
    # 1 FPS fits the best rung: the whole window, the scene's grid and bounces
    assert (r["width"], r["height"], r["scale"], r["cells"], r["bounces"]) == (
        96, 72, 1.0, "32x24", 1)
    assert 0 < r["predicted_ms"] <= 1000.0 and r["caustics"] == "off" and r["photons"] is None
    assert r["window_fps"] == round(1e3 / r["window_frame_ms"], 1)
