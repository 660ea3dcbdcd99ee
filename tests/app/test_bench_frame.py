"""`lbwater bench frame` runs the World's frame loop and writes per-stage times and FPS."""

import json

import pytest

from app.cli import main
from raytrace.render import RenderSettings


def test_bench_frame_writes_stages_and_fps(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["bench", "frame", "--cells", "32", "--size", "48", "32", "--frames", "3",
                 "--warmup", "1", "--frame-time", "0.1", "--out", str(out)]) == 0
    rows = json.loads((out / "bench_frame.json").read_text())
    assert len(rows) == 1 and rows[0]["cells"] == "32x24"
    r = rows[0]
    assert r["fps"] > 0 and r["lbm_steps_per_frame"] > 0
    assert r["lbm.step_ms"] > 0 and r["render.trace_ms"] > 0 and r["kernels_ms"] > 0
    assert (out / "bench_frame.csv").read_text().startswith("device,")
    assert "32x24 cells" in capsys.readouterr().out
    assert r["host_copy"] is False


def test_bench_frame_host_copy_is_recorded(tmp_path):
    out = tmp_path / "res"
    assert main(["bench", "frame", "--cells", "32", "--size", "48", "32", "--frames", "2",
                 "--warmup", "1", "--frame-time", "0.1", "--host-copy", "--out", str(out)]) == 0
    assert json.loads((out / "bench_frame.json").read_text())[0]["host_copy"] is True


def test_bench_frame_needs_water(tmp_path, capsys):
    scene = tmp_path / "dry.toml"
    scene.write_text('[[meshes]]\nfile = "bunny_5k.obj"\n')
    assert main(["bench", "frame", "--scene", str(scene), "--out", str(tmp_path)]) == 2
    assert "needs a scene with [water]" in capsys.readouterr().err


def test_bench_frame_photons_sets_the_caustic_photons_and_times_them(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["bench", "frame", "--cells", "32", "--size", "48", "32", "--frames", "2",
                 "--warmup", "1", "--caustics", "traced", "--photons", "1024",
                 "--out", str(out)]) == 0
    r = json.loads((out / "bench_frame.json").read_text())[0]
    assert r["caustic_photons"] == 1024 and r["caustics.photons_ms"] > 0
    assert main(["bench", "frame", "--photons", "0", "--out", str(out)]) == 2
    assert "--photons 0 is out of range" in capsys.readouterr().err


@pytest.mark.parametrize("flags", [[], ["--no-overlap"], ["--overlap-from", "0"],
                                   ["--overlap-from", "2"]])
def test_bench_frame_per_depth_stages(tmp_path, flags):
    out = tmp_path / "res"
    assert main(["bench", "frame", "--cells", "32", "--size", "48", "32", "--frames", "2",
                 "--warmup", "1", "--frame-time", "0.1", "--caustics", "off", "--per-depth",
                 *flags, "--out", str(out)]) == 0
    r = json.loads((out / "bench_frame.json").read_text())[0]
    depths = [int(n) for n in r["rays_per_depth"].split()]
    assert depths[0] == 48 * 32 and len(depths) == 6  # the pool's 5 bounces
    overlap = "--no-overlap" not in flags
    first = int(flags[1]) if "--overlap-from" in flags else RenderSettings.overlap_from
    assert r["overlap"] is overlap and r["overlap_from"] == first and r["render.trace.d0_ms"] > 0
    assert r["render.shadow.d5_ms"] >= 0   # the last level's shadow rays run alone either way
    # level d's shadow rays with level d + 1's trace, from level `first` on
    combined = {f"render.shadow_trace.d{d}_ms" for d in range(first + 1, 6)} if overlap else set()
    assert {k for k in r if k.startswith("render.shadow_trace")} == combined
    assert ("render.shadow.d0_ms" in r) == (not overlap or first > 0)
    assert ("render.trace_secondary.d1_ms" in r) == (not overlap or first > 0)
    assert ("render.trace_secondary.d2_ms" in r) == (not overlap or first > 1)
    assert "render.shadow_ms" not in r and "render.trace_ms" not in r


def test_bench_frame_overlap_from_out_of_range_is_one_line(tmp_path, capsys):
    assert main(["bench", "frame", "--cells", "32", "--size", "48", "32", "--frames", "2",
                 "--overlap-from", "99", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--overlap-from 99 is out of range; allowed [0, 32]" in err
    assert "\n" not in err


def test_bench_frame_coop_from_is_recorded_and_checked(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["bench", "frame", "--cells", "32", "--size", "48", "32", "--frames", "2",
                 "--warmup", "1", "--frame-time", "0.1", "--caustics", "off", "--coop-from", "4",
                 "--out", str(out)]) == 0
    r = json.loads((out / "bench_frame.json").read_text())[0]
    assert r["coop_from"] == 4 and r["fps"] > 0
    capsys.readouterr()   # the run's own output (a first-build notice with a cold cache)
    assert main(["bench", "frame", "--coop-from", "-1", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--coop-from -1 is out of range; allowed off or [0, 32]" in err and "\n" not in err
    assert main(["bench", "frame", "--coop-from", "x", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--coop-from x is not a depth; allowed off or [0, 32]" in err and "\n" not in err


def test_bench_frame_light_buffer_is_recorded_and_checked(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["bench", "frame", "--cells", "32", "--size", "48", "32", "--frames", "2",
                 "--warmup", "1", "--frame-time", "0.1", "--caustics", "off",
                 "--light-buffer", "64", "--one-crossing", "off", "--out", str(out)]) == 0
    r = json.loads((out / "bench_frame.json").read_text())[0]
    assert r["light_buffer"] == 64 and r["render.light_buffer.raster_ms"] > 0
    assert r["one_crossing"] is False
    capsys.readouterr()
    assert main(["bench", "frame", "--light-buffer", "-1", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--light-buffer -1 is out of range; allowed [0, 8192]" in err and "\n" not in err


def test_bench_frame_shadow_list_is_recorded(tmp_path, capsys):
    """--shadow-list on traces every level's shadow rays in one launch: one render.shadow
    stage and no render.shadow_trace; off (the CPU's default) launches them per level."""
    rows = {}
    for flag in ("on", "off"):
        out = tmp_path / flag
        assert main(["bench", "frame", "--cells", "32", "--size", "48", "32", "--frames", "2",
                     "--warmup", "1", "--frame-time", "0.1", "--caustics", "off",
                     "--shadow-list", flag, "--out", str(out)]) == 0
        rows[flag] = json.loads((out / "bench_frame.json").read_text())[0]
    assert rows["on"]["shadow_list"] is True and rows["off"]["shadow_list"] is False
    assert rows["on"]["render.shadow_ms"] > 0 and "render.shadow_trace_ms" not in rows["on"]
    assert rows["off"]["render.shadow_trace_ms"] > 0
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:   # argparse's one line and status 2
        main(["bench", "frame", "--shadow-list", "maybe", "--out", str(tmp_path)])
    assert exc.value.code == 2 and "--shadow-list" in capsys.readouterr().err
