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


def test_boats_series_places_each_mesh_by_the_saved_pose(tmp_path):
    """boats.pvd: at the start the mesh sits where the scene puts it (the renderer's placement,
    app.assets.mesh_transform); at the end it is the file's mesh moved by the pose simulate
    --save writes: vertices = R(q) (V - c) + p, c the box's centroid (0, 0.1, 0) analytically
    (size 0 keeps the file's frame; no mass_height: the centre of mass is the centroid)."""
    from app.assets import mesh_transform
    from app.meshes import load_mesh
    from lbm.bodies import matrix_from_quat
    from tests.lbm.test_cmd_simulate import BOX_OBJ

    (tmp_path / "box.obj").write_text(BOX_OBJ)
    scene = tmp_path / "b.toml"
    scene.write_text("""
[water]
size = [1.6, 1.0]
cells = [32, 20]
depth = 0.3
viscosity = 1e-3

[[boats]]
file = "box.obj"
mass = 9.0
position = [0.8, 0.33, 0.5]
rotation = [0.0, 30.0, 10.0]
""")
    npz, vtk = tmp_path / "b.npz", tmp_path / "vtk"
    assert main(["simulate", str(scene), "--steps", "60", "--save", str(npz), "--vtk", str(vtk),
                 "--every", "40", "--quiet"]) == 0
    water, boats = read_series(vtk / "water.pvd"), read_series(vtk / "boats.pvd")
    assert [t for t, _ in boats] == [t for t, _ in water] and len(boats) == 3   # 0, 40, 60
    V, F = load_mesh(tmp_path / "box.obj")   # the rendered mesh, as the scene loads it
    first, last = boats[0][1], boats[-1][1]
    assert last.n_points == len(V) and last.n_cells == len(F)
    assert set(np.asarray(last.cell_data["boat"]).tolist()) == {0}
    M0 = mesh_transform(V, (0.8, 0.33, 0.5), (0.0, 30.0, 10.0), 0.0)
    np.testing.assert_allclose(first.points, V @ M0[:3, :3].T + M0[:3, 3], atol=2e-6)
    saved = np.load(npz)
    p, q = saved["boat_position"][0], saved["boat_rotation"][0]
    want = (V - (0.0, 0.1, 0.0)) @ matrix_from_quat(q).T + p
    np.testing.assert_allclose(last.points, want, atol=2e-6)
    assert np.abs(want - first.points).max() > 1e-3          # the boat moved in between
    tri = np.asarray(last.faces).reshape(-1, 4)
    assert (tri[:, 0] == 3).all() and np.array_equal(tri[:, 1:], F)
