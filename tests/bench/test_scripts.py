"""The scripts in bench/ that BENCHMARKS.md and docs/lbm.md quote, run at tiny sizes: each must
still run against the current API and produce what its figures are made of."""

import csv
import importlib.util
import json
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"


def _script(name):
    spec = importlib.util.spec_from_file_location(f"bench_{name}", BENCH / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_lattice_stability_device(tmp_path, capsys, rt):
    out = tmp_path / "s.csv"
    rc = _script("lattice_stability").main(
        ["--n", "16", "--sigma", "2", "--ratios", "0.5,0.62", "--taus", "0.6",
         "--seconds", "0.2", "--out", str(out)])
    assert rc == 0
    rows = {r["ratio"]: r for r in csv.DictReader(out.open())}
    assert rows["0.5"]["clamped"] == "0" and int(rows["0.5"]["steps"]) > 30
    assert "lattice_speed" in rows["0.62"]["refused"]   # above the limiter's cap of 0.6
    assert "| 0.62 | refused |" in capsys.readouterr().out


def test_lattice_stability_reference_finds_the_instability(capsys):
    rc = _script("lattice_stability").main(
        ["--solver", "reference", "--n", "16", "--sigma", "2", "--ratios", "0.5,0.64",
         "--taus", "0.505", "--seconds", "0.5"])
    assert rc == 0
    lines = capsys.readouterr().out.splitlines()
    assert "| 0.50 | 0 |" in lines
    row = next(ln for ln in lines if ln.startswith("| 0.64 |"))
    assert int(row.split("|")[2]) > 100


def test_ab_radix_bits_same_tree(capsys, rt):
    rc = _script("ab_radix_bits").main(["--n", "40", "--rounds", "2", "--builds", "1"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["same_tree"] is True
    assert (out["bits4_passes"], out["bits8_passes"]) == (8, 4)
    assert len(out["bits4_round_wall_ms"]) == 2 and out["bits8_device_ms"] > 0


def test_ab_embree_interleaved(capsys, rt):
    pytest.importorskip("embreex", reason="embreex is a test dependency (pyproject.toml)")
    rc = _script("ab_embree_interleaved").main(["--n", "17", "--rounds", "1", "--rays", "small"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    for kind in ("primary", "incoherent"):
        assert out[kind]["same_hit_fraction"] >= 0.999
        assert out[kind]["ours_Mrays_s"] > 0 and out[kind]["embree_1t_Mrays_s"] > 0


def test_collect_results_gathers_every_json_by_relative_path(tmp_path):
    (tmp_path / "r" / "a").mkdir(parents=True)
    (tmp_path / "r" / "a" / "x.json").write_text('{"wall_ms": 1.5}')
    (tmp_path / "r" / "b.json").write_text("[1, 2]")
    (tmp_path / "r" / "bad.json").write_text("{not json")
    assert _script("collect_results").main([str(tmp_path / "r"), str(tmp_path / "all.json")]) == 0
    got = json.loads((tmp_path / "all.json").read_text())
    assert got["a/x.json"] == {"wall_ms": 1.5} and got["b.json"] == [1, 2]
    assert "unreadable" in got["bad.json"]


def test_profile_host_prints_the_frame_and_the_top_functions(capsys, rt):
    assert _script("profile_host").main(["--cells", "32", "--size", "32", "18", "--frames", "3",
                                         "--top", "3"]) == 0
    out = capsys.readouterr().out
    assert "3 frames" in out and "ms/frame wall under cProfile" in out
    assert "enqueue_frame" in out or "Ordered by: internal time" in out


def test_host_frame_reports_the_hosts_ms_per_frame(capsys, rt):
    assert _script("host_frame").main(["--cells", "32", "--size", "16", "12", "--frames", "3",
                                       "--steps", "2", "--hold-ms", "2", "--split"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["lbm_steps"] == 2 and out["events_per_frame"] > 20
    assert 0 < out["enqueue_py_ms"] <= out["enqueue_ms"] and out["read_ms"] > 0
    assert out["enqueue_cl_calls"] >= out["events_per_frame"]
    assert out["pipelined_wall_ms"] > 0 and 0 <= out["held_waits"] <= 3


def test_shadow_lean_probe(tmp_path, capsys, rt):
    out = tmp_path / "lean.json"
    rc = _script("shadow_lean_probe").main(
        ["--size", "48", "32", "--cells", "32", "--settle", "1", "--repeats", "1",
         "--json", str(out)])
    assert rc == 0
    res = json.loads(out.read_text())
    assert [lv["depth"] for lv in res["levels"]] == [0, 1]
    for lv in res["levels"]:
        assert lv["shadow_ms"] > 0 and lv["lean_ms"] > 0
        assert lv["emit_plus_lean_ms"] == lv["emit_ms"] + lv["lean_ms"]
        assert lv["max_abs_diff"] <= 1e-4 * lv["radiance_max"]
    assert res["levels"][0]["primary_trace_ms"] > 0
    assert "level 1:" in capsys.readouterr().out


def test_shadow_lean_probe_one_light(tmp_path, capsys, rt):
    """A scene of two lights: one line naming the file and the count, exit 2, no JSON."""
    root = BENCH.parent
    text = (BENCH / "scenes" / "pool_static_boat.toml").read_text().replace(
        'floor_texture = "../../scenes/textures/', f'floor_texture = "{root}/scenes/textures/')
    text += '\n[[lights]]\nkind = "directional"\ndirection = [0.0, -1.0, 0.0]\n'
    scene = tmp_path / "two_lights.toml"
    scene.write_text(text)
    out = tmp_path / "lean.json"
    rc = _script("shadow_lean_probe").main(
        ["--scene", str(scene), "--size", "32", "24", "--cells", "32", "--settle", "0",
         "--json", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and not out.exists()
    assert err == [f"shadow_lean_probe: {scene}: the probe takes a scene of one light, it has 2"]
