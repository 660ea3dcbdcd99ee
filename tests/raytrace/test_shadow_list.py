"""RenderSettings.shadow_list (kernels/render_shadow_list.cl): the shading lists every level's
shadow rays and one launch traces them after the last level. Against the float64 pipeline (image
and shadow-ray count), against the per-level shadow stage (the same light up to float rounding),
and against itself: the same bytes whatever the list's room (a ray with no room is traced at
once), the order of its atomics, the chunks, the light buffer, and run after run."""

import dataclasses

import numpy as np
import pytest

from kernels.runtime import Runtime
from raytrace import render_reference as ref
from raytrace.render import (
    BYTES_PER_RAY_SLOT,
    Renderer,
    RenderSettings,
    bytes_per_ray_slot,
    device_shadow_list,
    shadow_list_rooms,
)
from raytrace.render_types import SHADOW_RAY
from tests.raytrace.test_light_buffer import clutter
from tests.raytrace.test_render import tiny_scene
from tests.raytrace.test_render_plans import CAMERAS, build
from tests.raytrace.test_render_shadow import pond

LISTED = dict(shadow_list=True)


def frame(rt, sc, settings, eye=(0.5, 1.5, 3.0), target=(0, 0.3, 0)):
    r = Renderer(rt, sc, settings)
    r.set_camera(eye, target, (0, 1, 0), 50)
    img = r.render()
    return r, img, r.read_framebuffer(), r.read_stats()


def list_counts(rt, r) -> np.ndarray:
    """The last chunk's counts: rays of full cells (the first part holds them up to its room,
    the main part the rest), main part, spilled."""
    return rt.to_host(r.list_counts, np.uint32, 4)[:3]


@pytest.fixture(scope="module")
def rt_count(rt):
    return Runtime(rt.device, defines={"TRACE_COUNT": 1})


@pytest.mark.parametrize("scene", ["tiny", "pond"])
def test_matches_the_float64_pipeline_and_its_shadow_rays(rt_count, scene):
    """Two lights (a sun and a spot), glass, a mirror; or water over a floor: the image against
    the float64 pipeline, and the rays listed (none spilled) are the reference's shadow
    rays, which the trace counters saw traced."""
    s = RenderSettings(width=27, height=19, spp=1, bounces=3, **LISTED)
    make, eye, target = {"tiny": (tiny_scene, (0.5, 1.5, 3.0), (0, 0.3, 0)),
                         "pond": (pond, (0.03, 1.5, 2.0), (0, 0, 0))}[scene]
    sc = make(rt_count)
    r = Renderer(rt_count, sc, s)
    r.set_camera(eye, target, (0, 1, 0), 50)
    sc.scene.update()
    sc.scene.reset_trace_counts()
    img = r.render()
    fb, stats = r.read_framebuffer(), r.read_stats()
    out = ref.render(sc.tables(), r.camera, r.params(), sc.lights)
    ok = ~out["fragile"]
    assert ok.mean() > 0.95
    err = np.abs(fb - out["framebuffer"]).max(axis=2)
    assert np.all(err[ok] <= 2e-4 * np.maximum(1.0, out["framebuffer"].max(axis=2))[ok])
    assert np.abs(img.astype(int) - out["rgba"].astype(int))[ok].max() <= 1
    assert stats["shadow_rays_spilled"] == 0
    assert abs(stats["shadow_rays_listed"] - out["shadow_rays"]) <= (~ok).sum()
    assert stats["shadow_rays_listed"] == sc.scene.trace_counts()["shadow"]["rays"] > 50
    assert stats["rays_per_depth"][1] > 0


def stages(r):
    return [op[4] for op in r._last_ops if op[0] == r._LAUNCH]


@pytest.mark.parametrize("chunk", [None, 128])
def test_the_per_level_stage_light_up_to_rounding(rt, chunk):
    """Spots and suns, several chunks: the framebuffer of the per-level shadow launches up to
    float rounding, the image within one level of a byte; one shadow launch per chunk."""
    s = RenderSettings(width=24, height=20, spp=4, bounces=3, max_chunk_rays=chunk)
    sc = tiny_scene(rt)
    r0, img0, fb0, st0 = frame(rt, sc, s)
    r1, img1, fb1, st1 = frame(rt, sc, dataclasses.replace(s, **LISTED))
    np.testing.assert_allclose(fb1, fb0, rtol=1e-5, atol=1e-6)
    assert np.abs(img1.astype(int) - img0).max() <= 1
    assert st1["rays_per_depth"] == st0["rays_per_depth"]
    assert st0["shadow_rays_listed"] == 0 < st1["shadow_rays_listed"]
    n_chunks = len(r1.chunks)
    assert (n_chunks > 1) == (chunk is not None)
    got = stages(r1)
    # per chunk the list's launch and, from the first level whose rays could find the list
    # full (two lights: level 0's could not), each level's launch for the rays with no room
    assert r1._first_spill(int(r1._plan[0][0]["n_rays"])) == 1
    assert got.count("render.shadow") == 4 * n_chunks and "render.shadow_trace" not in got
    names = [op[1].function_name for op in r1._last_ops if op[0] == r1._LAUNCH]
    assert names.count("render_shadow_spill") == 3 * n_chunks
    assert got.count("render.shade") == 4 * n_chunks   # levels 0..3, each shading its hits
    assert img1[..., :3].std() > 5


def test_no_room_changes_no_byte(rt):
    """Room for every ray, for some (the rest spilled: traced by their level's
    render_shadow_spill), for none: the same bytes, framebuffer too, and the same rays traced;
    the counts say where they went."""
    s = RenderSettings(width=24, height=18, spp=2, bounces=3, **LISTED)
    sc = tiny_scene(rt)
    runs = [frame(rt, sc, dataclasses.replace(s, shadow_list_room=room))
            for room in (0.5, 0.004, 0.0)]
    (_, img, fb, st), *rest = runs
    assert st["shadow_rays_spilled"] == 0 < st["shadow_rays_listed"]
    total = st["shadow_rays_listed"]
    for _, img_b, fb_b, st_b in rest:
        assert np.array_equal(img, img_b) and np.array_equal(fb, fb_b)
        assert st_b["shadow_rays_listed"] + st_b["shadow_rays_spilled"] == total
    assert 0 < runs[1][3]["shadow_rays_listed"] < total       # partly listed
    assert runs[2][3]["shadow_rays_listed"] == 0              # none listed
    main, full = shadow_list_rooms(runs[1][0].settings, runs[1][0].capacity)
    assert runs[1][3]["shadow_rays_listed"] <= main + full


def test_same_bytes_run_after_run_and_frame_after_frame(rt):
    """The list's atomics land in another order each run (PoCL's work-groups on two cores):
    the pixels' fixed-point sums never show it."""
    s = RenderSettings(width=32, height=24, spp=4, bounces=4, **LISTED)
    sc = build(rt, 3)
    r = Renderer(rt, sc, s)
    r.set_camera(*CAMERAS[1], (0, 1, 0), 50)
    first = r.render()
    fb = r.read_framebuffer()
    for _ in range(3):
        assert np.array_equal(r.render(), first)
        assert np.array_equal(r.read_framebuffer(), fb)
    again = Renderer(rt, sc, s)
    again.set_camera(*CAMERAS[1], (0, 1, 0), 50)
    assert np.array_equal(again.render(), first)


def test_with_the_light_buffer_and_its_full_cells(rt):
    """With a map of the sun's blockers the list's rays get the same answers (the same bytes as
    without a map). The stacks of triangles along the light fill cells past their room at 48
    cells, and a third of the map at 3: their rays take the list's first part, and past its
    room the main part."""
    s = RenderSettings(width=24, height=18, spp=2, bounces=3, **LISTED)
    sc = clutter(rt, spot=True, stacks=True)
    r0, img0, fb0, _ = frame(rt, sc, s, *CAMERAS[1])
    assert list_counts(rt, r0)[0] == 0   # no map: no full cells
    fulls = []
    for cells in (48, 3):
        r1, img1, fb1, st1 = frame(rt, sc, dataclasses.replace(s, light_buffer=cells),
                                   *CAMERAS[1])
        assert np.array_equal(img0, img1) and np.array_equal(fb0, fb1)
        assert r1.light_buffer.active
        full, main, spilled = list_counts(rt, r1)
        room = int(r1.list_params["full_room"])
        assert spilled == 0 and min(full, room) + main == st1["shadow_rays_listed"]
        fulls.append((full, room))
    assert 0 < fulls[0][0] < fulls[0][1]       # 48 cells: all in the first part
    assert fulls[1][0] > fulls[1][1]           # 3 cells: more than its room


def test_switched_on_and_off_at_run_time(rt):
    s = RenderSettings(width=20, height=14, bounces=2)
    sc = build(rt, 3)
    r = Renderer(rt, sc, s)
    r.set_camera(*CAMERAS[0], (0, 1, 0), 50)
    off = r.render()
    assert r.shadow_list is None and r.memory_report()["bytes_per_ray_slot"] > 0
    r.set_shadow_list(True)
    on = r.render()
    fresh = frame(rt, sc, dataclasses.replace(s, **LISTED), *CAMERAS[0])[1]
    assert np.array_equal(on, fresh) and np.abs(on.astype(int) - off).max() <= 1
    assert "render.shadow_trace" not in stages(r)
    r.set_shadow_list(True, room=0.0)
    assert np.array_equal(r.render(), on) and r.read_stats()["shadow_rays_listed"] == 0
    r.set_shadow_list(False)
    assert np.array_equal(r.render(), off)
    with pytest.raises(ValueError, match="shadow_list_room must lie in"):
        r.set_shadow_list(True, room=-1)


def test_no_lights_no_list(rt):
    from tests.raytrace.test_render_overlap import glass_without_lights

    s = RenderSettings(width=20, height=14, bounces=2)
    sc = glass_without_lights(rt)
    _, img0, fb0, _ = frame(rt, sc, s, *CAMERAS[1])
    r, img1, fb1, st = frame(rt, sc, dataclasses.replace(s, **LISTED), *CAMERAS[1])
    assert np.array_equal(img0, img1) and np.array_equal(fb0, fb1)
    assert "render.shadow" not in stages(r) and st["shadow_rays_listed"] == 0


def test_memory_and_settings(rt):
    s = RenderSettings(**LISTED)
    assert bytes_per_ray_slot(s) == BYTES_PER_RAY_SLOT + -(-SHADOW_RAY.itemsize * 9 // 16)
    assert bytes_per_ray_slot(dataclasses.replace(s, shadow_list_room=0.0)) == BYTES_PER_RAY_SLOT
    assert shadow_list_rooms(s, 1000) == (500, 62)
    assert SHADOW_RAY.itemsize == 32
    for bad in (-0.1, 8.5, float("nan")):
        with pytest.raises(ValueError, match="shadow_list_room must lie in"):
            RenderSettings(shadow_list=True, shadow_list_room=bad).resolved()
    assert device_shadow_list(rt) == bool(rt.is_gpu)
    r = Renderer(rt, build(rt, 1), dataclasses.replace(s, width=16, height=8))
    main, full = shadow_list_rooms(r.settings, r.capacity)
    assert r.shadow_list.size == (main + full) * SHADOW_RAY.itemsize
    assert r.shadow_light.size == 24 * r.n_q


def test_header_constants_mirror_python():
    """The stats slots and the entry's packing agree between render_types.h and Python."""
    import re
    from pathlib import Path

    from raytrace import render_types as T

    text = (Path(__file__).resolve().parents[2] / "kernels" / "render_types.h").read_text()
    defs = dict(re.findall(r"#define (\w+) (.+)", text))
    md = T.MAX_DEPTH

    def value(name):
        return eval(defs[name].split("/*")[0].replace("RENDER_MAX_DEPTH", str(md))
                    .replace("u", ""))

    assert value("RENDER_STAT_DROPPED") == T.STAT_DROPPED
    assert value("RENDER_STAT_SHADOW_LISTED") == T.STAT_SHADOW_LISTED
    assert value("RENDER_STAT_SHADOW_SPILLED") == T.STAT_SHADOW_SPILLED
    assert value("RENDER_STATS_LEN") == T.STATS_LEN
    assert value("SHADOW_RAY_LIGHT_SHIFT") == T.SHADOW_RAY_LIGHT_SHIFT
    assert value("GATHER_FINISH_SHADOW_LIST") == T.GATHER_FINISH_SHADOW_LIST
    # the pixel field holds the largest image's tile-order pixels, the light index above them
    assert (16384 // 8) ** 2 * 64 <= 1 << T.SHADOW_RAY_LIGHT_SHIFT
    assert (T.MAX_LIGHTS - 1) << T.SHADOW_RAY_LIGHT_SHIFT < 1 << 32


def test_few_work_items_loop_over_every_hit(rt, monkeypatch):
    """Every per-ray and list kernel launched with one work-group loops over its hits and rays
    (a work-item's state reset per hit, the spill marks included): the same bytes as launches
    of a work-item per slot, with room for all, some and none of the rays."""
    s = RenderSettings(width=24, height=18, spp=2, bounces=3, **LISTED)
    sc = tiny_scene(rt)
    want = {room: frame(rt, sc, dataclasses.replace(s, shadow_list_room=room))[1:3]
            for room in (0.5, 0.004, 0.0)}
    real = Renderer._launch_sizes

    def one_group(self, depths, hint):
        ls = (self.settings.local_size,)
        return tuple((ls, scan, ls, ls) for _, scan, _, _ in real(self, depths, hint))

    monkeypatch.setattr(Renderer, "_launch_sizes", one_group)
    monkeypatch.setattr(Renderer, "_list_size", lambda self: (self.settings.local_size,))
    for room, (img, fb) in want.items():
        r, img_b, fb_b, st = frame(rt, sc, dataclasses.replace(s, shadow_list_room=room))
        assert all(op[2] == (64,) for op in r._last_ops if op[0] == r._LAUNCH
                   and op[1].function_name in ("render_shade_list", "render_shadow_list",
                                       "render_shadow_spill"))
        assert np.array_equal(img, img_b) and np.array_equal(fb, fb_b), room
        assert st["shadow_rays_spilled"] > 0 or room == 0.5
