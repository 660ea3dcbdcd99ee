"""``lbwater render``: a PNG (and AOVs) on success; on bad input one line, exit 2, no file."""

import numpy as np
import pytest

from app.cli import main

SCENE = """
[render]
width = 16
height = 12
[camera]
eye = [0.0, 0.3, 0.6]
target = [0.0, 0.1, 0.0]
[[lights]]
direction = [-0.3, -1, -0.2]
[[meshes]]
file = "bunny_5k.obj"
size = 0.3
"""


def test_render_writes_png_and_aov(tmp_path, capsys):
    import imageio.v3 as iio

    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out, aov = tmp_path / "o.png", tmp_path / "a.npz"
    assert main(["render", str(scene), "-o", str(out), "--aov", str(aov), "--width", "20"]) == 0
    img = iio.imread(out)
    assert img.shape == (12, 20, 4) and img.dtype == np.uint8
    with np.load(aov) as z:
        assert set(z.files) >= {"depth", "normal", "prim", "inst"}
        hit = z["prim"] >= 0
        assert 0 < hit.mean() < 1
        assert np.isfinite(z["depth"][hit]).all() and np.isinf(z["depth"][~hit]).all()
    assert not list(tmp_path.glob("*.partial*"))


@pytest.mark.parametrize("args,needle", [
    (["--spp", "0"], "--spp 0 is out of range"),
    (["--width", "99999"], "--width 99999 is out of range"),
    (["-o", "x.jpg"], "must end in .png"),
    (["--aov", "a.txt"], "must end in .npz"),
])
def test_bad_arguments(tmp_path, capsys, args, needle):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    argv = ["render", str(scene), "-o", str(tmp_path / "o.png")] + args
    if "-o" in args:
        argv = ["render", str(scene)] + args
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and "\n" not in err
    assert not (tmp_path / "o.png").exists() and not list(tmp_path.glob("*.partial*"))


def test_bad_scene_leaves_no_png(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE + "\n[materials.x]\nior = 9\n")
    out = tmp_path / "o.png"
    assert main(["render", str(scene), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "ior = 9 is out of range" in err and "\n" not in err
    assert not out.exists() and not list(tmp_path.glob("*.partial*"))
    assert main(["render", str(tmp_path / "none.toml"), "-o", str(out)]) == 2
    assert "does not exist" in capsys.readouterr().err
