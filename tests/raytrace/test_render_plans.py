"""The renderer's launch plans (made once, reused while nothing they depend on changes) give
the image a fresh renderer gives after every change: camera, a reflective material that adds
the secondary levels, a new instance (rebound buffers), stage names per depth, lights, chunks."""

import numpy as np
import pytest

from raytrace.render import Renderer, RenderSettings
from raytrace.render_scene import Material, RenderScene
from tests.raytrace.test_render_dynamic import grid, surface

BOX = (np.array([[-0.3, 0, -0.3], [0.3, 0, -0.3], [0.3, 0.5, -0.3], [-0.3, 0.5, -0.3],
                 [-0.3, 0, 0.3], [0.3, 0, 0.3], [0.3, 0.5, 0.3], [-0.3, 0.5, 0.3]],
                np.float32),
       [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [3, 6, 2],
        [3, 7, 6], [1, 2, 6], [1, 6, 5], [0, 4, 7], [0, 7, 3]])


def build(rt, steps: int):
    """The scene after the first ``steps`` changes, made from scratch."""
    sc = RenderScene(rt)
    floor = sc.add_material(Material(diffuse=(0.8, 0.7, 0.5)))
    v, _ = surface(6, 0.7)
    sc.add_instance(sc.add_mesh(v[:, :3], grid(6), material=floor))
    if steps >= 1:
        sc.add_light("directional", direction=(-0.3, -1, -0.2), color=(1, 1, 1))
    if steps >= 2:   # a mirror-ish box: secondary levels from now on
        glass = sc.add_material(Material(diffuse=(0.1, 0.2, 0.3), specular=(0.5, 0.5, 0.5),
                                         shininess=40, reflectivity=0.4, ior=1.33))
        sc.add_instance(sc.add_mesh(*BOX, material=glass))
    if steps >= 3:   # another instance: new tables, every kernel rebound
        sc.add_instance(sc.add_mesh(*BOX, material=0),
                        np.array([[1, 0, 0, 0.6], [0, 1, 0, 0], [0, 0, 1, -0.5]], np.float32))
    return sc


CAMERAS = [((0.3, 1.6, 2.4), (0, 0, 0)), ((-1.2, 1.1, 1.9), (0.1, 0.2, 0))]


def fresh(rt, steps, camera, settings):
    r = Renderer(rt, build(rt, steps), settings)
    r.set_camera(*camera, (0, 1, 0), 50)
    return r.render()


@pytest.mark.parametrize("chunk", [None, 128])
def test_each_change_gives_the_image_of_a_fresh_renderer(rt, chunk):
    settings = RenderSettings(width=20, height=14, bounces=3, max_chunk_rays=chunk)
    sc = build(rt, 0)
    r = Renderer(rt, sc, settings)
    assert (len(r.chunks) > 1) == (chunk is not None)
    floor = 0
    for steps, cam, per_depth in [(0, 0, False), (0, 1, False), (1, 1, False), (2, 1, False),
                                  (2, 0, True), (3, 0, True), (3, 0, False), (3, 1, False)]:
        if steps >= 1 and len(sc.lights) == 0:
            sc.add_light("directional", direction=(-0.3, -1, -0.2), color=(1, 1, 1))
        if steps >= 2 and len(sc.materials) == 1:
            glass = sc.add_material(Material(diffuse=(0.1, 0.2, 0.3), specular=(0.5, 0.5, 0.5),
                                             shininess=40, reflectivity=0.4, ior=1.33))
            sc.add_instance(sc.add_mesh(*BOX, material=glass))
        if steps >= 3 and len(sc.instances) == 2:
            sc.add_instance(sc.add_mesh(*BOX, material=floor),
                            np.array([[1, 0, 0, 0.6], [0, 1, 0, 0], [0, 0, 1, -0.5]],
                                     np.float32))
        r.set_stage_per_depth(per_depth)
        r.set_camera(*CAMERAS[cam], (0, 1, 0), 50)
        for _ in range(2):   # the second frame: the cached plan (and size hints) again
            got = r.render()
            want = fresh(rt, steps, CAMERAS[cam], settings)
            assert np.array_equal(got, want), (steps, cam, per_depth)
        assert r.read_stats()["levels"] == (3 if steps >= 2 else 0)
    assert len(r._plans) >= 3
