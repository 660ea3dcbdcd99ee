"""The cooperative traversal (kernels/traverse_coop.h: one ray per work-group of 32) gives the
serial walk's hits: the same t exactly, the same triangle except where two are hit at the same t
(it then keeps the smallest (inst, prim)), the same any-hit booleans, masks and tmax obeyed; a
tiny stack forces its serial redo, counted. Binary layout only (PoCL defaults to wide: forced)."""

import numpy as np
import pytest

from app.meshes import height_field_grid
from kernels.runtime import Runtime
from raytrace import RayQuery, Scene
from raytrace.bvh import HIT_DTYPE
from raytrace.query import intersect_reference, pack_rays
from tests.raytrace.test_intersect import assert_hits_match
from tests.raytrace.test_render_plans import BOX
from tests.raytrace.test_trace_flavours import as_result


@pytest.fixture(scope="module")
def binary_rt(rt):
    return Runtime(rt.device, bvh_layout="binary")


def sphere(n=10, r=0.25):
    th, ph = np.meshgrid(np.linspace(0, np.pi, n), np.linspace(0, 2 * np.pi, 2 * n))
    v = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], -1) * r
    i = np.arange(v.shape[0] * v.shape[1]).reshape(v.shape[:2])
    a, b, c, d = i[:-1, :-1], i[:-1, 1:], i[1:, :-1], i[1:, 1:]
    tri = np.stack([np.stack([a, c, b], -1), np.stack([b, c, d], -1)], -2).reshape(-1, 3)
    return v.reshape(-1, 3).astype(np.float32), tri


def pool(rt):
    """A wavy height field (instance 0), a box (1), both of mask 1, and a sphere (2, mask 2)."""
    scene = Scene(rt, leaf_size=2)
    v, t = height_field_grid(41)
    scene.add_instance(scene.add_mesh(v, t))
    m = np.eye(4)
    m[:3, :3] *= 0.8
    m[:3, 3] = (0.3, -0.05, -0.2)
    scene.add_instance(scene.add_mesh(*BOX), m)
    m = np.eye(4)
    m[:3, 3] = (-0.4, 0.2, 0.3)
    scene.add_instance(scene.add_mesh(*sphere()), m)
    for i, mask in enumerate((1, 1, 2)):
        scene.set_instance_mask(i, mask)
    scene.update()
    return scene


def rays(n=1200, seed=5):
    rng = np.random.default_rng(seed)
    o = np.stack([rng.uniform(-1.2, 1.2, n), rng.uniform(-0.02, 0.6, n),
                  rng.uniform(-1.2, 1.2, n)], -1)
    d = rng.normal(size=(n, 3))
    g = n // 3   # grazing: just above the waves, nearly level
    o[:g, 1] = rng.uniform(0.035, 0.05, g)
    d[:g, 1] = rng.uniform(-0.03, 0.01, g)
    tmax = np.where(rng.random(n) < 0.3, rng.uniform(0.1, 2.0, n), np.inf)
    return o, d, tmax


def trace(scene, o, d, tmax, coop, any_hit=False, mask=0xFFFFFFFF, defines=None, only=-1):
    rt = scene.rt
    ro, rd = pack_rays(o, d, 0.0, tmax)
    n = len(ro)
    hits = rt.buffer(HIT_DTYPE.itemsize * n)
    RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits, n, any_hit=any_hit, mask=mask,
             coop=coop, defines=defines, only=only).enqueue()
    h = rt.to_host(hits, HIT_DTYPE, n)
    scene.check()
    return h


def assert_same_closest(serial, coop):
    """The same hit bit for bit, ties included: of two triangles at one distance both walks
    keep the smaller (inst, prim) (kernels/traverse.h trace_tie_wins)."""
    for field in ("t", "u", "v", "prim", "inst"):
        assert np.array_equal(serial[field], coop[field]), field


@pytest.mark.parametrize("mask", [0xFFFFFFFF, 1, 2])
def test_coop_walk_matches_the_serial_walk(binary_rt, mask):
    scene = pool(binary_rt)
    o, d, tmax = rays()
    serial = trace(scene, o, d, tmax, False, mask=mask)
    coop = trace(scene, o, d, tmax, True, mask=mask)
    assert_same_closest(serial, coop)
    insts = set(np.unique(coop["inst"]).tolist())
    want = {-1, 0, 1, 2} if mask == 0xFFFFFFFF else ({-1, 0, 1} if mask == 1 else {-1, 2})
    assert insts == want   # every instance seen, masked ones never
    assert np.all(coop["t"][coop["prim"] >= 0] < tmax[coop["prim"] >= 0])   # tmax obeyed
    anys = [trace(scene, o, d, tmax, c, any_hit=True, mask=mask) for c in (False, True)]
    assert np.array_equal(anys[0]["prim"] >= 0, anys[1]["prim"] >= 0)
    assert np.array_equal(anys[1]["prim"] >= 0, coop["prim"] >= 0)
    assert scene.coop_redos() == 0


def test_coop_walk_matches_the_float64_reference(binary_rt):
    v, t = height_field_grid(33)
    scene = Scene(binary_rt)
    scene.add_instance(scene.add_mesh(v, t))
    scene.update()
    o, d, tmax = rays(600, seed=9)
    got = trace(scene, o, d, tmax, True)
    ref = intersect_reference(v, t, o, d, 0.0, tmax)
    assert 0.2 < np.mean(ref["prim"] >= 0) < 0.9
    assert_hits_match(as_result(got), ref, 1.0)


def test_full_stack_redoes_the_ray_serially(binary_rt):
    scene = pool(binary_rt)
    o, d, tmax = rays(300, seed=3)
    serial = trace(scene, o, d, tmax, False)
    before = scene.coop_redos()
    coop = trace(scene, o, d, tmax, True, defines={"TRACE_COOP_STACK": 8})
    redos = scene.coop_redos() - before
    assert 0 < redos <= len(o)
    assert np.array_equal(serial["t"], coop["t"])
    assert (serial["prim"] != coop["prim"]).mean() < 0.01
    anys = trace(scene, o, d, tmax, True, any_hit=True, defines={"TRACE_COOP_STACK": 8})
    assert np.array_equal(anys["prim"] >= 0, serial["prim"] >= 0)


def test_wide_layout_falls_back_to_the_serial_walk(rt):
    if rt.bvh_layout != "wide":
        rt = Runtime(rt.device, bvh_layout="wide")
    v, t = height_field_grid(17)
    scene = Scene(rt)
    scene.add_instance(scene.add_mesh(v, t))
    scene.update()
    o, d, tmax = rays(200, seed=2)
    serial, coop = trace(scene, o, d, tmax, False), trace(scene, o, d, tmax, True)
    assert np.array_equal(serial.view(np.uint8), coop.view(np.uint8))
