"""Caustics in the frame (app.world, docs/render.md): under still, flat water the picture with
the caustic map equals the shadow-ray picture, the stage is timed under its own name, the toggle
works, only the image and scalars cross per frame, and bad settings are one-line errors."""

import numpy as np
import pytest

from app.errors import InputError
from app.scene import parse_scene
from app.world import World
from tests.transfer_counter import TransferCounter

FLAT = """
[render]
width = 48
height = 32
bounces = 3

[camera]
eye = [0.5, 1.4, -0.3]
target = [0.5, 0.0, 0.55]

[shading]
caustic_photons = 4096      # 4 photons per floor texel
caustic_resolution = 32
caustic_filter = 1
caustic_blend = 0.5

[water]
size = [1.0, 1.0]
cells = [16, 16]
depth = 0.3

[[lights]]
kind = "directional"
direction = [0.0, -1.0, 0.0]
color = [1.5, 1.4, 1.3]

[pool]
steps = 0
wall_height = 0.45
deck = 0.3
"""


@pytest.fixture
def flat(tmp_path):
    return parse_scene(FLAT, tmp_path / "flat.toml")


def test_flat_water_picture_with_caustics_equals_the_shadow_ray_picture(flat, rt):
    """The sun straight down through still water: the old shadow rays were exact here
    (straight path = refracted path), so the caustic map must give the same picture."""
    off = World(flat, rt).frame(0.0)
    on_world = World(flat, rt, caustics="traced")
    on = on_world.frame(0.0)
    assert on_world.caustics == "traced"
    diff = np.abs(on.astype(int) - off.astype(int))
    assert diff.max() <= 1, diff.max()
    # the pool floor under the water really is lit by the map: zero map, dark floor
    c = on_world._caustics
    E = c.read_map()["floor"]
    assert np.allclose(E[4:-4, 4:-4], E[16, 16], rtol=1e-3) and E[16, 16, 0] > 1.0


def test_the_caustics_stage_is_timed_and_toggled(flat, rt):
    w = World(flat, rt, caustics="traced")
    w.add_drop(0.5, 0.5, 0.15, 0.03)
    w.frame(0.05)
    w.frame(0.05)
    assert w.stats.stage_ms.get("caustics.photons", 0) > 0
    assert "caustics.filter" in w.stats.stage_ms
    wavy = w.frame(0.05)
    w.set_caustics("off")
    assert w.caustics == "off"
    plain = w.frame(0.0)
    assert "caustics.photons" not in w.stats.stage_ms
    ref = World(flat, rt)
    ref.add_drop(0.5, 0.5, 0.15, 0.03)
    for _ in range(3):
        ref.frame(0.05)
    assert np.array_equal(plain, ref.frame(0.0)), "off is the old picture exactly"
    assert not np.array_equal(wavy, plain), "moving water makes caustics differ from rays"


def test_caustic_frames_move_only_the_image_and_scalars(flat, rt):
    w = World(flat, rt, caustics="traced")
    w.frame(1 / 60)
    image = 48 * 32 * 4
    with TransferCounter() as c:
        for i in range(8):
            if i == 2:
                w.add_drop(0.4, 0.6, 0.1, 0.02)
            w.enqueue_frame(1 / 60)
        w.drain()
    assert not c.buffers
    assert c.bytes / 8 <= image + 4096, c.calls[:12]


def test_caustic_frames_are_deterministic(flat, rt):
    def run():
        w = World(flat, rt, caustics="traced")
        w.add_drop(0.3, 0.4, 0.12, 0.03)
        return [w.frame(1 / 30) for _ in range(3)]
    a, b = run(), run()
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def test_the_photon_launches_get_the_records_params_makes(flat, rt):
    """The stage reuses its records between frames (only the seed changes): each launch's
    bytes equal a fresh params(frame, light), across history, light and mode changes."""
    w = World(flat, rt, caustics="traced")
    c = w._caustics
    seen = []

    class Spy:
        def __init__(self, k):
            self.k = k

        def bind(self, **kw):
            seen.append((kw["cp"].tobytes(), c.params(w.frames_enqueued, 0).tobytes()))
            return self.k.bind(**kw)

        def launch(self, *a):
            return self.k.launch(*a)

    c.k_photons = Spy(c.k_photons)
    w.frame(0.0)
    w.frame(0.0)                                    # with history: blend on
    w.render_scene.lights[0]["color"][:3] = (3.0, 2.0, 1.0)   # a light changed in place
    w.frame(0.0)
    w.set_caustics("off")
    w.set_caustics("traced")                        # history off again
    w.frame(0.0)
    assert len(seen) == 4 and all(got == want for got, want in seen)
    assert len({got for got, _ in seen}) == 4


def test_bad_caustic_settings_are_one_line_errors(flat, rt, tmp_path):
    with pytest.raises(InputError, match=r"\[shading\].*projected.*not implemented"):
        World(flat, rt, caustics="projected")
    bad = FLAT.replace("caustic_blend = 0.5", "caustic_blend = 1.5")
    with pytest.raises(InputError, match="caustic_blend"):
        parse_scene(bad, tmp_path / "bad.toml")
    nopool = parse_scene(FLAT.split("[pool]")[0], tmp_path / "nopool.toml")
    w = World(nopool, rt)
    with pytest.raises(InputError, match="no pool"):
        w.set_caustics("traced")


def test_the_window_key_toggles_the_worlds_caustics_and_a_rebuilt_world_keeps_the_choice(
        flat, rt):
    from app.controls import Action, Controls, OrbitCamera, Water

    on = World(flat, rt, caustics=True)   # a bool, as the window passes
    assert on.caustics == "traced"
    c = Controls(OrbitCamera.from_look((0.5, 1.4, -0.3), (0.5, 0.0, 0.55), 50.0),
                 Water((0, 0, 0), (1, 1), 0.3, 1 / 16), window_size=(48, 32),
                 image_size=(48, 32))
    assert c.caustics is None                 # no choice yet: the world keeps the scene's
    c.action(on, Action.TOGGLE_CAUSTICS)
    assert on.caustics == "off" and c.caustics == "off"   # the mode string, as the world's
    assert c.status_message(0.0) == "caustics off"
    c.action(on, Action.TOGGLE_CAUSTICS)
    assert on.caustics == "traced" and c.caustics == "traced"
    c.action(on, Action.TOGGLE_CAUSTICS)
    rebuilt = World(flat, rt, caustics="traced")
    c.reapply(rebuilt)
    assert rebuilt.caustics == "off", "the user's choice outlives a rebuild"


def test_with_shading_overrides_caustics_for_capture_and_window(tmp_path):
    from app.assemble import caustic_settings
    from app.frames import with_shading

    bare = parse_scene(FLAT.replace("[shading]", "[shading_unused]").split(
        "[shading_unused]")[0], tmp_path / "bare.toml")
    assert bare.shading is None
    assert caustic_settings(with_shading(bare, {"caustics": "traced"})).mode == "traced"


def test_fewer_photons_keep_the_photons_per_texel_and_light_the_floor_alike(flat, rt):
    """The window's caustic levels (app.window.caustic_scene): a quarter of the photons on a
    map of half the side; under flat water the floor's irradiance is the same."""
    from app.assemble import caustic_settings
    from app.window import caustic_scene

    assert caustic_scene(flat, None) is flat and caustic_scene(flat, 4096) is flat
    quarter = caustic_scene(flat, 1024)
    s = caustic_settings(quarter, "traced")
    assert (s.photons, s.resolution) == (1024, 16)
    full, less = World(flat, rt, caustics="traced"), World(quarter, rt, caustics="traced")
    full.frame(0.0)
    less.frame(0.0)
    a, b = full.read_caustics()["floor"], less.read_caustics()["floor"]
    assert a.shape == (32, 32, 3) and b.shape == (16, 16, 3)
    assert np.allclose(b[2:-2, 2:-2], a[16, 16], rtol=1e-3)   # the same sunlight, coarser
