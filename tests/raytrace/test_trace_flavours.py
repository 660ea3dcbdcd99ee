"""kernels/traverse.h has two flavours selected by TRACE_CPU (on by default where PoCL compiles
for the host CPU, off on NVIDIA). Both must return the same hits, equal to the float64 reference:
this runs the GPU flavour on PoCL too, where the other tests only see the CPU one."""

import numpy as np
import pytest

from app.meshes import height_field_grid
from raytrace import RayQuery, Scene
from raytrace.bvh import HIT_DTYPE
from raytrace.query import intersect_reference, pack_rays
from tests.raytrace.test_intersect import assert_hits_match


def trace(rt, scene, ro, rd, flavour, any_hit=False):
    n = len(ro)
    hits = rt.buffer(HIT_DTYPE.itemsize * n)
    defines = None if flavour is None else {"TRACE_CPU": flavour}
    q = RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits, n, any_hit=any_hit,
                 defines=defines)
    q.enqueue()
    h = rt.to_host(hits, HIT_DTYPE, n)
    scene.check()
    return h


def as_result(h):
    miss = h["prim"] < 0
    return {"prim": h["prim"], "t": np.where(miss, np.inf, h["t"]), "u": h["u"], "v": h["v"]}


@pytest.mark.parametrize("leaf_size", [1, 3])
def test_cpu_and_gpu_flavours_same_hits_as_reference(rt, leaf_size):
    v, t = height_field_grid(33)
    rng = np.random.default_rng(11)
    n = 1500
    o = np.stack([rng.uniform(-1.2, 1.2, n), rng.uniform(-0.05, 0.4, n),
                  rng.uniform(-1.2, 1.2, n)], -1)
    d = rng.normal(size=(n, 3))
    d[: n // 4] = np.eye(3)[rng.integers(0, 3, n // 4)] * rng.choice([-1.0, 1.0], (n // 4, 1))
    tmax = rng.uniform(0.2, 3.0, n)
    ro, rd = pack_rays(o, d, 0.0, tmax)
    scene = Scene(rt, leaf_size=leaf_size)
    scene.add_instance(scene.add_mesh(v, t))
    scene.update()
    ref = intersect_reference(v, t, o, d, 0.0, tmax)
    assert 0.2 < np.mean(ref["prim"] >= 0) < 0.9   # both hits and misses are exercised
    got = {f: trace(rt, scene, ro, rd, f) for f in (0, 1, None)}
    for h in got.values():
        assert_hits_match(as_result(h), ref, 1.0)
    # same traversal order and arithmetic: bit-identical records, not merely close ones
    assert np.array_equal(got[0].view(np.uint8), got[1].view(np.uint8))
    assert np.array_equal(got[1].view(np.uint8), got[None].view(np.uint8))
    anys = {f: trace(rt, scene, ro, rd, f, any_hit=True) for f in (0, 1)}
    assert np.array_equal(anys[0]["prim"] >= 0, ref["prim"] >= 0)
    assert np.array_equal(anys[0].view(np.uint8), anys[1].view(np.uint8))


@pytest.mark.parametrize("bins_coop", [False, True])
def test_gpu_flavour_frames_are_the_cpu_flavour_s_bytes(rt, bins_coop):
    """TRACE_CPU=0 also keeps the shadow stage's walks out of line (render_shadow.h SHADOW_WALK),
    as on a GPU: frames of issue 9's baseline scene, whose shadow rays fall back to the any-hit
    walk in the light buffer's full cells and cross the water, are the CPU flavour's bytes
    through the plain, binned and cooperative shadow kernels."""
    from app.world import World
    from kernels.runtime import Runtime

    frames = {}
    for flavour in (0, 1):
        run = Runtime(rt.device, defines={"TRACE_CPU": flavour})
        w = World("bench/scenes/pool_static_boat.toml", run, width=48, height=27, cells=32,
                  light_buffer=64)
        if bins_coop:
            w.renderer.set_cost_bins(True)
            w.renderer.set_coop(1)
        frames[flavour] = [w.frame(1 / 30) for _ in range(2)]
        assert w.renderer.light_buffer.read(0)["count"].max() > 16   # full cells: walks
    for a, b in zip(frames[0], frames[1], strict=True):
        assert np.array_equal(a, b)
    assert frames[0][0][..., :3].std() > 5
