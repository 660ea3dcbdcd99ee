"""RenderSettings.cost_bins (each work-group's shadow rays handed to its work-items grouped by
cost class, kernels/render_bins.h) gives the bytes of the unbinned
kernels, in either order of the levels, fused or not, over chunks, and in the pool with caustics
and a boat; the grouping itself against a NumPy reference."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pyopencl as cl
import pytest

from raytrace.render import BIN_WG, RenderSettings, device_cost_bins
from tests.raytrace.test_render_overlap import frame, glass_without_lights
from tests.raytrace.test_render_plans import build


def launches(r):
    return [(op[1].function_name, op[3]) for op in r._last_ops if op[0] == r._LAUNCH]


@pytest.mark.parametrize("fused,lights,chunk,overlap", [(False, True, None, True),
                                                        (True, True, 128, True),
                                                        (False, True, 128, False),
                                                        (False, False, None, True)])
def test_binned_shadow_rays_give_the_unbinned_bytes(rt, fused, lights, chunk, overlap):
    s = RenderSettings(width=20, height=14, bounces=3, spp=4, fuse_trace_shade=fused,
                       max_chunk_rays=chunk, overlap_levels=overlap)
    scene = build(rt, 2) if lights else glass_without_lights(rt)   # a glass box: crossings
    _, want, fb_want, st_want = frame(rt, scene, s)
    assert st_want["rays_per_depth"][3] > 0 and want[..., :3].std() > 5
    r, got, fb, st = frame(rt, scene, dataclasses.replace(s, cost_bins=True))
    assert np.array_equal(got, want) and np.array_equal(fb, fb_want) and st == st_want
    # with no counts yet every level from depth 1 is binned (local size BIN_WG), level 0 never
    binned = [(n, ls) for n, ls in launches(r) if n.endswith("_binned")]
    assert all(ls == (BIN_WG,) for _, ls in binned)
    assert bool(binned) == lights
    first = [n for n, _ in launches(r)][:4]   # raygen, level 0's trace (+ shade), shadow rays
    assert first[1].startswith("render_trace") and not any("binned" in n for n in first)
    # the next frame's plan has the counts, all under BIN_MIN_RAYS: nothing binned, same bytes
    assert np.array_equal(r.render(), want)
    assert len(r.chunks) > 1 or not any(n.endswith("_binned") for n, _ in launches(r))


def test_levels_of_many_rays_by_the_last_counts_are_binned(rt, monkeypatch):
    import raytrace.render as render_module

    s = RenderSettings(width=20, height=14, bounces=3, spp=4, cost_bins=True)
    scene = build(rt, 2)
    r, want, *_ = frame(rt, scene, dataclasses.replace(s, cost_bins=False))
    hint = r.read_stats()["rays_per_depth"]
    monkeypatch.setattr(render_module, "BIN_MIN_RAYS", hint[2])   # levels 1 and 2, not 3
    assert hint[1] >= hint[2] > hint[3] > 0
    r, got, *_ = frame(rt, scene, s)
    assert np.array_equal(r.render(), want)   # its plan from the counts
    ops = [op for op in r._last_ops if op[0] == r._LAUNCH]
    binned = [op for op in ops if op[1].function_name.endswith("_binned")]
    # level 1's shadow rays with level 2's trace, level 2's with level 3's: two launches
    assert [op[1].function_name for op in binned] == ["render_shadow_trace_binned"] * 2


def test_pool_with_caustics_and_a_boat_binned_gives_the_same_bytes(rt, monkeypatch):
    """The pool (floating boat, caustics: floor rays of the LOOKUP class, walls under the water
    CROSSING): every level from depth 1 binned gives the bytes of the unbinned frames."""
    import raytrace.render as render_module
    from app.frames import with_shading
    from app.scene import load_scene
    from app.world import World

    monkeypatch.setattr(render_module, "BIN_MIN_RAYS", 0)
    scene = with_shading(load_scene(Path(__file__).parents[2] / "scenes" / "pool.toml"),
                         {"caustics": "traced", "caustic_photons": 4096})
    images = []
    for on in (False, True):
        world = World(scene, rt, width=48, height=28, cells=40, water_steps=5)
        world.renderer.set_cost_bins(on)
        images.append([world.frame(1 / 60).copy() for _ in range(3)])
        names = [op[1].function_name for op in world.renderer._last_ops
                 if op[0] == world.renderer._LAUNCH]
        assert any(n.endswith("_binned") for n in names) == on
    assert all(np.array_equal(a, b) for a, b in zip(*images, strict=True))
    assert images[0][-1][..., :3].std() > 5


def test_set_cost_bins_switches_and_keeps_the_image(rt, monkeypatch):
    import raytrace.render as render_module

    monkeypatch.setattr(render_module, "BIN_MIN_RAYS", 0)   # binned whatever the counts
    s = RenderSettings(width=16, height=12, bounces=2)
    scene = build(rt, 2)
    r, want, *_ = frame(rt, scene, s)
    for on in (True, False, True):
        r.set_cost_bins(on)
        assert np.array_equal(r.render(), want), on
        assert any(n.endswith("_binned") for n, _ in launches(r)) == on


@pytest.mark.parametrize("n,groups", [(1000, 2), (256, 1), (5, 3), (777, 7)])
def test_bin_round_groups_each_rounds_entries_by_class(rt, n, groups):
    """Each round of BIN_WG entries comes out as a permutation of itself, sorted by class
    (the order within a class is the local atomics' and never matters)."""
    rng = np.random.default_rng(n)
    classes = rng.integers(0, 4, n).astype(np.uint32)
    k = cl.Kernel(rt.program("render_bins_probe.cl"), "render_bins_probe")
    rounds = -(-n // BIN_WG)
    out = np.full(rounds * BIN_WG, 0xDEADBEEF, np.uint32)
    out_buf, cls_buf = rt.to_device(out), rt.to_device(classes)   # held while the kernel runs
    k.set_args(cls_buf, np.uint32(n), out_buf)
    cl.enqueue_nd_range_kernel(rt.queue, k, (groups * BIN_WG,), (BIN_WG,))
    got = rt.to_host(out_buf, np.uint32, out.size)
    padded = np.concatenate([classes, np.full(rounds * BIN_WG - n, 3, np.uint32)])
    for r in range(rounds):
        want = np.arange(r * BIN_WG, (r + 1) * BIN_WG)
        g = got[r * BIN_WG:(r + 1) * BIN_WG]
        assert np.array_equal(np.sort(g), want)
        assert np.all(np.diff(padded[g].astype(int)) >= 0)   # costliest class first


def test_header_mirrors_and_device_choice(rt):
    import types

    text = (Path(__file__).parents[2] / "kernels" / "render_bins.h").read_text()
    defs = dict(re.findall(r"#define (RENDER_BIN\w*) (\d+)", text))
    assert int(defs["RENDER_BIN_WG"]) == BIN_WG
    assert device_cost_bins(types.SimpleNamespace(is_gpu=True))
    assert not device_cost_bins(types.SimpleNamespace(is_gpu=False))
