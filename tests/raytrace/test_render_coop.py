"""RenderSettings.coop_from (the trace and shadow rays of the deeper levels traversed one per
work-group, kernels/traverse_coop.h) gives the bytes of the per-work-item walk (the same hits,
ties included), whatever the order of the levels (overlap_levels), fused or not, over chunks.
(On a CPU the cooperative kernels take the serial walk, TRACE_COOP_SERIAL: there these check
the kernels' plumbing; the walk itself is checked through trace_query.cl in
test_trace_coop.py, and the whole on a GPU by bench/h200_session3.sh.)"""

import dataclasses

import numpy as np
import pytest

from raytrace.render import RenderSettings
from tests.raytrace.test_render_overlap import frame, glass_without_lights, stages
from tests.raytrace.test_render_plans import build
from tests.raytrace.test_trace_coop import binary_rt  # noqa: F401  (fixture)


def same(a, b):
    return np.array_equal(a, b)


@pytest.mark.parametrize("coop_from,fused,lights,chunk", [(1, False, True, None),
                                                          (2, True, True, 128),
                                                          (2, False, True, None),
                                                          (1, False, False, 128)])
def test_coop_levels_give_the_serial_image(binary_rt, coop_from, fused, lights, chunk):  # noqa: F811
    rt = binary_rt
    s = RenderSettings(width=20, height=14, bounces=3, spp=4, fuse_trace_shade=fused,
                       max_chunk_rays=chunk)
    scene = build(rt, 2) if lights else glass_without_lights(rt)
    _, want, _, st = frame(rt, scene, s)
    assert st["rays_per_depth"][3] > 0 and want[..., :3].std() > 5
    c = dataclasses.replace(s, coop_from=coop_from)
    r_on, on, fb_on, st_on = frame(rt, scene, c)
    r_off, off, fb_off, st_off = frame(rt, scene, dataclasses.replace(c, overlap_levels=False))
    assert same(on, want) and st_on == st
    assert np.array_equal(on, off) and np.array_equal(fb_on, fb_off) and st_on == st_off
    assert scene.scene.coop_redos() == 0
    # the next frame's plan has this one's counts, all few: with one chunk the cooperative
    # kernels ran (local size 32), for the same bytes (several chunks have no counts to go by)
    for r in (r_on, r_off):
        assert same(r.render(), want)
        coop = [op for op in r._last_ops if op[0] == r._LAUNCH and op[1].function_name.endswith(
            "_coop")]
        assert all(op[3] == (32,) for op in coop) and bool(coop) == (len(r.chunks) == 1)


def test_set_coop_switches_and_validates(binary_rt):  # noqa: F811
    rt = binary_rt
    s = RenderSettings(width=16, height=12, bounces=2)
    scene = build(rt, 2)
    _, want, *_ = frame(rt, scene, s)
    r, *_ = frame(rt, scene, s)
    for first in (0, 2, None, 1):
        r.set_coop(first)
        got = r.render()
        assert same(got, want), first
        names = [op[1].function_name for op in r._last_ops if op[0] == r._LAUNCH]
        assert any(n.endswith("_coop") for n in names) == (first is not None)
    assert "render.shadow_trace" in stages(r)
    for bad in (-1, 99, 1.5):
        with pytest.raises(ValueError, match="coop_from must be None or an integer"):
            r.set_coop(bad)


def test_coplanar_ties_give_the_serial_bytes(binary_rt):  # noqa: F811
    """build(rt, 3): two boxes share a face (hits there tie: the same t on two instances); the
    same bytes as the serial walk, in either order of the levels."""
    rt = binary_rt
    s = RenderSettings(width=20, height=14, bounces=3, spp=4, coop_from=1)
    scene = build(rt, 3)
    _, want, fb_want, st_want = frame(rt, scene, dataclasses.replace(s, coop_from=None))
    _, on, fb_on, st_on = frame(rt, scene, s)
    assert same(on, want) and same(fb_on, fb_want) and st_on == st_want
    _, off, fb_off, st_off = frame(rt, scene, dataclasses.replace(s, overlap_levels=False))
    assert np.array_equal(on, off) and np.array_equal(fb_on, fb_off) and st_on == st_off


def test_a_level_of_many_rays_goes_one_per_work_item(binary_rt, monkeypatch):  # noqa: F811
    """The cooperative kernels check the device-side count: a level of more than
    TRACE_COOP_MAX_RAYS rays goes one ray per work-item in them (here the plan is made to pick
    them for level 0's 19200 primary rays: the host's threshold raised), the deeper levels a
    group per ray; the serial bytes, in either order of the levels."""
    import raytrace.render as render_module
    from raytrace.query import COOP_MAX_RAYS

    rt = binary_rt
    s = RenderSettings(width=160, height=120, bounces=2, spp=1)
    scene = build(rt, 2)
    _, want, _, st = frame(rt, scene, s)
    assert st["rays_per_depth"][0] > COOP_MAX_RAYS >= st["rays_per_depth"][1] > 0
    monkeypatch.setattr(render_module, "COOP_MAX_RAYS", 10**9)
    for overlap in (True, False):
        r, got, *_ = frame(rt, scene, dataclasses.replace(s, coop_from=0,
                                                           overlap_levels=overlap))
        assert same(got, want)
        assert same(r.render(), want)   # the plan from the counts: level 0 cooperative too
        names = [op[1].function_name for op in r._last_ops if op[0] == r._LAUNCH]
        assert names[1] == "render_trace_coop"   # after raygen: level 0's trace


def test_header_mirrors():
    import re
    from pathlib import Path

    from raytrace.query import COOP_MAX_RAYS, COOP_WIDTH

    text = (Path(__file__).parents[2] / "kernels" / "traverse_coop.h").read_text()
    defs = dict(re.findall(r"#define (TRACE_COOP_\w+) (\d+)", text))
    assert int(defs["TRACE_COOP_WIDTH"]) == COOP_WIDTH
    assert int(defs["TRACE_COOP_MAX_RAYS"]) == COOP_MAX_RAYS


def test_the_device_choice_is_cooperative_only_on_a_gpu_with_the_binary_layout(rt):
    """A frame's coop_from (raytrace.render.device_coop_from): GPU_COOP_FROM on a GPU with the
    binary BVH layout, off on a CPU (a 32-wide group would trace each ray 32 times over)."""
    import types

    from raytrace.render import GPU_COOP_FROM, device_coop_from

    gpu = types.SimpleNamespace(is_gpu=True, bvh_layout="binary")
    assert device_coop_from(gpu) == GPU_COOP_FROM == 2
    assert device_coop_from(types.SimpleNamespace(is_gpu=True, bvh_layout="wide")) is None
    assert device_coop_from(types.SimpleNamespace(is_gpu=False, bvh_layout="binary")) is None
    assert device_coop_from(rt) == (GPU_COOP_FROM if rt.is_gpu and rt.bvh_layout == "binary"
                                    else None)


def test_plan_picks_the_cooperative_kernels_by_the_last_counts(binary_rt):  # noqa: F811
    """Levels of few rays (their last counts, ``few``) take the cooperative kernels; a combined
    launch of level d's shadow rays and level d + 1's trace takes them when both levels are
    few, not for many shadow rays beside few traces."""
    rt = binary_rt
    r, *_ = frame(rt, build(rt, 2), RenderSettings(width=16, height=12, bounces=3, coop_from=2))
    sizes = tuple(r._launch_sizes(depths, None) for *_, depths in r._plan)

    def kernels(few, bins=(False,) * 4):
        return [op[1].function_name for op in r._make_plan(sizes, 3, True, few, bins)
                if op[0] == r._LAUNCH]

    assert not any(n.endswith("_coop") for n in kernels((None,) * 4))
    both = kernels((None, None, 90, 40))      # S2+T3 cooperative, S3 too; S1+T2 plain
    assert both.count("render_shadow_trace_coop") == 1 and "render_shadow_coop" in both
    assert both.count("render_shadow_trace") == 1
    tail = kernels((None, None, None, 40))    # level 2 many: S2+T3 plain, S3 cooperative
    assert "render_shadow_trace_coop" not in tail and "render_shadow_coop" in tail
    first = kernels((None, None, 90, None))   # level 1 many, level 2 few: S1+T2 plain
    assert "render_shadow_trace_coop" not in first and "render_shadow_coop" not in first
    assert first.count("render_shadow_trace") == 2   # S1+T2, S2+T3
    # with level 1's shadow rays binned (cost_bins, many rays): S1+T2 binned
    r.set_cost_bins(True)
    r._bind(3)
    binned = kernels((None, None, 90, None), (False, True, False, False))
    assert "render_shadow_trace_coop" not in binned
    assert binned.count("render_shadow_trace_binned") == 1
