"""The shadow kernels with no BVH walk (kernels/render_shadow.h SHADOW_MAPPED): a renderer takes
them once the light buffer's last build has been read back complete (raytrace/light_buffer.py
LightBuffer.complete) and the scene allows them (Renderer.mapped_possible), and its frames are
then the frames rendered with no map at all, byte for byte, through every flavour of the shadow
launch; where the maps leave rays unanswered, or the scene has a spot light or a dielectric
other than the height field, it keeps the kernels that walk. (A boat the device moves rebuilds
the map every frame: test_light_buffer.py's floating boat, whichever kernels its frames take.)"""

import dataclasses

import numpy as np
import pytest

from kernels.runtime import Runtime
from raytrace.render import Renderer, RenderSettings
from tests.raytrace.test_light_buffer import clutter
from tests.raytrace.test_render_plans import CAMERAS

STATIC = "bench/scenes/pool_static_boat.toml"


def frames(rt, sc, settings, n: int, cells: int, moves=()):
    """``n`` frames of ``sc`` with a map of ``cells`` (0: none), then one after each move
    (None: none); and whether each frame's shadow launches were the mapped ones."""
    r = Renderer(rt, sc, dataclasses.replace(settings, light_buffer=cells))
    r.set_camera(*CAMERAS[1], (0, 1, 0), 50)
    imgs, used = [], []
    for _ in range(n):
        imgs.append(r.render())
        used.append(r.mapped_shadows_used)
    for move in moves:
        if move is not None:
            sc.set_transform(*move)
        imgs.append(r.render())
        used.append(r.mapped_shadows_used)
    return imgs, used, r


@pytest.mark.parametrize("settings", [
    RenderSettings(width=24, height=18, bounces=3, spp=4),
    RenderSettings(width=24, height=18, bounces=3, spp=4, max_chunk_rays=96),
    RenderSettings(width=24, height=18, bounces=3, spp=4, cost_bins=True, coop_from=1),
], ids=["plain", "chunks", "binned"])
def test_frames_are_the_frames_without_a_map(rt, settings):
    sc = clutter(rt, glass=False)
    want, _, _ = frames(rt, sc, settings, 3, 0)
    got, used, r = frames(rt, sc, settings, 3, 6)   # coarse: long lists past the slots
    # once the build's counters have been read (the first frame's may be in time, or not)
    assert r.mapped_possible() and used[1:] == [True, True]
    assert r.light_buffer.read(0)["lists"]
    for a, b in zip(want, got, strict=True):
        assert np.array_equal(a, b)
    assert want[0][..., :3].std() > 5
    walked, used, _ = frames(rt, sc, dataclasses.replace(settings, mapped_shadows=False), 3, 6)
    assert not any(used) and all(np.array_equal(a, b) for a, b in zip(want, walked, strict=True))


def test_a_moved_instance_is_walked_until_its_build_is_read(rt):
    """A host move rebuilds the map: that frame walks unless the build's counters arrived in
    time; the next frames are mapped again, but not after a move that reached off the map."""
    sc = clutter(rt, glass=False)
    s = RenderSettings(width=24, height=18, bounces=2)
    near = np.array([[0, 0, 1, -0.3], [0, 1, 0, 0.1], [-1, 0, 0, 0.2], [0, 0, 0, 1]])
    off = np.array([[1, 0, 0, 30.0], [0, 1, 0, 0], [0, 0, 1, 30.0], [0, 0, 0, 1]])
    moves = [(1, near), None, (1, off), None]
    start = np.vstack([sc.scene.read_host_transforms()[1], [0, 0, 0, 1]])
    got, used, r = frames(rt, sc, s, 2, 48, moves)
    assert [used[k] for k in (1, 3, 4, 5)] == [True, True, False, False]
    sc.set_transform(1, start)
    want, _, _ = frames(rt, sc, s, 2, 0, moves)
    assert all(np.array_equal(a, b) for a, b in zip(want, got, strict=True))


def test_scenes_the_maps_cannot_answer_keep_the_walks(rt):
    s = RenderSettings(width=20, height=14, bounces=2)
    for sc, why in ((clutter(rt, spot=True, glass=False), "a spot light has no map"),
                    (clutter(rt), "the glass box is crossed, not the height field")):
        _, used, r = frames(rt, sc, s, 2, 32)
        assert r.light_buffer.active and not r.mapped_possible() and not any(used), why


@pytest.fixture(scope="module")
def counting(rt):
    return Runtime(rt.device, defines={"TRACE_COUNT": 1})


def test_the_water_s_crossings_walk_the_height_field_alone(rt, counting):
    """Issue 9's baseline scene (the pool's water a height field, a dielectric; a static boat):
    the mapped frames are the frames with no map, and a TRACE_COUNT build counts the same
    crossings of the water through both kernels, and no shadow walk of the BVH."""
    from app.world import World

    imgs, counts = {}, {}
    for cells, mapped in ((0, False), (64, False), (64, True)):
        w = World(STATIC, counting, width=64, height=36, cells=32, light_buffer=cells)
        w.renderer.set_mapped_shadows(mapped)
        w.frame(1 / 30)
        w.frame(1 / 30)
        sc = w.render_scene.scene
        sc.reset_trace_counts()
        imgs[cells, mapped] = [w.frame(1 / 30) for _ in range(2)]
        counts[cells, mapped] = sc.trace_counts()
        assert w.renderer.mapped_shadows_used == mapped
    for key in ((64, False), (64, True)):
        assert all(np.array_equal(a, b) for a, b in zip(imgs[0, False], imgs[key], strict=True))
    walk, lean = counts[64, False], counts[64, True]
    assert lean["crossing"] == walk["crossing"] and lean["crossing"]["hits"] > 0
    assert lean["heightfield"] == walk["heightfield"]
    assert lean["shadow"]["traversals"] == 0
    # the same answers (a blocked ray tests as many triangles as come before its blocker in
    # the cell's order, which varies from build to build)
    lean["light_buffer"].pop("triangles"), walk["light_buffer"].pop("triangles")
    assert lean["light_buffer"] == walk["light_buffer"]

