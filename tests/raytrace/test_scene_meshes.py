"""app.meshes.load_mesh: shipped models load (from the committed caches), one-line errors."""

import shutil

import numpy as np
import pytest

from app.errors import InputError
from app.meshes import MODELS_DIR, load_mesh


@pytest.mark.parametrize("name, n_tris", [("dragon_100k.obj", 100_000),
                                          ("buddha_100k.obj", 100_000),
                                          ("utah_hand_00_handonly.obj", 15_855),
                                          ("bunny_5k.obj", 4968),
                                          ("stanford_bunny_69k.obj", 69_451),
                                          ("sailboat_15k.obj", 15_030)])
def test_shipped_models_have_fresh_caches(name, n_tris):
    v, t = load_mesh(name)
    assert v.dtype == np.float32 and t.dtype == np.uint32 and v.shape[1] == t.shape[1] == 3
    assert len(t) == n_tris and t.max() < len(v) and np.isfinite(v).all()
    # the committed cache is the one used (the GPU machine has no pyvista)
    with np.load(MODELS_DIR / "cache" / f"{name}.npz") as z:
        assert np.array_equal(z["triangles"], t)


def test_cache_is_made_and_invalidated(tmp_path):
    pytest.importorskip("pyvista")
    src = tmp_path / "quad.obj"
    src.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    v, t = load_mesh(src)
    assert len(t) == 2 and (tmp_path / "cache" / "quad.obj.npz").is_file()
    src.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n")
    v2, t2 = load_mesh(src)            # edited file: the stale cache is not used
    assert len(t2) == 1 and len(v2) == 3


@pytest.mark.parametrize("text, match", [
    (None, "mesh file not found"),
    ("this is not a mesh \x00\x01", "unreadable|no triangles"),
    ("v 0 0 0\nv 1 0 0\nl 1 2\n", "no triangles|no faces"),
    ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "non-finite"),
])
def test_bad_files_give_one_line_errors(tmp_path, text, match):
    pytest.importorskip("pyvista")
    path = tmp_path / "bad.obj"
    if text is not None:
        path.write_text(text)
    with pytest.raises(InputError, match=match) as e:
        load_mesh(path)
    assert "\n" not in str(e.value) and "bad.obj" in str(e.value)


def test_sailboat_mtl_travels_with_the_obj(tmp_path):
    pytest.importorskip("pyvista")  # a copy elsewhere has no cache beside it
    for f in ("sailboat_15k.obj", "sailboat_15k.mtl"):
        shutil.copy(MODELS_DIR / f, tmp_path / f)
    v, t = load_mesh(tmp_path / "sailboat_15k.obj")
    assert len(t) == 15_030
