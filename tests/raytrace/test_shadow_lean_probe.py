"""The lean-shadow probe (kernels/render_shadow_lean_probe.cl, bench/shadow_lean_probe.py): its
two launches (shading writes a list of shadow rays, a second launch traces the list) against
render_shadow, the renderer's shadow stage, on the same level's hits: the same radiance, and a
list that holds exactly the rays render_shadow traces, crossing rays in front."""

from pathlib import Path

import numpy as np
import pytest

from app.world import World
from bench.shadow_lean_probe import LeanShadowProbe, compare
from raytrace.render_types import RAY

ROOT = Path(__file__).resolve().parents[2]
STATIC = ROOT / "bench" / "scenes" / "pool_static_boat.toml"   # no caustics
POOL = ROOT / "scenes" / "pool.toml"                            # caustics: the map's branch


@pytest.fixture(scope="module", params=[STATIC, POOL], ids=["static", "pool"])
def world(request, rt):
    w = World(request.param, rt, width=64, height=48, cells=64, bounces=1)
    for _ in range(3):
        w.frame(1 / 60)
    w.frame(0.0)
    rt.queue.finish()
    return w


@pytest.mark.parametrize("depth", [0, 1])
def test_probe_matches_render_shadow(world, depth):
    probe = LeanShadowProbe(world, depth)
    res = compare(probe)
    assert res["radiance_max"] > 0
    assert res["max_abs_diff"] <= 1e-5 * res["radiance_max"]
    traced = res["list_crossing"] + res["list_other"]
    assert 0 < traced <= probe.n
    if depth == 0:   # primary rays start in air: none of their hits' shadow rays crosses first
        assert res["list_crossing"] == 0


def test_list_holds_the_traced_rays(rt):
    """Without caustics the floor under the water is lit through it: level 1's list starts with
    those crossing rays, each a unit direction toward the sun from inside the water."""
    w = World(STATIC, rt, width=64, height=48, cells=64, bounces=1)
    w.frame(1 / 60)
    rt.queue.finish()
    probe = LeanShadowProbe(w, 1)
    *_, n_cross, n_other = probe.run_lean()
    rt.queue.finish()
    probe.restore()
    assert n_cross > 0
    lst = rt.to_host(probe.list, RAY, probe.capacity)
    front = lst[:n_cross]
    d = np.stack([front["dx"], front["dy"], front["dz"]], axis=1)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-5)
    sun = -w.render_scene.lights[0]["direction"][:3].astype(float)
    assert np.allclose(d, sun / np.linalg.norm(sun), atol=1e-5)
    assert np.all(front["medium"] >= 0)
    assert np.all(front["pixel"] < probe.n)
    assert len(np.unique(front["pixel"])) == n_cross   # one entry per hit (one light)
    back = lst[probe.capacity - n_other:]
    assert np.all(back["medium"] < 0)


@pytest.mark.parametrize("depth", [0, 1])
def test_hits_of_full_cells_first_give_render_shadow_s_radiance(rt, depth):
    """With a coarse light buffer (full cells under the boat), the renderer's shadow kernels
    over the hits of full cells first (render_shadow_ordered, _binned) write render_shadow's
    radiance exactly; the list holds each flagged hit once, the flags no other."""
    w = World(STATIC, rt, width=64, height=48, cells=64, bounces=1, light_buffer=24)
    w.frame(1 / 60)
    rt.queue.finish()
    probe = LeanShadowProbe(w, depth)
    res = compare(probe)
    assert res["ordered_equal"] and res["radiance_max"] > 0
    assert 0 < res["first_hits"] < probe.n
    probe.run_ordered()
    flags = rt.to_host(probe.first_flags, np.uint8, probe.n)
    first = rt.to_host(probe.first_list, np.uint32, res["first_hits"])
    probe.restore()
    assert sorted(first.tolist()) == np.flatnonzero(flags).tolist()


def test_every_level_s_list_in_one_launch_holds_each_level_s_rays(rt):
    """time_all_levels: the merged list holds exactly the rays of the six levels' own lists."""
    import argparse

    from bench.shadow_lean_probe import time_all_levels

    args = argparse.Namespace(scene=str(STATIC), device=rt, size=(64, 48), cells=64, settle=1,
                              repeats=1, light_buffer=24, full_first=True)
    out = time_all_levels(args)
    assert len(out["hits"]) == 6 and out["hits"][0] == 64 * 48 and out["hits"][1] > 0
    assert out["lean_all_one_launch_ms"] > 0 and out["primary_trace_ms"] > 0
    w = World(STATIC, rt, width=64, height=48, cells=64, bounces=1, light_buffer=24)
    w.frame(1 / 60)
    w.frame(0.0)
    rt.queue.finish()
    alone = 0
    for depth in (0, 1):
        probe = LeanShadowProbe(w, depth, full_first=True)
        *_, n_cross, n_other = probe.run_lean()
        alone += n_cross + n_other + probe.full_rays
    assert out["list"] >= alone > 0   # levels 2-5 add theirs
