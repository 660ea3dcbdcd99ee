"""`lbwater simulate`: runs a scene's water, saves the fields atomically, one-line errors."""

import re

import numpy as np
import pytest

import lbm
from app.cli import main
from app.scene import load_scene

SCENE = """
[scene]
name = "tiny pool"

[water]
size = [0.6, 0.4]
cells = [24, 16]
depth = 0.2
viscosity = 1e-4
expected_speed = 0.3

[water.rain]
rate = 40.0
radius = 0.05
height = 0.004
seed = 9

[[water.drops]]
x = 0.3
y = 0.2
radius = 0.1
height = 0.02
"""


@pytest.fixture()
def scene(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(SCENE)
    return path


def test_simulate_saves_fields_like_the_api(rt, scene, tmp_path, capsys):
    out = tmp_path / "res" / "water.npz"
    assert main(["simulate", str(scene), "--steps", "60", "--chunk", "25", "--save", str(out),
                 "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    d = np.load(out)
    assert {"h", "u", "v", "bed", "x", "y", "time"} <= set(d.files)
    assert d["h"].shape == d["u"].shape == d["v"].shape == d["bed"].shape == (16, 24)
    np.testing.assert_allclose(d["x"], (np.arange(24) + 0.5) * 0.025)
    np.testing.assert_allclose(d["y"], (np.arange(16) + 0.5) * 0.025)
    # the same run through the API gives the same water (rain from the same seed)
    sim = lbm.from_water_spec(load_scene(scene).water, device=rt)
    sim.step(60)
    f = sim.fields()
    assert float(d["time"]) == pytest.approx(sim.time) and sim.time == pytest.approx(60 * sim.dt)
    for k in ("h", "u", "v", "bed"):
        np.testing.assert_array_equal(d[k], f[k])
    assert d["h"].sum() * 0.025**2 > 0.2 * 0.6 * 0.4   # the drop and the rain added water
    assert not list(out.parent.glob("*.partial"))


def test_simulate_reports_progress(scene, tmp_path, capsys):
    out = tmp_path / "w.npz"
    assert main(["simulate", str(scene), "--steps", "10", "--save", str(out)]) == 0
    err = capsys.readouterr().err
    assert "tiny pool: 24x16 cells" in err and "step 10/10" in err and "saved" in err


@pytest.mark.parametrize("text, match", [
    (None, r"does-not-exist.toml: scene file does not exist"),
    ("[scene]\nname = 'dry'\n", r"the scene has no \[water\] section"),
    (SCENE.replace("viscosity = 1e-4", "viscosity = 0.0"),
     r"\[water\] viscosity: viscosity = 0 is out of range; allowed in \(0, 1000\]"),
    (SCENE.replace("radius = 0.1\n", "radius = 0.001\n"), r"add_drop: radius=0.001 m"),
    (SCENE.replace("depth = 0.2", "depth = -1"), r"depth = -1 is out of range"),
])
def test_bad_scene_is_one_line_exit_2_and_no_file(tmp_path, capsys, text, match):
    path = tmp_path / "does-not-exist.toml"
    if text is not None:
        path = tmp_path / "bad.toml"
        path.write_text(text)
    out = tmp_path / "out.npz"
    out.write_bytes(b"old")
    assert main(["simulate", str(path), "--steps", "5", "--save", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("lbwater simulate: error:")
    assert re.search(match, err), err
    assert out.read_bytes() == b"old"          # left as it was
    assert [p.name for p in tmp_path.iterdir() if p.suffix == ".partial"] == []


@pytest.mark.parametrize("steps", ["0", "-3", "ten"])
def test_bad_steps_exit_2(scene, tmp_path, steps, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", str(scene), "--steps", steps, "--save", str(tmp_path / "o.npz")])
    assert exc.value.code == 2
    assert "--steps" in capsys.readouterr().err
    assert not (tmp_path / "o.npz").exists()


# a dip to 1 mm at a cell centre in 0.2 m of water: below min_depth (2 mm), so the guard acts
ACTING = SCENE.replace("x = 0.3\ny = 0.2\nradius = 0.1\nheight = 0.02",
                       "x = 0.3125\ny = 0.2125\nradius = 0.1\nheight = -0.199")


def test_guard_action_is_one_warning_line_and_strict_fails(tmp_path, capsys):
    assert ACTING != SCENE
    path = tmp_path / "acting.toml"
    path.write_text(ACTING)
    out = tmp_path / "o.npz"
    assert main(["simulate", str(path), "--steps", "30", "--chunk", "10", "--save", str(out),
                 "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lbwater simulate: warning: the guard acted")
    assert out.exists()
    out2 = tmp_path / "o2.npz"
    assert main(["simulate", str(path), "--steps", "30", "--save", str(out2), "--quiet",
                 "--strict"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--strict: the guard acted" in err[0]
    assert not out2.exists()


def test_clean_run_prints_no_warning(scene, tmp_path, capsys):
    assert main(["simulate", str(scene), "--steps", "30", "--save", str(tmp_path / "o.npz"),
                 "--quiet", "--strict"]) == 0
    assert capsys.readouterr().err == ""
