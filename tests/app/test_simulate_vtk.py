"""``lbwater simulate --vtk DIR --every K``: a ParaView series that pyvista opens, holding the
fields ``simulate --save`` writes, and nothing from VTK on the terminal."""

import numpy as np
import pytest

from app.cli import main
from app.vtk_output import read_series

SCENE = """
[water]
size = [1.0, 0.75]
cells = [16, 12]
depth = 0.2
origin = [0.5, 0.1, -0.2]

[[water.drops]]
x = 0.4
y = 0.4
radius = 0.2
height = 0.03
"""


def test_vtk_series_matches_saved_fields(tmp_path, capfd):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    npz, vtk = tmp_path / "w.npz", tmp_path / "vtk"
    assert main([ "simulate", str(scene), "--steps", "25", "--chunk", "7", "--save", str(npz),
                 "--vtk", str(vtk), "--every", "10", "--quiet"]) == 0
    err = capfd.readouterr()
    assert "vtk" not in (err.out + err.err).lower()
    series = read_series(vtk / "water.pvd")
    saved = np.load(npz)
    times = [t for t, _ in series]
    assert len(series) == 4 and times == sorted(times) and times[0] == 0.0   # 0, 10, 20, 25
    assert times[-1] == pytest.approx(float(saved["time"]), rel=1e-6)
    mesh = series[-1][1]
    assert mesh.dimensions == (16, 12, 1)
    for name in ("h", "u", "v", "bed"):
        got = np.asarray(mesh.point_data[name]).reshape(12, 16)
        np.testing.assert_array_equal(got, saved[name])
    pts = np.asarray(mesh.points).reshape(12, 16, 3)
    np.testing.assert_allclose(pts[..., 1], 0.1 + saved["bed"] + saved["h"], rtol=1e-6)
    np.testing.assert_allclose(pts[0, :, 0], 0.5 + saved["x"], rtol=1e-6)
    np.testing.assert_allclose(pts[:, 0, 2], -0.2 + saved["y"], rtol=1e-6)
    first = np.asarray(series[0][1].point_data["h"])
    assert np.abs(first - saved["h"].ravel()).max() > 1e-4      # the water moved in between


def test_vtk_unwritable_folder_fails_before_simulating(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["simulate", str(scene), "--vtk", str(blocker / "sub"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(blocker / "sub") in err[0]
