"""Shadow rays: a light whose share of the pixel is below min_weight is added unshadowed with no
shadow ray (the water's sharp highlight away from the sun's mirror direction); the opaque
blockers are found before the water is crossed. Checked against the float64 pipeline, image and
shadow-ray count, with the counters of a TRACE_COUNT build."""

import dataclasses

import numpy as np
import pytest

from kernels.runtime import Runtime
from raytrace import render_reference as ref
from raytrace.render import Renderer, RenderSettings
from raytrace.render_scene import Material, RenderScene
from tests.raytrace.test_render import box, quad


@pytest.fixture(scope="module")
def rt_count(rt):
    return Runtime(rt.device, defines={"TRACE_COUNT": 1})


def pond(rt):
    """Flat water over a tiled floor, an opaque slab above the water shadowing part of it, the
    sun in the camera's mirror direction (its highlight in view)."""
    sc = RenderScene(rt)
    floor = sc.add_material(Material(diffuse=(0.8, 0.75, 0.7), specular=(0.1, 0.1, 0.1)))
    water = sc.add_material(Material(diffuse=(0, 0, 0), specular=(1, 1, 1), shininess=400,
                                     ior=1.333, absorption=(0.45, 0.09, 0.06)))
    slab = sc.add_material(Material(diffuse=(0.5, 0.3, 0.2)))
    V, F = quad((0, -0.4, 0), 4)
    sc.add_instance(sc.add_mesh(V, F, material=floor))
    V, F = quad((0, 0, 0), 4)
    sc.add_instance(sc.add_mesh(V, F, material=water))
    V, F = box((-0.2, 0.3, -0.9), (1.2, 0.35, 0.1))
    sc.add_instance(sc.add_mesh(V, F, material=slab))
    sc.add_light("directional", direction=(0.05, -0.6, 0.8), color=(2.0, 1.9, 1.8))
    return sc


def render(rt, settings):
    sc = pond(rt)
    r = Renderer(rt, sc, settings)
    r.set_camera((0.03, 1.5, 2.0), (0, 0, 0), (0, 1, 0), 60)
    sc.scene.update()
    sc.scene.reset_trace_counts()
    r.render()
    return sc, r


def check(rt, settings):
    """Render, compare image and shadow-ray count with the float64 pipeline; its output."""
    sc, r = render(rt, settings)
    fb = r.read_framebuffer()
    counts = sc.scene.trace_counts()["shadow"]
    out = ref.render(sc.tables(), r.camera, r.params(), sc.lights)
    ok = ~out["fragile"]
    assert ok.mean() > 0.95
    err = np.abs(fb - out["framebuffer"]).max(axis=2)
    assert np.all(err[ok] <= 2e-4 * np.maximum(1.0, out["framebuffer"].max(axis=2))[ok])
    # the kernels traced the shadow rays the reference traced (up to the fragile pixels)
    assert abs(counts["rays"] - out["shadow_rays"]) <= (~ok).sum()
    # the any-hit query of opaque blockers never entered the water (instance 1); the rays it
    # let through crossed the water alone, some of them (from the floor) through its surface
    crossing = sc.scene.trace_counts()["crossing"]
    assert counts["blas_nodes_by_instance"][1] == 0 and counts["blas_nodes"] > 0
    assert 0 < crossing["rays"] <= counts["rays"] - counts["hits"]
    assert crossing["blas_nodes_by_instance"][1] == crossing["blas_nodes"] > 0
    assert crossing["hits"] > 0
    return out, float(r.params()["min_weight"])


def test_faint_light_needs_no_shadow_ray(rt_count):
    s = RenderSettings(width=27, height=19, bounces=1)
    cut, min_weight = check(rt_count, s)
    # without the cut-off every lit hit traces a shadow ray: far more, and the image differs
    # by at most the cut-off where the faint light was occluded
    full, _ = check(rt_count, dataclasses.replace(s, min_weight=0.0))
    assert cut["shadow_rays"] < 0.7 * full["shadow_rays"]
    diff = np.abs(cut["framebuffer"] - full["framebuffer"]).max(axis=2)
    assert 0 < diff.max() <= 2 * min_weight


def crossing_counts(sc, r):
    return r.read_framebuffer(), sc.scene.trace_counts()["crossing"]


def test_crossings_walk_the_one_dielectric_instance_alone(rt_count):
    """The pond's water is its one instance holding a dielectric: with direct_crossings (the
    default) the shadow rays' crossings walk its BLAS with no TLAS node visited, the same rays
    and hits as through the TLAS, and the same image bytes."""
    s = RenderSettings(width=27, height=19, bounces=2)
    sc, r = render(rt_count, s)
    assert sc.crossing_instance == 1 and r.params()["crossing_instance"] == 1
    direct, cd = crossing_counts(sc, r)
    sc, r = render(rt_count, dataclasses.replace(s, direct_crossings=False))
    assert r.params()["crossing_instance"] == -1
    walked, ct = crossing_counts(sc, r)
    assert cd["tlas_nodes"] == 0 < ct["tlas_nodes"]
    assert cd["rays"] == ct["rays"] > 0 and cd["hits"] == ct["hits"] > 0
    # the walk alone visits the BLAS's root for the rays the TLAS would have culled at its box
    assert cd["blas_nodes"] >= ct["blas_nodes"]
    np.testing.assert_array_equal(direct, walked)


def test_crossing_instance_is_the_only_one(rt):
    """-1 where no instance, or more than one, holds a dielectric: the TLAS walk finds them."""
    sc = pond(rt)
    glass = sc.add_material(Material(diffuse=(0, 0, 0), ior=1.5))
    sc.update()
    assert sc.crossing_instance == 1
    V, F = box((0.5, 0.5, 0.5), (0.8, 0.8, 0.8))
    sc.add_instance(sc.add_mesh(V, F, material=glass))
    sc.update()
    assert sc.crossing_instance == -1
    dry = RenderScene(rt)
    V, F = quad((0, 0, 0), 1)
    dry.add_instance(dry.add_mesh(V, F, material=dry.add_material(Material())))
    dry.update()
    assert dry.crossing_instance == -1


def test_crossings_walk_the_height_field_alone(rt_count):
    """The pool's water, traced as a height field, is its one instance holding a dielectric:
    the crossings walk its cells with no TLAS node visited, and the frame is the same bytes as
    through the TLAS."""
    from pathlib import Path

    from app.world import World

    scene = Path(__file__).resolve().parents[2] / "bench" / "scenes" / "pool_static_boat.toml"
    frames = []
    for direct in (True, False):
        world = World(scene, rt_count, width=40, height=24, cells=64, water_steps=2)
        assert world.water_accel == "grid"
        world.renderer.set_direct_crossings(direct)
        world.renderer.set_one_crossing(False)   # every walk, as through the TLAS
        sc = world.render_scene
        sc.scene.reset_trace_counts()
        img = world.frame(0.0).copy()
        assert world.instances[sc.crossing_instance] == "water"
        frames.append((img, sc.scene.trace_counts()["crossing"]))
    (direct, cd), (walked, ct) = frames
    assert cd["tlas_nodes"] == 0 < ct["tlas_nodes"]
    assert cd["rays"] == ct["rays"] > 0 and cd["hits"] == ct["hits"] > 0
    np.testing.assert_array_equal(direct, walked)
