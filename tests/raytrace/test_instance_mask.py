"""Instance visibility masks (kernels/bvh.h Instance.mask): a masked query sees only instances
sharing a bit with its mask; RenderScene marks instances opaque or transmissive for the shadow
rays (render_shadow.h)."""

import numpy as np
import pytest

from raytrace import RayQuery, Scene
from raytrace.bvh import HIT_DTYPE
from raytrace.query import pack_rays
from raytrace.render_scene import Material, RenderScene
from raytrace.render_types import MASK_OPAQUE, MASK_TRANSMISSIVE
from raytrace.scene import MASK_ALL
from tests.raytrace.test_render import quad

TRI = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]]))


def stacked(rt):
    """One triangle twice: instance 0 at z = 0, instance 1 behind it at z = -1."""
    scene = Scene(rt)
    mesh = scene.add_mesh(*TRI)
    scene.add_instance(mesh)
    m = np.eye(4)
    m[2, 3] = -1.0
    scene.add_instance(mesh, m)
    return scene


def hit_instance(rt, scene, mask, any_hit=False):
    ro, rd = pack_rays([[0.2, 0.3, 1.0]], [[0.0, 0.0, -1.0]])
    hits = rt.buffer(HIT_DTYPE.itemsize)
    RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits, 1, any_hit=any_hit,
             mask=mask).enqueue()
    h = rt.to_host(hits, HIT_DTYPE, 1)[0]
    return int(h["inst"]), float(h["t"])


def test_masked_queries_see_only_their_instances(rt):
    scene = stacked(rt)
    scene.update()
    assert scene.instance_mask(0) == scene.instance_mask(1) == MASK_ALL
    assert hit_instance(rt, scene, MASK_ALL) == (0, 1.0)
    scene.set_instance_mask(0, 1)
    scene.set_instance_mask(1, 2)
    assert hit_instance(rt, scene, 1) == (0, 1.0)  # not yet: masks apply at the next update
    assert hit_instance(rt, scene, 2) == (0, 1.0)
    scene.update()
    assert hit_instance(rt, scene, 1) == (0, 1.0)
    assert hit_instance(rt, scene, 2) == (1, 2.0)
    assert hit_instance(rt, scene, 2, any_hit=True) == (1, 2.0)
    assert hit_instance(rt, scene, 3) == (0, 1.0)
    assert hit_instance(rt, scene, 4)[0] == -1
    with pytest.raises(ValueError, match="mask"):
        scene.set_instance_mask(0, -1)
    with pytest.raises(ValueError, match="out of range"):
        scene.set_instance_mask(2, 1)


def test_render_scene_marks_opaque_and_transmissive_instances(rt):
    sc = RenderScene(rt)
    stone = sc.add_material(Material(diffuse=(0.5, 0.5, 0.5)))
    glass = sc.add_material(Material(ior=1.5))
    mirror = sc.add_material(Material(reflectivity=0.8))
    V, F = quad((0, 0, 0), 1)
    opaque = sc.add_instance(sc.add_mesh(V, F, material=stone))
    water = sc.add_instance(sc.add_mesh(V, F, material=glass))
    mixed = sc.add_instance(sc.add_mesh(V, F, tri_materials=[mirror, glass]))
    shiny = sc.add_instance(sc.add_mesh(V, F, tri_materials=[mirror, stone]))
    overridden = sc.add_instance(sc.add_mesh(V, F, material=stone), material=glass)
    sc.update()
    masks = [sc.scene.instance_mask(i) for i in (opaque, water, mixed, shiny, overridden)]
    assert masks == [MASK_OPAQUE, MASK_TRANSMISSIVE, MASK_TRANSMISSIVE, MASK_OPAQUE,
                     MASK_TRANSMISSIVE]
