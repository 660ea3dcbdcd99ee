"""RenderSettings.overlap_levels (level d's shadow rays and level d + 1's trace in one launch,
render_shadow_trace.cl) changes only the order of the launches: the same bytes as the level by
level order, fused or not, with and without lights, over several chunks; switched at run time."""

import dataclasses

import numpy as np
import pytest

from raytrace.bvh import HIT_DTYPE
from raytrace.render import BYTES_PER_RAY_SLOT, Renderer, RenderSettings
from raytrace.render_scene import Material, RenderScene
from tests.raytrace.test_render_dynamic import grid, surface
from tests.raytrace.test_render_plans import BOX, CAMERAS, build


def glass_without_lights(rt):
    sc = RenderScene(rt)
    v, _ = surface(6, 0.7)
    sc.add_instance(sc.add_mesh(v[:, :3], grid(6), material=sc.add_material(Material())))
    glass = sc.add_material(Material(diffuse=(0.1, 0.2, 0.3), reflectivity=0.4, ior=1.33))
    sc.add_instance(sc.add_mesh(*BOX, material=glass))
    return sc


def frame(rt, scene, settings):
    r = Renderer(rt, scene, settings)
    r.set_camera(*CAMERAS[1], (0, 1, 0), 50)
    img = r.render()
    return r, img, r.read_framebuffer(), r.read_stats()


def stages(r):
    return [op[4] for op in r._last_ops if op[0] == r._LAUNCH]


@pytest.mark.parametrize("fused,lights,chunk", [(False, True, None), (True, True, 128),
                                                (False, False, 128), (True, False, None)])
def test_overlap_gives_the_bytes_of_the_level_by_level_order(rt, fused, lights, chunk):
    s = RenderSettings(width=20, height=14, bounces=3, spp=4, fuse_trace_shade=fused,
                       max_chunk_rays=chunk, overlap_from=0)
    scene = build(rt, 3) if lights else glass_without_lights(rt)
    r_on, *on = frame(rt, scene, s)
    r_off, *off = frame(rt, scene, dataclasses.replace(s, overlap_levels=False))
    assert np.array_equal(on[0], off[0]) and np.array_equal(on[1], off[1])
    assert on[2] == off[2] and on[2]["levels"] == 3 and on[2]["rays_per_depth"][3] > 0
    assert on[0][..., :3].std() > 5   # a picture, not a flat colour
    # one combined launch per deeper level (with lights), the last level's shadow rays alone
    n_chunks = len(r_on.chunks)
    assert (n_chunks > 1) == (chunk is not None)
    got = stages(r_on)
    assert got.count("render.shadow_trace") == 3 * n_chunks * lights
    assert got.count("render.shadow") == n_chunks * lights
    assert "render.shadow_trace" not in stages(r_off)
    assert stages(r_off).count("render.shadow") == 4 * n_chunks * lights
    # the same number of launches: scatter and accumulate apart, shadow and trace together
    assert len(got) == len(stages(r_off)) + (0 if lights else 3 * n_chunks)


def test_set_overlap_switches_the_order_and_keeps_the_image(rt):
    s = RenderSettings(width=16, height=12, bounces=2, overlap_levels=False)
    r = Renderer(rt, build(rt, 2), s)
    r.set_camera(*CAMERAS[0], (0, 1, 0), 50)
    assert r.hits[0] is r.hits[1] and r.memory_report()["bytes_per_ray_slot"] == 136
    want = r.render()
    r.set_overlap(True)
    assert r.hits[0] is not r.hits[1] and r.radiance[0] is r.radiance[1]
    assert r.memory_report()["bytes_per_ray_slot"] == 136 + HIT_DTYPE.itemsize
    for on, first, combined in ((True, 0, 2), (False, 0, 0), (True, 1, 1), (True, 2, 0),
                                (True, None, 0)):
        r.set_overlap(on, first)
        assert np.array_equal(r.render(), want), (on, first)
        # levels 0..2: level d < overlap_from (and the last) shoot their shadow rays alone
        assert stages(r).count("render.shadow_trace") == combined, (on, first)
        assert stages(r).count("render.shadow") == 3 - combined, (on, first)
    with pytest.raises(ValueError, match="overlap_from must be an integer"):
        r.set_overlap(True, -1)


def test_fused_overlap_double_buffers_the_radiance(rt):
    r = Renderer(rt, build(rt, 2), RenderSettings(width=8, height=8, fuse_trace_shade=True))
    assert r.radiance[0] is not r.radiance[1] and r.hits[0] is not r.hits[1]
    assert r.memory_report()["bytes_per_ray_slot"] == BYTES_PER_RAY_SLOT + HIT_DTYPE.itemsize + 16
