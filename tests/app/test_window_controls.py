"""The window's pure parts, no GL and no display: the orbit camera and pixel rays, the input
state machine against a recording fake world, the auto-quality choice, the event-file format and
the HUD's text."""

import dataclasses
import math

import numpy as np
import pytest

from app import quality as q
from app.controls import (
    Action,
    Button,
    Controls,
    DragMode,
    OrbitCamera,
    Water,
    pixel_ray,
)
from app.errors import InputError
from app.hud import GlyphAtlas, guard_lines, help_lines, hud_lines
from app.window import EventLog, parse_size


# ---- camera math -------------------------------------------------------------------------------
def test_orbit_camera_round_trips_a_look_and_keeps_its_distance():
    eye, target = (3.9, 1.7, 4.3), (2.0, 0.3, 1.4)
    cam = OrbitCamera.from_look(eye, target, 50)
    np.testing.assert_allclose(cam.eye, eye, atol=1e-12)
    d0 = cam.distance
    cam.orbit(120, -40)
    assert np.linalg.norm(np.subtract(cam.eye, target)) == pytest.approx(d0)
    assert not np.allclose(cam.eye, eye)
    cam.orbit(0, 1e6)                        # pitch is clamped below the pole
    assert cam.pitch == pytest.approx(OrbitCamera.PITCH_LIMIT)
    cam.zoom(2)
    assert cam.distance == pytest.approx(d0 * 0.81)


def test_pan_moves_target_and_eye_together_in_the_view_plane():
    cam = OrbitCamera.from_look((0, 0, 5), (0, 0, 0), 90)
    eye0 = np.array(cam.eye)
    cam.pan(-50, 0, 100)                     # cursor left: the scene follows, target moves right
    # at 90 degrees fov and 5 m, 100 px span 10 m: 50 px are 5 m along +x (right)
    np.testing.assert_allclose(cam.target, (5, 0, 0), atol=1e-9)
    np.testing.assert_allclose(np.array(cam.eye) - eye0, (5, 0, 0), atol=1e-9)


def test_pixel_ray_matches_the_renderers_camera_record():
    from raytrace.render import RenderSettings, make_camera

    eye, target, up, fov, w, h = (1, 2, 3), (0.5, 0, -1), (0, 1, 0), 40.0, 64, 48
    cam = make_camera(eye, target, up, fov, RenderSettings(width=w, height=h).resolved())
    for x, y in ((0, 0), (63, 47), (10, 30)):
        o, d = pixel_ray(eye, target, up, fov, w, h, x + 0.5, y + 0.5)
        sx, sy = 2 * (x + 0.5) / w - 1, 1 - 2 * (y + 0.5) / h   # render_raygen.cl
        ref = cam["forward"][:3] + sx * cam["right"][:3] + sy * cam["up"][:3]
        np.testing.assert_allclose(d, ref / np.linalg.norm(ref), atol=1e-6)
        np.testing.assert_allclose(o, eye)


# ---- the input state machine --------------------------------------------------------------------
class FakeWorld:
    """Records calls; the 'water' is the plane y = 0.2 over [0, 1] x [0, 1]; pick intersects it
    with the camera ray so picking and drops line up as in a real world."""

    def __init__(self, w=64, h=48):
        self.size = (w, h)
        self.calls = []
        self.camera = ((0.5, 1.5, 1.5), (0.5, 0.2, 0.5), (0, 1, 0), 50.0)

    def pick(self, px, py):
        from app.world import Pick

        eye, target, up, fov = self.camera
        o, d = pixel_ray(eye, target, up, fov, *self.size, px, py)
        if d[1] >= 0:
            return None
        p = o + (0.2 - o[1]) / d[1] * d
        water = 0 <= p[0] <= 1 and 0 <= p[2] <= 1
        return Pick(tuple(p), 0 if water else 1, water, (p[0], p[2]) if water else None)

    def __getattr__(self, name):
        if name in ("add_drop", "push", "set_rain", "set_camera"):
            return lambda *a: self.calls.append((name, a))
        raise AttributeError(name)


def make_controls(world):
    eye, target, _, fov = world.camera
    return Controls(OrbitCamera.from_look(eye, target, fov), Water((0, 0, 0), (1, 1), 0.2, 1 / 32),
                    window_size=(128, 96), image_size=world.size)


def test_drag_on_water_drops_ripples_at_the_picked_points():
    world = FakeWorld()
    c = make_controls(world)
    c.cursor(world, 64, 60)                  # window px; the image is half that
    c.mouse_button(world, Button.LEFT, True)
    assert c.drag == DragMode.RIPPLE
    for x in range(64, 100, 4):
        c.cursor(world, x, 60)
    c.mouse_button(world, Button.LEFT, False)
    drops = [a for n, a in world.calls if n == "add_drop"]
    assert len(drops) >= 3 and c.drag == DragMode.NONE
    for x, y, radius, height in drops:
        assert 0 <= x <= 1 and 0 <= y <= 1 and radius > 0 and height > 0
    p = world.pick(32, 30)                   # the press point, in image pixels
    assert drops[0][:2] == pytest.approx(p.pool_xy)
    assert not any(n == "set_camera" for n, _ in world.calls)


def test_shift_drag_pushes_along_the_drag_and_drag_off_water_orbits():
    world = FakeWorld()
    c = make_controls(world)
    c.cursor(world, 64, 60)
    c.mouse_button(world, Button.LEFT, True, shift=True)
    c.cursor(world, 80, 60)
    c.mouse_button(world, Button.LEFT, False)
    (x, y, dx, dy, s), = [a for n, a in world.calls if n == "push"]
    assert dx > 0 and abs(dy) < 1e-9 and s > 0   # rightwards on screen is +x here
    c.cursor(world, 2, 2)                    # the sky
    c.mouse_button(world, Button.LEFT, True)
    assert c.drag == DragMode.ORBIT
    yaw = c.camera.yaw
    c.cursor(world, 30, 2)
    c.apply(world)
    assert c.camera.yaw != yaw and world.calls[-1][0] == "set_camera"
    assert not [a for n, a in world.calls if n == "add_drop"]


def test_actions_rain_pause_step_and_rebuild_requests():
    world = FakeWorld()
    c = make_controls(world)
    c.cells, c.bounces, c.spp = 32, 2, 1
    c.action(world, Action.TOGGLE_RAIN)
    c.action(world, Action.RAIN_MORE)
    r = c.apply(world)
    assert world.calls[-1] == ("set_rain", (30.0,)) and not r.rebuild
    c.action(world, Action.PAUSE)
    assert c.frame_seconds(0.1) == 0.0
    c.action(world, Action.STEP)
    assert c.frame_seconds(0.1) == 0.1 and c.frame_seconds(0.1) == 0.0
    for a in (Action.BOUNCES_UP, Action.SPP_4, Action.GRID_DOWN):
        c.action(world, a)
    r = c.apply(world)
    assert r.rebuild == {"bounces": 3, "spp": 4, "cells": 21}
    assert not c.apply(world).rebuild        # requests are handed over once
    c.action(world, Action.DROP_BOAT)        # no boats in the fake: a message, no error
    assert "boat" in c.message
    c.action(world, Action.QUIT)
    assert c.apply(world).quit


def test_b_drops_a_boat_over_the_water_under_the_cursor_or_says_why_not():
    from app.errors import InputError

    class Boats(FakeWorld):
        boats = True

        def drop_boat(self, x, y):
            if not self.boats:
                raise InputError("drop_boat: the scene has no [[boats]]")
            self.calls.append(("drop_boat", (x, y)))

    world = Boats()
    c = make_controls(world)
    c.cursor(world, 64, 60)
    c.action(world, Action.DROP_BOAT)
    (name, (x, y)), = world.calls
    hit = world.pick(32, 30).pool_xy
    assert name == "drop_boat" and (x, y) == pytest.approx(hit) and c.message == "boat dropped"
    c.cursor(world, 1, 1)                    # the sky: nothing to drop onto
    c.action(world, Action.DROP_BOAT)
    assert len(world.calls) == 1 and "point at the water" in c.message
    world.boats = False                      # a World whose scene has no boats: its reason
    c.cursor(world, 64, 60)
    c.action(world, Action.DROP_BOAT)
    assert len(world.calls) == 1 and c.message == "drop_boat: the scene has no [[boats]]"


def test_action_names_round_trip_and_unknown_names_list_the_valid_ones():
    assert Action.from_str("toggle_rain") is Action.TOGGLE_RAIN
    with pytest.raises(ValueError, match="valid: quit, toggle_rain"):
        Action.from_str("jump")


# ---- auto quality ------------------------------------------------------------------------------
COSTS = q.Costs(per_cell_step=2e-5, per_cell=1e-5, per_ray=2e-4, fixed=3.0,
                ray_ratio=(1.0, 0.8, 0.5), steps_per_frame=2.0)


def choose(costs, **kw):
    args = dict(target_fps=20, window=(640, 360), max_cells=200, max_bounces=5, aspect=0.75,
                base_cells=64)
    return q.choose(costs, **(args | kw))


def test_auto_quality_picks_smaller_settings_on_a_slower_device():
    fast, slow = choose(COSTS), choose(COSTS.scaled(8.0))
    assert fast.predicted_ms <= 50.0
    assert (slow.cells, slow.scale, slow.bounces) != (fast.cells, fast.scale, fast.bounces)
    assert slow.cells <= fast.cells and slow.scale <= fast.scale and slow.bounces <= fast.bounces
    # the choice is monotone in the device's speed, from the best rung to the least
    picks = [choose(COSTS.scaled(f)) for f in (0.01, 0.1, 1, 10, 100)]
    rank = q.ladder(200, 5)
    idx = [rank.index((p.cells, p.scale, p.bounces, 0)) for p in picks]
    assert idx == sorted(idx) and idx[0] == 0 and idx[-1] == len(rank) - 1
    assert picks[-1].predicted_ms > 50.0    # nothing fits: the last rung, and it says so


def test_steps_that_save_little_wait_until_they_matter():
    # the water grid costs little beside the rays (as on a CPU): coarser grids are not rungs
    rays = dataclasses.replace(COSTS, per_cell_step=1e-9, per_cell=1e-9)
    least = choose(rays.scaled(1000.0))
    assert least.cells == 200 and least.scale == 0.25 and least.bounces == 1
    # caustics that cost nothing stay on while the scale drops
    free = choose(dataclasses.replace(COSTS, caustics=0.01, caustic_photons=P), photons=P)
    assert free.caustics is None and free.photons == P and free.scale == 0.5
    # caustics that cost much: bounces go later, once their saving matters (not never)
    dear = dataclasses.replace(COSTS, caustics=900.0, caustic_photons=P)
    rungs = q.ladder(200, 5, P, worth=lambda a, b: q.predict_ms(
        dear, cells=b.cells, aspect=0.75, scale=b.scale, bounces=b.bounces, window=(640, 360),
        photons=b.photons) <= 0.95 * q.predict_ms(
        dear, cells=a.cells, aspect=0.75, scale=a.scale, bounces=a.bounces, window=(640, 360),
        photons=a.photons))
    assert all(r.bounces == 5 for r in rungs if r.photons == P)   # photons go first here
    assert [r.bounces for r in rungs if r.photons == 0][0] == 2      # bounces followed


P = 262144   # a scene's caustic photons (twice the default: dear on a CPU)


def test_expensive_caustics_are_turned_down_then_off_before_the_picture_gets_coarse():
    costs = dataclasses.replace(COSTS, caustics=900.0, caustic_photons=65536)  # 3.6 s at P
    pick = choose(costs, photons=P)
    assert pick.caustics == "off" and pick.scale >= 0.5 and pick.predicted_ms <= 50
    assert pick.photons == P // 16          # what C turns on: the fewest photons
    assert "caustics off" in pick.describe()
    mid = choose(dataclasses.replace(costs, caustics=30.0), photons=P, target_fps=10)
    assert mid.caustics is None and mid.photons in (P // 4, P // 16) and mid.predicted_ms <= 100
    assert f"caustics traced ({mid.photons} photons)" in mid.describe()
    cheap = choose(dataclasses.replace(COSTS, caustics=0.01, caustic_photons=P), photons=P,
                   target_fps=1)
    assert cheap.caustics is None and cheap.photons == P    # kept: the scene's setting
    kept = choose(costs, photons=P, keep_caustics=True)      # --caustics traced
    assert kept.caustics is None and kept.photons == P // 16 and "caustics" in kept.source
    assert "caustics" not in choose(COSTS).describe()        # a scene without them
    # the cost model: linear in the photons; the map's side with their square root
    assert costs.caustic_ms(P) == pytest.approx(3600.0) and costs.caustic_ms(0) == 0.0
    assert q.caustic_levels(P) == [P, P // 4, P // 16] and q.caustic_levels(2048) == [2048, 1024]
    assert [q.caustic_map_resolution(p, P, 256) for p in q.caustic_levels(P)] == [256, 128, 64]


#: A probe of the pool scene on 2 quiet PoCL cores (2026-12-01; 64 cells, 320x180, 2 bounces,
#: 65536 photons), as app.window.decide_quality measured it (display not included).
POCL_2CORE = q.Costs(per_cell_step=1.9e-4, per_cell=1.8e-4, per_ray=1.2e-3, fixed=16.2,
                     ray_ratio=(1.0, 0.431, 0.0035), steps_per_frame=1.0, caustics=57.7,
                     caustic_photons=65536)


def test_the_pool_on_two_cpu_cores_gets_20_fps_and_a_fast_device_the_full_picture():
    pool = dict(window=(640, 360), max_cells=200, max_bounces=5, aspect=0.75, base_cells=64,
                photons=P)
    cpu = q.choose(POCL_2CORE, target_fps=20, **pool)
    assert cpu.predicted_ms <= 50.0 and cpu.caustics == "off" and cpu.photons == P // 16
    assert cpu.bounces == 5 and cpu.cells >= 64     # they cost little beside the pixels
    # on a device 200x faster (a GPU: the H200 is hundreds of times) at 1280x720 and 60 FPS: the
    # whole picture, the scene's grid, bounces and photons
    fast = q.choose(POCL_2CORE.scaled(1 / 200), target_fps=60,
                    **(pool | {"window": (1280, 720)}))
    assert (fast.cells, fast.scale, fast.bounces, fast.caustics, fast.photons) == (
        200, 1.0, 5, None, P) and fast.predicted_ms <= 1000 / 60


def test_presets_turn_caustics_down_or_off():
    low, med, high = (q.preset(n, max_cells=200, max_bounces=5, photons=P)
                      for n in ("low", "medium", "high"))
    assert (low.caustics, low.photons) == ("off", P // 16)
    assert (med.caustics, med.photons) == (None, P // 4)
    assert (high.caustics, high.photons) == (None, P)
    assert q.preset("low", max_cells=200, max_bounces=5).photons is None   # no caustics


def test_ladder_rungs_never_cost_more_and_overrides_pin_their_part():
    rungs = q.ladder(200, 5, photons=P)
    costs = dataclasses.replace(COSTS, caustics=5.0, caustic_photons=P)
    ms = [q.predict_ms(costs, cells=c, aspect=0.75, scale=s, bounces=b, window=(640, 360),
                       photons=k) for c, s, b, k in rungs]
    assert rungs[0] == (200, 1.0, 5, P) and rungs[-1] == (32, 0.25, 1, 0)
    assert [k for k in dict.fromkeys(r.photons for r in rungs)] == [P, P // 4, P // 16, 0]
    assert all(b <= a for a, b in zip(ms, ms[1:], strict=False))
    pinned = choose(COSTS.scaled(100.0), fixed_scale=1.0, fixed_bounces=3)
    assert pinned.scale == 1.0 and pinned.bounces == 3 and "fixed" in pinned.source
    assert q.preset("low", max_cells=48, max_bounces=5).cells == 48


def test_costs_from_probe_stats_recover_the_units():
    class S:
        stage_ms = {"lbm.step": 4.0, "lbm.surface": 1.0, "bvh.blas.refit": 1.0,
                    "render.trace": 10.0, "render.shade": 10.0, "caustics.photons": 3.0}
        n_rays = 1000
        rays_per_depth = (800, 200)

    c = q.costs_from_stats([S, S], wall_ms=33.0, n_cells=100, steps=2, photons=4096)
    assert c.per_cell_step == pytest.approx(0.02) and c.per_cell == pytest.approx(0.02)
    assert c.per_ray == pytest.approx(0.02) and c.fixed == pytest.approx(4.0)
    assert c.caustics == pytest.approx(3.0) and c.caustic_photons == 4096
    assert c.caustic_ms(8192) == pytest.approx(6.0)
    assert c.ray_ratio == pytest.approx((1.0, 0.25))


# ---- event files, sizes ------------------------------------------------------------------------
def test_event_file_round_trip_and_errors_name_the_line(tmp_path):
    log = EventLog({"window": [64, 48], "cells": 32, "scale": 1.0, "bounces": 1, "spp": 1},
                   [{"frame": 2, "t": 0.1, "kind": "action", "action": "toggle_rain"},
                    {"frame": 3, "t": 0.2, "kind": "tick", "seconds": 0.02}])
    p = tmp_path / "ev.jsonl"
    log.write(p)
    back = EventLog.load(p)
    assert back.header["cells"] == 32 and back.by_frame[2][0]["action"] == "toggle_rain"
    p.write_text(p.read_text() + '{"frame": 4, "kind": "action", "action": "jump"}\n')
    with pytest.raises(InputError, match=r"ev.jsonl:4: unknown action 'jump'"):
        EventLog.load(p)
    p.write_text('{"frame": 1, "kind": "tick", "seconds": 1}\n')
    with pytest.raises(InputError, match="ev.jsonl:1: the first line must be the header"):
        EventLog.load(p)


def test_parse_size():
    assert parse_size("640x360") == (640, 360)
    for bad in ("640", "axb", "8x8"):
        with pytest.raises(InputError, match="--size"):
            parse_size(bad)


# ---- HUD text ----------------------------------------------------------------------------------
class Stats:
    stage_ms = {"render.trace": 3.0, "lbm.step": 1.25}
    n_rays, n_triangles, wall_ms = 2_500_000, 12345, 5.0
    water_cells = (32, 24)
    guard = {"nan": False, "clamped": 7, "max_froude": 0.91, "damped": 0}


def test_hud_lines_show_fps_stages_grid_rays_device_and_guard_warnings():
    text = "\n".join(hud_lines(Stats, fps=59.94, path="copy", size=(64, 48), device="PoCL",
                               quality="quality auto", spp=1, bounces=2))
    for want in ("59.9 FPS", "render.trace\t3.000 ms", "grid 32x24", "12,345 triangles",
                 "2.50 M rays", "device: PoCL", "display: copy", "64x48"):
        assert want in text
    assert guard_lines(Stats) == ["water: 7 cell updates limited (max Froude 0.91)"]
    assert hud_lines(None, fps=0, path="copy")[-1] == "display: copy"
    assert hud_lines(None, fps=0, path="copy (x); shared path unavailable: y")[-2:] == [
        "display: copy (x)", "  shared path unavailable: y"]
    before = hud_lines(None, fps=0, path="copy", size=(64, 48), caustics="off")
    assert "caustics off" in before[1] and "grid" not in before[1]
    assert help_lines([("R", "rain")])[1] == "R\train"


def test_glyph_atlas_has_ink_for_letters_and_none_for_space():
    at = GlyphAtlas(14)
    cw, ch = at.cell
    x, y = at.boxes["W"]
    assert at.image[y:y + ch, x:x + cw].max() > 128
    x, y = at.boxes[" "]
    assert at.image[y:y + ch, x:x + cw].max() == 0
    assert at.quads("ab c", 0, 0, (1, 1, 1, 1)).shape == (18, 8)   # 3 glyphs, 6 vertices each
    assert math.isclose(at.text_width("ab"), at.advance["a"] + at.advance["b"])


def test_glyph_quads_sit_at_the_pen_position_with_the_glyphs_atlas_box():
    at = GlyphAtlas(14)
    (H, W), (cw, ch) = at.image.shape, at.cell
    runs = [("a c", 10.0, 20.0), ("", 0.0, 0.0), ("\x01", 5.0, 40.0)]
    v = at.quads_many(runs, (0.1, 0.2, 0.3, 0.4)).reshape(-1, 6, 8)
    assert v.shape == (3, 6, 8)                     # a, c and '?' for the unprintable
    want = [("a", 10.0, 20.0), ("c", 10.0 + at.advance["a"] + at.advance[" "], 20.0),
            ("?", 5.0, 40.0)]
    for quad, (c, x, y) in zip(v, want, strict=True):
        ax, ay = at.boxes[c]
        assert quad[:, 0].min() == pytest.approx(x) and quad[:, 0].max() == pytest.approx(x + cw)
        assert quad[:, 1].min() == pytest.approx(y) and quad[:, 1].max() == pytest.approx(y + ch)
        assert quad[:, 2].min() == pytest.approx(ax / W) and quad[:, 3].max() == pytest.approx(
            (ay + ch) / H)
        # each corner's uv goes with its position: u grows with x, v with y
        assert np.allclose((quad[:, 0] - x) / cw, (quad[:, 2] * W - ax) / cw)
        assert np.allclose((quad[:, 1] - y) / ch, (quad[:, 3] * H - ay) / ch)
        assert np.allclose(quad[:, 4:], (0.1, 0.2, 0.3, 0.4))


def test_tab_columns_line_up_across_a_block():
    at = GlyphAtlas(14)
    offsets, w, h = at.layout(["a\tb", "wide text\tc", "title"])
    assert offsets == [0.0, at.text_width("wide text") + 12.0]
    last = max(at.text_width("b"), at.text_width("c"))
    assert w == pytest.approx(max(offsets[1] + last, at.text_width("title")) + 12)
    assert h == 3 * at.line_height + 8
