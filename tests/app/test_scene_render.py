"""Renderer sections of scene files: every shipped scene loads and renders without a NaN or a
dropped ray; bad input gives one line naming the file, section, key and rule."""

from pathlib import Path

import numpy as np
import pytest

from app.errors import InputError
from app.scene import check_material_names, load_scene, parse_scene

SCENES = sorted((Path(__file__).resolve().parents[2] / "scenes").glob("*.toml"))


def test_the_pool_and_the_seed_scenes_ship():
    assert {p.stem for p in SCENES} >= {"pool", "hand", "human", "boat", "dragon", "buddha"}
    assert "tesina" not in " ".join(p.read_text() for p in SCENES)


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_shipped_scene_renders_finite(rt, path):
    from app.world import World

    world = World(load_scene(path), rt, width=24, height=16, water_steps=2)
    renderer = world.renderer
    img = world.frame()
    fb = renderer.read_framebuffer()
    assert np.isfinite(fb).all()
    assert fb.min() >= 0
    assert renderer.read_stats()["dropped"] == 0
    assert img[..., 3].min() == 255 and img[..., :3].std() > 1  # not a blank image


def parse(text, tmp_path):
    return parse_scene(text, tmp_path / "s.toml")


@pytest.mark.parametrize("text,needle", [
    ("[sky]\nsun_colour = [1, 1, 1]\n", "unknown key 'sun_colour'; valid keys: cubemap"),
    ("[sky]\nkind = 'hdr'\n", "kind = 'hdr' is not valid; allowed one of procedural, cubemap"),
    ("[sky]\nkind = 'cubemap'\n", "needs cubemap"),
    ("[[lights]]\nkind = 'spot'\ninner_angle = 40\nouter_angle = 30\n", "exceeds outer_angle"),
    ("[[lights]]\ncolor = 'white'\n", "color = 'white' should be a list of 3 numbers"),
    ("[[lights]]\ndirection = [0, 0, 0]\n", "direction must not be zero"),
    ("[materials.glass]\nior = 0.5\n", "ior = 0.5; use 0 (opaque) or a value in [1, 4]"),
    ("[materials.glass]\nreflectivity = 1.5\n", "reflectivity = 1.5 is out of range; "
                                                 "allowed in [0, 1]"),
    ("[materials.tile]\ntexture = 'nope.png'\n", "does not exist"),
    ("[[meshes]]\nfile = 'missing.obj'\n", "not found beside the scene or in scenes/models"),
    ("[[meshes]]\nfile = 'bunny_5k.obj'\nsize = -1\n", "size = -1 is out of range"),
    ("[shading]\nfresnel = 'fast'\n", "allowed one of exact, schlick"),
    ("[shading]\nexposure = true\n", "exposure = True should be a number"),
    ("[pool]\nwall_height = 0\n", "wall_height = 0 is out of range"),
])
def test_bad_renderer_sections_name_the_problem(tmp_path, text, needle):
    with pytest.raises(InputError) as err:
        parse(text, tmp_path)
    msg = str(err.value)
    assert needle in msg and "\n" not in msg and "s.toml" in msg


def test_undefined_material_and_pool_without_water(tmp_path):
    s = parse("[[meshes]]\nfile = 'bunny_5k.obj'\nmaterial = 'gold'\n", tmp_path)
    with pytest.raises(InputError, match="names material 'gold'; defined: none"):
        check_material_names(s)
    s = parse("[pool]\nwall_height = 1\n", tmp_path)
    with pytest.raises(InputError, match=r"\[pool\] needs a \[water\] section"):
        check_material_names(s)


def test_renderer_sections_parse(tmp_path):
    s = parse("""
[shading]
fresnel = "schlick"
[sky]
sun_direction = [0, 1, 0]
[[lights]]
kind = "spot"
position = [0, 2, 0]
[materials.red]
diffuse = [1, 0, 0]
[[meshes]]
file = "bunny_5k.obj"
material = "red"
rotation = [0, 90, 0]
""", tmp_path)
    assert s.shading.fresnel == "schlick"
    assert s.lights[0].kind == "spot"
    assert s.materials["red"].diffuse == (1.0, 0.0, 0.0)
    assert s.meshes[0].file.name == "bunny_5k.obj"
    check_material_names(s)


def test_mesh_shading_attributes():
    from app.meshes import (
        MODELS_DIR,
        load_mesh,
        load_mesh_groups,
        mtl_path,
        read_mtl,
        smooth_normals,
    )

    path = MODELS_DIR / "sailboat_15k.obj"
    V, F = load_mesh(path)
    ids, names = load_mesh_groups(path, len(F))
    assert len(ids) == len(F) and 0 <= ids.min() and ids.max() < len(names)
    assert {"Shiny", "NOTShiny", "WorldGridMaterial"} <= set(names)
    assert len(np.unique(ids)) >= 4
    mtl = read_mtl(mtl_path(path))
    assert mtl["WorldGridMaterial"]["Kd"] == (0.215861, 0.215861, 0.215861)
    assert mtl["Shiny"]["Ns"] == 200.0
    # a closed box: area-weighted vertex normals point away from its centre
    Vb = np.array([[x, y, z] for x in (0, 1) for y in (0, 2) for z in (0, 3)], np.float32)
    Fb = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    n = smooth_normals(Vb, Fb)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)
    assert (np.sum(n * (Vb - Vb.mean(axis=0)), axis=1) > 0).all()
