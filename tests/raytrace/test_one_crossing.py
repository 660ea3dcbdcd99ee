"""A ray that rises faster than the water's steepest slope crosses the height field at most
once, upward; one that sinks faster, at most once, downward (kernels/heightfield.h: hf_climbs,
hf_sinks, hf_side, hf_unreachable). The shadow rays' crossings use it (RenderSettings.
one_crossing), and every walk culls the rays that cannot meet the surface (HF_CULL_UNREACHABLE).
Checked here: the claim itself against a float64 brute force over every triangle; the
predicates against float64 (they never claim what is false, and they claim all that is clearly
true away from a cell's edges); culled rays against the brute force and walks against the BVH;
frames with and without each shortcut, byte for byte, through every shadow kernel, with fewer
walks where the sun climbs over the waves and the same walks where it does not. The bounds
pass's slope against float64: tests/raytrace/test_heightfield.py."""

import dataclasses

import numpy as np
import pyopencl as cl
import pytest

from app.meshes import height_field_grid, smooth_normals
from kernels.runtime import Runtime
from raytrace import Scene
from raytrace.render import Renderer, RenderSettings
from raytrace.render_scene import Material, RenderScene
from tests.raytrace.test_heightfield import assert_identical, scenes, steepest_slope
from tests.raytrace.test_render_plans import BOX
from tests.raytrace.test_trace_coop import trace

N = 33   # vertices per side of the test grid: cells of 1/16 over [-1, 1]^2


@pytest.fixture(scope="module")
def rt_count(rt):
    return Runtime(rt.device, defines={"TRACE_COUNT": 1})


@pytest.fixture(scope="module")
def binary_rt(rt):
    return Runtime(rt.device, bvh_layout="binary")


def wavy_grid(jitter: float = 0.0, seed: int = 0):
    """height_field_grid(N) (slopes up to about 0.6), its x and z moved by up to ``jitter``
    cells (within the grid's tolerance, HF_GRID_TOL)."""
    v, tri = height_field_grid(N, 0.4)
    v = v.copy()
    if jitter:
        rng = np.random.default_rng(seed)
        v[:, [0, 2]] += rng.uniform(-jitter, jitter, (len(v), 2)).astype(np.float32) * 2 / (N - 1)
    return v, tri


def surface_height(v, tri, xz):
    """float64 height of the grid over each point of xz (n, 2), NaN off the grid."""
    p = v.astype(np.float64)[tri]
    a, b, c = p[:, 0][:, [0, 2]], p[:, 1][:, [0, 2]], p[:, 2][:, [0, 2]]
    h = np.full(len(xz), np.nan)
    for k in range(0, len(xz), 512):
        q = xz[k:k + 512, None, :]
        e1, e2, s = b - a, c - a, q - a
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        u = (s[..., 0] * e2[:, 1] - s[..., 1] * e2[:, 0]) / det
        w = (e1[:, 0] * s[..., 1] - e1[:, 1] * s[..., 0]) / det
        inside = (u >= 0) & (w >= 0) & (u + w <= 1)
        y = (1 - u - w) * p[:, 0, 1] + u * p[:, 1, 1] + w * p[:, 2, 1]
        row = np.where(inside.any(1), np.where(inside, y, -np.inf).max(1), np.nan)
        h[k:k + 512] = row
    return h


def crossings(v, tri, org, d):
    """float64: how many times each ray org + t d, t > 0, crosses the grid (Moeller-Trumbore on
    every triangle; hits at one distance, an edge or vertex, count once)."""
    p = v.astype(np.float64)[tri]
    a, e1, e2 = p[:, 0], p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    out = np.zeros(len(org), int)
    for i, (o, di) in enumerate(zip(org, d, strict=True)):
        q = np.cross(di, e2)
        det = (e1 * q).sum(1)
        s = o - a
        u = (s * q).sum(1) / det
        r = np.cross(s, e1)
        w = (r @ di) / det
        t = (r * e2).sum(1) / det
        hit = (u >= -1e-12) & (w >= -1e-12) & (u + w <= 1 + 1e-12) & (t > 1e-12)
        out[i] = len(np.unique(np.round(t[hit], 9)))
    return out


def test_a_climbing_ray_crosses_the_surface_at_most_once():
    """The claim the shortcut rests on, for the exact piecewise-linear surface: from over it, no
    crossing; from under it, at most one (none where it leaves the grid's side first)."""
    v, tri = wavy_grid()
    g = steepest_slope(v, tri)
    rng = np.random.default_rng(1)
    n = 300
    xz = rng.uniform(-0.95, 0.95, (n, 2))
    h = surface_height(v, tri, xz)
    gap = np.where(np.arange(n) % 2, 1, -1) * 10.0 ** rng.uniform(-6, -1, n)
    org = np.c_[xz[:, 0], h + gap, xz[:, 1]]
    az = rng.uniform(0, 2 * np.pi, n)
    rise = g * rng.uniform(1.001, 3.0, n)   # climbs: d.y > slope |d.xz|
    d = np.c_[np.cos(az), rise, np.sin(az)]
    got = crossings(v, tri, org, d)
    assert np.all(got[gap > 0] == 0)
    assert np.all(got[gap < 0] <= 1) and got[gap < 0].mean() > 0.5
    # a ray that rises slower than the steepest triangle is not bound by it: some cross more
    flat = np.c_[np.cos(az), 0.05 * rise / g, np.sin(az)]
    assert crossings(v, tri, org, flat).max() >= 2


def predicates(rt, v, tri, points, dirs):
    """The kernel's hf_climbs, hf_sinks, hf_side and hf_unreachable of each point and direction,
    and the grid's slope bound."""
    scene = Scene(rt)
    scene.add_instance(scene.add_mesh(v, tri, grid=(N, N)))
    scene.update()
    hf = scene.heightfield.bindings()
    k = rt.kernel_launcher("heightfield.cl", "heightfield_predicates", stage="test")
    out = rt.buffer(4 * len(points))
    p4, d4 = (np.c_[x, np.zeros(len(x))].astype(np.float32) for x in (points, dirs))
    k.bind(hf=hf["hf_info"], verts=hf["hf_vertices"], points=rt.to_device(p4),
           dirs=rt.to_device(d4), out=out, n=len(points))
    k.launch(-(-len(points) // 64) * 64, 64)
    got = rt.to_host(out, np.int32, len(points))
    return {"climbs": (got & 1) > 0, "sinks": (got & 2) > 0, "side": ((got >> 2) & 3) - 1,
            "unreachable": (got & 16) > 0, "slope": float(scene.heightfield.read()["slope"])}


def near_surface(v, tri, n, seed):
    """n points over [-1.05, 1.05]^2 (some off the grid) within 1e-8..0.1 over or under the
    surface (200 on it), and n random directions, all float32."""
    rng = np.random.default_rng(seed)
    xz = rng.uniform(-1.05, 1.05, (n, 2))
    h = surface_height(v, tri, xz)
    gap = rng.choice([-1, 1], n) * 10.0 ** rng.uniform(-8, -1, n)
    gap[:200] = 0.0
    y = np.where(np.isnan(h), rng.uniform(-0.1, 0.1, n), h + gap)
    points = np.c_[xz[:, 0], y, xz[:, 1]].astype(np.float32)
    return points, rng.normal(size=(n, 3)).astype(np.float32)


@pytest.mark.parametrize("jitter", [0.0, 0.0015])
def test_predicates_never_claim_what_float64_denies(rt, jitter):
    v, tri = wavy_grid(jitter)
    points, dirs = near_surface(v, tri, 6000, seed=2)
    got = predicates(rt, v, tri, points, dirs)
    g, slope = steepest_slope(v, tri), got["slope"]
    p, dd = points.astype(np.float64), dirs.astype(np.float64)
    h32 = surface_height(v, tri, p[:, [0, 2]])   # under the float32 point as stored
    run = np.hypot(dd[:, 0], dd[:, 2])
    # never wrong
    assert g <= slope <= 1.5 * g
    assert np.all(~got["climbs"] | (dd[:, 1] > slope * run))
    assert np.all(~got["sinks"] | (-dd[:, 1] > slope * run))
    assert np.all((got["side"] != 1) | (p[:, 1] > h32))
    assert np.all((got["side"] != -1) | (p[:, 1] < h32))
    # and right where it is clear: every ray rising or sinking 0.1% faster than the bound, and
    # the points over or under the surface by more than 1e-5, in a cell, away from its edges
    # and its diagonal
    for name, fast in (("climbs", dd[:, 1] > 1.001 * slope * run),
                       ("sinks", -dd[:, 1] > 1.001 * slope * run)):
        assert fast.sum() > 1000 and got[name][fast].all()
    cell = (p[:, [0, 2]] + 1) * (N - 1) / 2
    frac = cell - np.floor(cell)
    inner = (((frac > 0.02) & (frac < 0.98)).all(1) & (np.abs(frac.sum(1) - 1) > 0.03)
             & (cell > 0).all(1) & (cell < N - 1).all(1))
    for side, clear in ((1, inner & (p[:, 1] - h32 > 1e-5)), (-1, inner & (h32 - p[:, 1] > 1e-5))):
        assert clear.sum() > 1000 and (got["side"][clear] == side).all()
    # unreachable: exactly the rays that climb from over it or sink from under it (or from
    # over or under the grid's box)
    hf_lo, hf_hi = v[:, 1].min(), v[:, 1].max()
    want = ((got["climbs"] & ((p[:, 1] > hf_hi) | (got["side"] == 1)))
            | (got["sinks"] & ((p[:, 1] < hf_lo) | (got["side"] == -1))))
    assert np.array_equal(got["unreachable"], want) and want.mean() > 0.1


def test_unreachable_rays_meet_nothing_and_walks_keep_the_bvh_hits(binary_rt):
    """The rays hf_unreachable culls cross nothing (float64 brute force), and the walk, which
    culls them, still gives the BVH's hits for rays from near the surface both ways."""
    v, tri = wavy_grid()
    points, dirs = near_surface(v, tri, 1500, seed=5)
    got = predicates(binary_rt, v, tri, points, dirs)
    culled = got["unreachable"]
    assert culled.sum() > 150
    assert np.all(crossings(v, tri, points.astype(np.float64)[culled],
                            dirs.astype(np.float64)[culled]) == 0)
    walk, bvh = scenes(binary_rt, v, tri, N)
    tmax = np.full(len(points), np.inf)
    hits = trace(walk, points, dirs, tmax, False)
    assert_identical(hits, trace(bvh, points, dirs, tmax, False))
    assert (hits["inst"][culled] != 0).all() and (hits["inst"][~culled] == 0).any()


# -- frames with and without it -----------------------------------------------------------
def pond(rt, sun):
    """The wavy grid as the water (a height field written on the device), a tiled floor under
    it, a box half under the water, a slab over it, and the sun."""
    sc = RenderScene(rt)
    floor = sc.add_material(Material(diffuse=(0.8, 0.75, 0.6), specular=(0.1, 0.1, 0.1)))
    water = sc.add_material(Material(diffuse=(0, 0, 0), specular=(1, 1, 1), shininess=8,
                                     ior=1.333, absorption=(0.45, 0.09, 0.06)))
    red = sc.add_material(Material(diffuse=(0.7, 0.2, 0.1)))
    v, tri = wavy_grid()
    mesh, vbuf, nbuf = sc.add_dynamic_mesh(len(v), tri, material=water, grid=(N, N))
    cl.enqueue_copy(rt.queue, vbuf, np.c_[v, np.zeros(len(v))].astype(np.float32))
    cl.enqueue_copy(rt.queue, nbuf, np.c_[smooth_normals(v, tri), np.zeros(len(v))]
                    .astype(np.float32))
    sc.add_instance(mesh)
    quad = np.array([[-1.5, -0.4, -1.5], [1.5, -0.4, -1.5], [1.5, -0.4, 1.5], [-1.5, -0.4, 1.5]])
    sc.add_instance(sc.add_mesh(quad, [[0, 2, 1], [0, 3, 2]], material=floor))
    box = sc.add_mesh(*BOX, material=red)
    m = np.diag([0.5, 0.5, 0.5, 1.0])
    m[:3, 3] = (0.3, -0.05, -0.2)
    sc.add_instance(box, m)
    m = np.diag([0.8, 0.05, 0.4, 1.0])
    m[:3, 3] = (-0.5, 0.6, 0.3)
    sc.add_instance(box, m)
    sc.add_light("directional", direction=sun, color=(2.0, 1.9, 1.8))
    return sc


HIGH_SUN = (-0.4, -0.8, -0.3)    # rises 1.6 per unit across: over every slope of the grid
LOW_SUN = (-0.9, -0.15, -0.4)    # rises 0.15: under the steepest ones


def frames(rt, sun, settings):
    """(image, crossing counters) with one_crossing on, then off."""
    out = []
    for on in (True, False):
        sc = pond(rt, sun)
        r = Renderer(rt, sc, dataclasses.replace(settings, one_crossing=on))
        r.set_camera((0.4, 1.6, 1.9), (0, -0.2, 0), (0, 1, 0), 55)
        sc.scene.update()
        sc.scene.reset_trace_counts()
        img = r.render()
        out.append((img, sc.scene.trace_counts()["crossing"], sc, r))
    return out


@pytest.mark.parametrize("chunk,coop_from,bins,overlap_from",
                         [(None, None, False, 1), (96, None, False, 0), (None, 1, True, 0)])
def test_frames_are_the_frames_without_it(rt, chunk, coop_from, bins, overlap_from):
    """Every shadow kernel: alone, with the next level's trace, chunked, binned, cooperative."""
    s = RenderSettings(width=28, height=20, bounces=3, max_chunk_rays=chunk, coop_from=coop_from,
                       cost_bins=bins, overlap_from=overlap_from)
    (on, _, sc, r), (off, _, _, _) = frames(rt, HIGH_SUN, s)
    assert np.array_equal(on, off) and on[..., :3].std() > 5
    assert r.params()["one_crossing"] == 1 and sc.crossing_instance == 0


def test_walks_only_what_can_cross(rt_count):
    """High sun: the walks from over the water (its lit points) and after leaving it (the
    floor's) are gone; low sun: every walk as before. The same bytes either way."""
    s = RenderSettings(width=40, height=28, bounces=2)
    (on, c_on, sc, _), (off, c_off, _, _) = frames(rt_count, HIGH_SUN, s)
    assert np.array_equal(on, off)
    assert c_on["hits"] == c_off["hits"] > 0
    assert c_off["traversals"] > c_off["rays"]           # the second walks, after the exit
    assert c_on["traversals"] == c_on["rays"]            # none now
    assert c_on["traversals"] < 0.7 * c_off["traversals"]
    assert c_on["rays"] < 0.85 * c_off["rays"]           # the water's own points walk none
    assert sc.scene.heightfield.read()["slope"] < 0.8 / np.hypot(0.4, 0.3)
    (on, c_on, sc, _), (off, c_off, _, _) = frames(rt_count, LOW_SUN, s)
    assert np.array_equal(on, off)
    assert c_on == c_off and c_on["hits"] > 0
    assert sc.scene.heightfield.read()["slope"] > 0.15 / np.hypot(0.9, 0.4)


def test_the_pool_frame_is_the_same_with_fewer_walks(rt_count):
    """Issue 9's baseline scene through World: the same bytes, a fifth of the walks or fewer."""
    from app.world import World

    out = []
    for on in (True, False):
        world = World("bench/scenes/pool_static_boat.toml", rt_count, width=48, height=27,
                      cells=64, water_steps=2)
        world.renderer.set_one_crossing(on)
        sc = world.render_scene
        sc.scene.reset_trace_counts()
        out.append((world.frame(0.0).copy(), sc.scene.trace_counts()["crossing"]))
    (on, c_on), (off, c_off) = out
    assert np.array_equal(on, off)
    assert c_on["hits"] == c_off["hits"] > 0
    assert c_on["traversals"] <= 0.4 * c_off["traversals"]


def test_frames_are_the_same_without_the_walks_cull(rt):
    """hf_unreachable in every walk (HF_CULL_UNREACHABLE, traverse_heightfield.h): the
    reflections and refractions off the water, its shadow rays and the pool's caustic photons
    give the same frames as a build that walks every ray."""
    from app.world import World

    walk_all = Runtime(rt.device, defines={"HF_CULL_UNREACHABLE": 0})
    s = RenderSettings(width=28, height=20, bounces=3, coop_from=2, overlap_from=0)
    (culled, *_), _ = frames(rt, HIGH_SUN, s)
    (walked, *_), _ = frames(walk_all, HIGH_SUN, s)
    assert np.array_equal(culled, walked)
    pool = []
    for r in (rt, walk_all):
        w = World("scenes/pool.toml", r, width=48, height=27, cells=40)
        pool.append([w.frame(1 / 30).copy() for _ in range(2)])
    assert np.array_equal(np.array(pool[0]), np.array(pool[1]))


def test_a_steep_spot_leaves_the_rest_of_the_walk_skipping_spans(rt):
    """Gentle waves with one steep spike: few rays depart faster than the grid's steepest
    slope (culled whole: the nearly vertical ones), but a walk skips the spans whose blocks
    slope less than it rises or sinks (the blocks' bounds), with the hits of the BVH and of a
    build that walks every span."""
    counting = Runtime(rt.device, bvh_layout="binary", defines={"TRACE_COUNT": 1})
    n = 65
    v, tri = height_field_grid(n, 0.4)
    v = v.copy()
    v[:, 1] *= 0.1
    v[32 * n + 40, 1] += 0.3   # a spike: slopes near 10 around it
    points, dirs = near_surface(v, tri, 3000, seed=7)
    walk, bvh = scenes(counting, v, tri, n)
    assert walk.heightfield.read()["slope"] > 5
    tmax = np.full(len(points), np.inf)
    walk.reset_trace_counts()
    hits = trace(walk, points, dirs, tmax, False)
    counts = walk.trace_counts()["heightfield"]
    assert counts["skipped_spans"] > 500 and counts["culled"] < 0.01 * len(points)
    assert_identical(hits, trace(bvh, points, dirs, tmax, False))
    every = Runtime(rt.device, bvh_layout="binary", defines={"HF_CULL_UNREACHABLE": 0})
    walked, _ = scenes(every, v, tri, n)
    again = trace(walked, points, dirs, tmax, False)
    for field in ("t", "u", "v", "prim", "inst"):
        assert np.array_equal(hits[field], again[field]), field
    # the cull without the span skip (HF_SKIP_SPANS 0): the same walks culled, no span skipped
    no_skip = Runtime(rt.device, bvh_layout="binary",
                      defines={"TRACE_COUNT": 1, "HF_SKIP_SPANS": 0})
    spans_walked, _ = scenes(no_skip, v, tri, n)
    spans_walked.reset_trace_counts()
    again = trace(spans_walked, points, dirs, tmax, False)
    no_skip_counts = spans_walked.trace_counts()["heightfield"]
    assert no_skip_counts["skipped_spans"] == 0
    assert no_skip_counts["culled"] == counts["culled"]
    for field in ("t", "u", "v", "prim", "inst"):
        assert np.array_equal(hits[field], again[field]), field


def test_a_walk_that_starts_past_its_origin_keeps_the_bvh_hits(rt):
    """tmin > 0: the ray may have crossed the surface before its walk starts, so the side of
    its origin says nothing there. A cliff up to a flat plateau: rays from over the low ground
    rise into the cliff and, past it, cross the plateau from under it inside a gentle block,
    their walks starting there; and random rays over the spiky grid. The hits are the BVH's."""
    from raytrace import RayQuery
    from raytrace.bvh import HIT_DTYPE
    from raytrace.query import pack_rays

    binary = Runtime(rt.device, bvh_layout="binary")
    n = 65   # cells of 1/32 over [-1, 1]: blocks of 0.25
    v, tri = height_field_grid(n, 0.0)
    v = v.copy()
    v[:, 1] = np.where(v[:, 0] > 0.01, 0.2, 0.0)   # the cliff in the block [0, 0.25]
    k = 40
    cliff_o = np.c_[np.full(k, -0.3), np.full(k, 0.01), np.linspace(0.65, 0.9, k)]  # clear of
    # the box and sphere beside the grid (scenes)
    cliff_d = np.tile([1.0, 0.3, 0.0], (k, 1))   # at x = 0.26 (tmin) under the plateau
    points, dirs = near_surface(v, tri, 2000, seed=9)
    o = np.concatenate([cliff_o, points])
    d = np.concatenate([cliff_d, dirs])
    tmin = np.concatenate([np.full(k, 0.56), np.random.default_rng(9).uniform(0, 0.3, 2000)])
    out = []
    for scene in scenes(binary, v, tri, n)[:2]:
        ro, rd = pack_rays(o, d, tmin, np.inf)
        hits = binary.buffer(HIT_DTYPE.itemsize * len(ro))
        RayQuery(scene, binary.to_device(ro), binary.to_device(rd), hits, len(ro)).enqueue()
        out.append(binary.to_host(hits, HIT_DTYPE, len(ro)))
    walk, bvh = out
    assert_identical(walk, bvh)
    # the cliff's rays meet the plateau from under it at x = 1/3
    assert (walk["inst"][:k] == 0).all()
    assert np.allclose(o[:k, 0] + walk["t"][:k] * d[:k, 0], 1 / 3, atol=1e-4)
