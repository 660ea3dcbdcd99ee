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


BOX_OBJ = """v -0.3 0 -0.15
v -0.3 0 0.15
v -0.3 0.2 -0.15
v -0.3 0.2 0.15
v 0.3 0 -0.15
v 0.3 0 0.15
v 0.3 0.2 -0.15
v 0.3 0.2 0.15
f 1 2 4
f 1 4 3
f 5 7 8
f 5 8 6
f 1 5 6
f 1 6 2
f 3 4 8
f 3 8 7
f 1 3 7
f 1 7 5
f 2 6 8
f 2 8 4
"""

BOAT_SCENE = """
[scene]
name = "boat pool"

[water]
size = [1.6, 1.0]
cells = [32, 20]
depth = 0.3
viscosity = 1e-3

[[boats]]
file = "box.obj"
mass = 9.0
mass_height = 0.05
position = [0.8, 0.28, 0.5]
rotation = [0.0, 30.0, 0.0]
"""


def test_simulate_floats_boats_and_saves_their_poses(tmp_path, capsys):
    (tmp_path / "box.obj").write_text(BOX_OBJ)
    path = tmp_path / "boat.toml"
    path.write_text(BOAT_SCENE)
    out = tmp_path / "o.npz"
    assert main(["simulate", str(path), "--steps", "200", "--save", str(out), "--quiet"]) == 0
    d = np.load(out)
    assert d["boat_position"].shape == (1, 3) and d["boat_rotation"].shape == (1, 4)
    assert list(d["boat_names"]) == ["[[boats]] #1 (box.obj)"]
    q = d["boat_rotation"][0]
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-5)
    assert abs(q[2]) == pytest.approx(np.sin(np.radians(15)), abs=0.02)   # 30 deg about y kept
    # 9 kg on a 0.6 x 0.3 box: draft 5 cm; the centre of mass 5 cm above the keel floats near the
    # water line (0.3 m + the water it displaces over the pool)
    assert d["boat_position"][0, 1] == pytest.approx(0.3 + 9 / 1000 / 1.6, abs=0.02)
    assert np.isfinite(d["h"]).all()


@pytest.mark.parametrize("change, match", [
    ("mass = 9.0\n", r"give exactly one of mass \(kg\) or density"),
    ("mass = 9.0\n", r"mass 300 kg sinks it"),
    ("mass = 9.0\n", r"unknown key 'colour'"),
    ('file = "box.obj"\n', r"file: the mesh is not closed"),
])
def test_bad_boats_are_one_line_errors(tmp_path, capsys, change, match):
    (tmp_path / "box.obj").write_text(BOX_OBJ)
    (tmp_path / "open.obj").write_text(BOX_OBJ.rsplit("f ", 1)[0])
    replacement = {r"give exactly one of mass \(kg\) or density": "mass = 9.0\ndensity = 10.0\n",
                   r"mass 300 kg sinks it": "mass = 300.0\n",
                   r"unknown key 'colour'": "mass = 9.0\ncolour = 1\n",
                   r"file: the mesh is not closed": 'file = "open.obj"\n'}[match]
    path = tmp_path / "bad.toml"
    path.write_text(BOAT_SCENE.replace(change, replacement))
    out = tmp_path / "o.npz"
    assert main(["simulate", str(path), "--steps", "5", "--save", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("lbwater simulate: error:")
    assert re.search(match, err), err
    assert not out.exists()
