"""The wide BLAS layout (raytrace.bvh_wide, kernels/bvh_wide.cl, traverse.h with TRACE_WIDE=1).

Its tree is walked on the host and checked against the mesh in float64 after a build, a refit
and a rebuild; its hits are compared with the binary layout's (which must agree bit for bit where
they name the same triangle) and with the float64 brute force; hard inputs and closed meshes are
traced in it; and the choice of layout (runtime, environment, scene, renderer) is checked.
"""

import numpy as np
import pyopencl as cl
import pytest

from app.meshes import height_field_grid
from kernels.runtime import Runtime
from raytrace import RayQuery, Scene
from raytrace.bvh import HIT_DTYPE, tree_report, vertices_to_float4
from raytrace.bvh_wide import BLOCK, WIDTH, block_bound, wide_node_bound
from raytrace.query import intersect_reference, pack_rays
from tests.raytrace.test_bvh_hard import mesh_with_degenerate_triangles
from tests.raytrace.test_intersect_watertight import leak_rays
from tests.raytrace.test_scene import affine, rotation


# -- helpers ------------------------------------------------------------------------------------
def make_scene(rt, layout, meshes, *, leaf_size=None, xforms=None):
    """A scene of static meshes [(vertices, triangles)], one instance each, built."""
    scene = Scene(rt, layout=layout, leaf_size=leaf_size)
    for i, (v, t) in enumerate(meshes):
        scene.add_instance(scene.add_mesh(v, t), None if xforms is None else xforms[i])
    scene.update()
    return scene


def trace(rt, scene, o, d, tmin=0.0, tmax=np.inf, any_hit=False):
    ro, rd = pack_rays(o, d, tmin, tmax)
    n = len(ro)
    hits = rt.buffer(HIT_DTYPE.itemsize * n)
    q = RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits, n, any_hit=any_hit)
    q.enqueue()
    h = rt.to_host(hits, HIT_DTYPE, n)
    assert scene.check() == {"overflows": 0, "bad_triangles": 0}
    return h


def assert_same_hits(wide, binary):
    """Same hit or miss everywhere; the same record bit for bit where both name the same
    triangle (same watertight arithmetic), else the same t within 1e-6 relative (a tie on a
    shared edge or vertex). Returns the mask of hits naming different triangles."""
    hit = binary["prim"] >= 0
    assert np.array_equal(wide["prim"] >= 0, hit), \
        f"{int(np.sum((wide['prim'] >= 0) != hit))} rays differ in hit or miss"
    same = (wide["prim"] == binary["prim"]) & (wide["inst"] == binary["inst"])
    assert np.array_equal(wide[same].view(np.uint8), binary[same].view(np.uint8))
    tw, tb = wide["t"][~same].astype(np.float64), binary["t"][~same].astype(np.float64)
    assert np.all(np.abs(tw - tb) <= 1e-6 * np.maximum(np.abs(tb), 1.0)), \
        f"different triangles at different t: {np.c_[tw, tb][np.abs(tw - tb) > 1e-6][:5]}"
    return ~same & hit


def hit_distance64(o, d, p0, p1, p2, eps=1e-7):
    """Float64 Moller-Trumbore of ray i against triangle i (row by row); NaN where it misses
    (barycentrics within eps of the edges count as hits)."""
    e1, e2 = p1 - p0, p2 - p0
    pv = np.cross(d, e2)
    det = (e1 * pv).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        tv = o - p0
        u = (tv * pv).sum(1) * inv
        q = np.cross(tv, e1)
        v = (d * q).sum(1) * inv
        t = (e2 * q).sum(1) * inv
    inside = (det != 0) & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps)
    return np.where(inside, t, np.nan)


def cos_to_normal(vertices, triangles, prim, d):
    """|cos| of the angle between each ray and the normal of triangle prim[i] (float64)."""
    p = np.asarray(vertices, np.float64)[np.asarray(triangles, np.int64)[prim]]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return np.abs((normal * d).sum(1)) / (np.linalg.norm(normal, axis=1)
                                          * np.linalg.norm(d, axis=1))


def t_tolerance(t, cos):
    """float32 t is as good as the angle allows: its error grows as 1 / cos(ray, normal)."""
    return 1e-5 * np.abs(t) / np.maximum(cos, 1e-6) + 1e-6


def assert_matches_reference(h, ref, vertices, triangles, d, min_same=0.9):
    """The hits of intersect_reference (same hit or miss; t within the float32 conditioning of
    the triangle hit, so a tie on a shared edge may name either triangle; u, v of the same
    triangle where the angle is not grazing; at least ``min_same`` of the hits name the same
    triangle at a non-grazing angle)."""
    hit = ref["prim"] >= 0
    assert np.array_equal(h["prim"] >= 0, hit), \
        f"{int(np.sum((h['prim'] >= 0) != hit))} rays differ in hit or miss"
    assert np.all(h["prim"][~hit] == -1)
    cos = cos_to_normal(vertices, triangles, ref["prim"][hit], d[hit])
    assert np.all(np.abs(h["t"][hit] - ref["t"][hit]) <= t_tolerance(ref["t"][hit], cos))
    same = (h["prim"][hit] == ref["prim"][hit]) & (cos > 0.01)
    assert same.sum() >= min_same * hit.sum()
    assert np.allclose(h["u"][hit][same], ref["u"][hit][same], atol=1e-4)
    assert np.allclose(h["v"][hit][same], ref["v"][hit][same], atol=1e-4)


def assert_any_hits_real(h, vertices, triangles, o, d, tmin, tmax):
    """Each any-hit record names a triangle the ray really crosses at that t, in the window."""
    hit = h["prim"] >= 0
    n = len(o)
    lo = np.broadcast_to(np.asarray(tmin, np.float64), (n,))[hit]
    hi = np.broadcast_to(np.asarray(tmax, np.float64), (n,))[hit]
    t = h["t"][hit].astype(np.float64)
    assert np.all((t >= lo.astype(np.float32)) & (t < hi.astype(np.float32)))
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles, np.int64)[h["prim"][hit]]
    t64 = hit_distance64(o[hit], d[hit], v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]])
    assert not np.isnan(t64).any(), f"{int(np.isnan(t64).sum())} any-hits on missed triangles"
    cos = cos_to_normal(vertices, triangles, h["prim"][hit], d[hit])
    assert np.all(np.abs(t - t64) <= t_tolerance(t64, cos))


def f32(a):
    """Rays as the device sees them (pack_rays rounds to float32), for a fair float64 oracle."""
    return np.asarray(a, np.float32).astype(np.float64)


def soup(n, seed):
    rng = np.random.default_rng(seed)
    v = rng.random((3 * n, 3)).astype(np.float32)
    t = rng.permutation(3 * n).reshape(n, 3)
    return v, t


# -- the host's independent walk of a wide tree ---------------------------------------------------
def check_wide(blas, vertices, triangles):
    """Assert every invariant of ``blas``'s wide tree against the mesh (float64) and against its
    binary tree; return the topology (for comparing a refit with the build)."""
    w, b = blas.wide.host_arrays(), blas.host_arrays()
    nodes, blocks, info = w["nodes"], w["blocks"], w["info"]
    nb, bb = w["node_base"], w["block_base"]
    n, n_nodes, n_blocks = len(triangles), len(nodes), len(blocks)
    V32 = np.asarray(vertices, np.float32)
    V = V32.astype(np.float64)
    T = np.asarray(triangles, np.int64)

    # header: counts within the bounds, levels contiguous from the single root
    assert int(info["truncated"]) == 0
    levels = info["level_count"].astype(np.int64)
    assert levels.sum() == int(info["n_nodes"]) == n_nodes
    assert levels[0] == 1
    assert np.array_equal(np.flatnonzero(levels), np.arange(np.count_nonzero(levels)))
    assert 1 <= n_nodes <= wide_node_bound(n)
    assert 1 <= n_blocks <= block_bound(n)
    level_of = np.repeat(np.arange(len(levels)), levels)

    ref, cnt = nodes["ref"].astype(np.int64), nodes["cnt"].astype(np.int64)   # (N, 8)
    lo = nodes["plane"][:, :3, :].transpose(0, 2, 1).astype(np.float64)       # (N, 8, 3)
    hi = nodes["plane"][:, 3:, :].transpose(0, 2, 1).astype(np.float64)
    empty, inner, leaf = cnt < 0, cnt == 0, cnt > 0

    # empty slots: the empty box; the others: finite proper boxes
    assert np.all(lo[empty] == np.inf) and np.all(hi[empty] == -np.inf)
    assert np.isfinite(lo[~empty]).all() and np.isfinite(hi[~empty]).all()
    assert np.all(lo[~empty] <= hi[~empty])
    n_children = (~empty).sum(1)
    if n > blas.leaf_size:
        assert n_children.min() >= 2
        # the greedy collapse opens inner children while a slot is free (wide_node_bound's proof)
        assert not np.any(inner[n_children < WIDTH])
    else:   # one leaf of every triangle
        assert n_nodes == 1 and n_children[0] == 1 and cnt[0].max() == n

    # inner links: in range, one level down, every node but the root the child of exactly one
    # slot; then the explicit walk from the root meets every node exactly once
    child = ref[inner] - nb
    assert child.size == 0 or (child.min() >= 0 and child.max() < n_nodes)
    parent = np.broadcast_to(np.arange(n_nodes)[:, None], cnt.shape)[inner]
    assert np.array_equal(level_of[child], level_of[parent] + 1)
    indegree = np.bincount(child, minlength=n_nodes)
    assert indegree[0] == 0 and np.all(indegree[1:] == 1)
    visits = np.zeros(n_nodes, np.int64)
    stack = [0]
    while stack:
        k = stack.pop()
        visits[k] += 1
        assert visits[k] == 1, f"wide node {k} reached twice"
        stack += [int(r) - nb for r in ref[k][inner[k]]]
    assert np.all(visits == 1), f"{int(np.sum(visits == 0))} wide nodes unreachable"

    # an inner slot's box is exactly the union of its child's non-empty slot boxes
    clo = np.where(empty[child][..., None], np.inf, lo[child]).min(1)
    chi = np.where(empty[child][..., None], -np.inf, hi[child]).max(1)
    assert np.array_equal(lo[inner], clo) and np.array_equal(hi[inner], chi)

    # leaves: block ranges in range, every block owned by exactly one leaf
    leaf_ref, leaf_cnt = ref[leaf] - bb, cnt[leaf]
    leaf_lo, leaf_hi = lo[leaf], hi[leaf]
    n_blk = (leaf_cnt + BLOCK - 1) // BLOCK
    assert leaf_cnt.max() <= blas.leaf_size
    assert leaf_ref.min() >= 0 and (leaf_ref + n_blk).max() <= n_blocks
    owner = np.zeros(n_blocks, np.int64)
    for r, c in zip(leaf_ref, n_blk, strict=True):
        owner[r:r + c] += 1
    assert np.all(owner == 1)

    # lanes below cnt: each input triangle exactly once, with the mesh's vertices exactly;
    # lanes past a leaf's end repeat one of the leaf's own triangles (never a false hit)
    prim = blocks["prim"].astype(np.int64)          # (B, 4)
    bv = blocks["v"].transpose(0, 3, 1, 2)          # (B, 4 lanes, 3 vertices, 3 axes)
    seen = np.zeros(n, np.int64)
    wide_leaves = {}
    for i, (r, c) in enumerate(zip(leaf_ref, leaf_cnt, strict=True)):
        j = np.arange(c)
        p = prim[r + j // BLOCK, j % BLOCK]
        assert p.min() >= 0 and p.max() < n
        seen[p] += 1
        assert np.array_equal(bv[r + j // BLOCK, j % BLOCK], V32[T[p]])
        # the slot's box contains its triangles, and is tight: exactly their float64 bounds
        v64 = V[T[p]].reshape(-1, 3)
        assert np.all(leaf_lo[i] <= v64.min(0)) and np.all(v64.max(0) <= leaf_hi[i])
        assert np.array_equal(leaf_lo[i], v64.min(0)) and np.array_equal(leaf_hi[i], v64.max(0))
        for q in range(c, BLOCK * n_blk[i]):
            blk, lane = r + q // BLOCK, q % BLOCK
            assert prim[blk, lane] in p
            assert np.array_equal(bv[blk, lane], V32[T[prim[blk, lane]]])
        wide_leaves[tuple(sorted(p.tolist()))] = (leaf_lo[i], leaf_hi[i])
    assert np.all(seen == 1), f"triangles in no leaf: {np.flatnonzero(seen == 0)[:5]}, " \
        f"in several: {np.flatnonzero(seen > 1)[:5]}"

    # the root's slots bound the whole mesh exactly
    root_lo = np.where(empty[0][:, None], np.inf, lo[0]).min(0)
    root_hi = np.where(empty[0][:, None], -np.inf, hi[0]).max(0)
    assert np.array_equal(root_lo, V[T].reshape(-1, 3).min(0))
    assert np.array_equal(root_hi, V[T].reshape(-1, 3).max(0))

    # the binary tree it was made from: the same leaves (as sets of triangles), the same boxes
    rep = tree_report(b["nodes"], b["tris"], int(b["info"]["root"]), b["node_base"],
                      b["tri_base"])
    bprim = b["tris"]["p0"][:, 3].view(np.int32)
    bin_leaves = {tuple(sorted(bprim[f:f + c].tolist())): (rep["leaf_lo"][k], rep["leaf_hi"][k])
                  for k, (f, c) in enumerate(zip(rep["leaf_first"], rep["leaf_count"],
                                                 strict=True))}
    assert bin_leaves.keys() == wide_leaves.keys()
    assert np.count_nonzero(levels) <= rep["depth"]   # never deeper than the binary tree
    for key, (blo, bhi) in bin_leaves.items():
        assert np.array_equal(wide_leaves[key][0], blo) and np.array_equal(wide_leaves[key][1], bhi)
    return {"ref": nodes["ref"].copy(), "cnt": nodes["cnt"].copy(), "prim": blocks["prim"].copy(),
            "levels": info["level_count"].copy(), "planes": nodes["plane"].copy()}


# -- 2. structure after build, refit and rebuild --------------------------------------------------
@pytest.mark.parametrize("leaf_size", [1, 4, 15])
def test_structure_build_refit_rebuild(rt, leaf_size):
    # a small static mesh first, so the grid's wide tree sits at non-zero node and block bases
    vs, ts = soup(37, 3)
    vs += np.float32(10.0)
    v, t = height_field_grid(33)
    vbuf = rt.to_device(vertices_to_float4(v))
    scene = Scene(rt, layout="wide", leaf_size=leaf_size)
    scene.add_instance(scene.add_mesh(vs, ts))
    grid = scene.add_mesh(vbuf, rt.to_device(t), dynamic=True, n_vertices=len(v),
                          n_triangles=len(t))
    scene.add_instance(grid)
    scene.update()
    check_wide(scene.blas(0), vs, ts)
    built = check_wide(scene.blas(grid), v, t)
    assert scene.blas(grid).wide.storage.node_base > 0
    assert scene.blas(grid).wide.storage.block_base > 0
    if leaf_size == 15:
        assert (built["cnt"] > BLOCK).any()  # leaves spanning several blocks were exercised

    # deform the grid's heights: a refit keeps the topology and refreshes boxes and triangles
    rng = np.random.default_rng(leaf_size)
    v2, _ = height_field_grid(33, t=1.7)
    v2[:, 1] = v2[:, 1] * 5.0 + rng.uniform(-0.02, 0.02, len(v2)).astype(np.float32)
    cl.enqueue_copy(rt.queue, vbuf, vertices_to_float4(v2))
    scene.update()
    refit = check_wide(scene.blas(grid), v2, t)
    for key in ("ref", "cnt", "prim", "levels"):
        assert np.array_equal(refit[key], built[key]), key
    assert not np.array_equal(refit["planes"], built["planes"])
    check_wide(scene.blas(0), vs, ts)  # the static mesh is left alone

    # hits after the refit are the float64 brute force's (the soup lies far off these rays)
    o = f32(np.stack([rng.uniform(-1.2, 1.2, 800), rng.uniform(0.2, 0.5, 800),
                      rng.uniform(-1.2, 1.2, 800)], -1))
    d = f32(rng.normal(size=(800, 3)) * [1.0, 0.0, 1.0] + [0.0, -1.0, 0.0])
    got = trace(rt, scene, o, d)
    ref = intersect_reference(v2, t, o, d)
    assert np.mean(ref["prim"] >= 0) > 0.5
    assert np.all(got["inst"][got["prim"] >= 0] == 1)
    assert_matches_reference(got, ref, v2, t, d)

    # a rebuild over the deformed vertices is a valid tree again
    scene.update(rebuild=True)
    check_wide(scene.blas(grid), v2, t)


# -- 3. hits: the wide layout against the binary one and the float64 brute force ------------------
def grid_rays(rng, xs, n=500):
    """Rays of every family the traversals must agree on, with their tmin and tmax:
    random rays from around the grid, axis-parallel rays (some along grid lines, some vertical
    through vertices), rays starting inside the boxes (in the grid's thin slab), and random rays
    with tmin/tmax windows. Also the mask of the rays along grid lines (ties expected)."""
    o1 = np.stack([rng.uniform(-1.3, 1.3, n), rng.uniform(-0.2, 0.6, n),
                   rng.uniform(-1.3, 1.3, n)], -1)
    d1 = rng.normal(size=(n, 3))
    axis = rng.integers(0, 3, n)
    d2 = np.eye(3)[axis] * rng.choice([-1.0, 1.0], (n, 1))
    o2 = np.stack([rng.uniform(-1.2, 1.2, n), rng.uniform(-0.05, 0.05, n),
                   rng.uniform(-1.2, 1.2, n)], -1)
    on_line = rng.random(n) < 0.5   # exactly above a grid line: the ray runs over shared edges
    o2[on_line, 0] = rng.choice(xs, on_line.sum())
    o2[on_line, 2] = rng.choice(xs, on_line.sum())
    vertical = axis == 1
    o2[vertical, 1] = np.where(d2[vertical, 1] < 0, 0.5, -0.5)  # down or up through the grid
    o3 = np.stack([rng.uniform(-1, 1, n), rng.uniform(-0.04, 0.04, n), rng.uniform(-1, 1, n)], -1)
    d3 = rng.normal(size=(n, 3))
    o4 = np.stack([rng.uniform(-1.3, 1.3, n), rng.uniform(-0.2, 0.6, n),
                   rng.uniform(-1.3, 1.3, n)], -1)
    d4 = rng.normal(size=(n, 3))
    lo4 = rng.uniform(0.0, 0.8, n)
    hi4 = lo4 + rng.uniform(0.05, 1.0, n)
    o = f32(np.concatenate([o1, o2, o3, o4]))
    d = f32(np.concatenate([d1, d2, d3, d4]))
    tmin = f32(np.concatenate([np.zeros(3 * n), lo4]))
    tmax = f32(np.concatenate([np.full(3 * n, np.inf), hi4]))
    on_edges = np.concatenate([np.zeros(n, bool), on_line, np.zeros(2 * n, bool)])
    return o, d, tmin, tmax, on_edges


@pytest.mark.parametrize("wide_leaf", [None, 1, 15])
def test_wide_hits_equal_binary_and_reference(rt, wide_leaf):
    v, t = height_field_grid(33)
    rng = np.random.default_rng(21)
    # every grid line, the outer ones (in the faces of the mesh's box) included
    o, d, tmin, tmax, on_edges = grid_rays(rng, np.unique(v[:, 0]))
    wide = make_scene(rt, "wide", [(v, t)], leaf_size=wide_leaf)
    binary = make_scene(rt, "binary", [(v, t)])
    assert wide.trace_defines == {"TRACE_WIDE": 1} and binary.trace_defines == {"TRACE_WIDE": 0}
    hw = trace(rt, wide, o, d, tmin, tmax)
    hb = trace(rt, binary, o, d, tmin, tmax)
    ref = intersect_reference(v, t, o, d, tmin, tmax)
    hit = ref["prim"] >= 0
    assert 0.3 < hit.mean() < 0.9
    n = len(o) // 4
    window = np.arange(len(o)) >= 3 * n
    assert hit[window].any() and (~hit[window]).any()   # windows cut some hits off, keep others
    differ = assert_same_hits(hw, hb)
    assert not differ[~on_edges].any()   # only rays along shared edges may see ties
    assert_matches_reference(hw, ref, v, t, d, min_same=0.75)   # many rays through vertices

    # any-hit: the same hit or miss as the closest hit, and every record a real crossing
    aw = trace(rt, wide, o, d, tmin, tmax, any_hit=True)
    ab = trace(rt, binary, o, d, tmin, tmax, any_hit=True)
    assert np.array_equal(aw["prim"] >= 0, hit) and np.array_equal(ab["prim"] >= 0, hit)
    assert_any_hits_real(aw, v, t, o, d, tmin, tmax)


def test_wide_random_soup_matches_float64_brute_force(rt):
    rng = np.random.default_rng(1)
    v = rng.random((300, 3)).astype(np.float32)
    t = rng.integers(0, 300, (100, 3))
    o = f32(rng.random((1500, 3)) * 1.4 - 0.2)
    d = f32(rng.normal(size=(1500, 3)))
    scene = make_scene(rt, "wide", [(v, t)])
    ref = intersect_reference(v, t, o, d)
    assert 0.2 < np.mean(ref["prim"] >= 0) < 0.9
    assert_matches_reference(trace(rt, scene, o, d), ref, v, t, d)
    anyh = trace(rt, scene, o, d, any_hit=True)
    assert np.array_equal(anyh["prim"] >= 0, ref["prim"] >= 0)
    assert_any_hits_real(anyh, v, t, o, d, 0.0, np.inf)


def test_two_instances_rotated_and_scaled(rt):
    rng = np.random.default_rng(4)
    vg, tg = height_field_grid(17)
    vs, ts = soup(60, 5)
    vs -= np.float32(0.5)
    xforms = [affine(rotation([0.2, 1, 0.1], 0.6), [0.1, -0.2, 0.0]),
              affine(rotation([1, 2, 3], 0.9), [0.3, 0.4, -0.2], 1.7)]
    xforms[1][:3, :3] = xforms[1][:3, :3] @ np.diag([1.0, 0.5, 2.0])   # non-uniform too
    meshes = [(vg, tg), (vs, ts)]
    wide = make_scene(rt, "wide", meshes, xforms=xforms)
    binary = make_scene(rt, "binary", meshes, xforms=xforms)
    n = 3000
    o = f32(rng.uniform(-2, 2, (n, 3)))
    d = f32(rng.normal(size=(n, 3)))
    hw, hb = trace(rt, wide, o, d), trace(rt, binary, o, d)
    assert assert_same_hits(hw, hb).mean() < 0.001
    # the transformed meshes as one soup in float64
    world = [v.astype(np.float64) @ x[:3, :3].T + x[:3, 3] for (v, _), x in zip(meshes, xforms,
                                                                                 strict=True)]
    tris = np.concatenate([tg, ts + len(vg)])
    owner = np.repeat([0, 1], [len(tg), len(ts)])
    local = np.concatenate([np.arange(len(tg)), np.arange(len(ts))])
    ref = intersect_reference(np.concatenate(world), tris, o, d)
    hit = ref["prim"] >= 0
    assert 0.1 < hit.mean() < 0.9
    assert set(np.unique(hw["inst"][hw["prim"] >= 0])) == {0, 1}
    assert np.array_equal(hw["prim"] >= 0, hit)
    assert np.allclose(hw["t"][hit], ref["t"][hit], rtol=1e-4, atol=1e-5)
    same = ((hw["inst"][hit] == owner[ref["prim"][hit]])
            & (hw["prim"][hit] == local[ref["prim"][hit]]))
    assert same.mean() > 0.995
    aw = trace(rt, wide, o, d, any_hit=True)
    assert np.array_equal(aw["prim"] >= 0, hit)


# -- 4. hard inputs in the wide layout ------------------------------------------------------------
def compare_layouts(rt, v, t, o, d, *, leaf_size=None):
    """Build both layouts, check the wide tree, and assert the wide hits (closest and any) equal
    the binary layout's and the float64 brute force's; returns the wide closest hits."""
    wide = make_scene(rt, "wide", [(v, t)], leaf_size=leaf_size)
    check_wide(wide.blas(0), v, t)
    binary = make_scene(rt, "binary", [(v, t)])
    hw, hb = trace(rt, wide, o, d), trace(rt, binary, o, d)
    assert_same_hits(hw, hb)
    assert_matches_reference(hw, intersect_reference(v, t, o, d), v, t, d)
    aw = trace(rt, wide, o, d, any_hit=True)
    assert np.array_equal(aw["prim"] >= 0, hw["prim"] >= 0)
    assert_any_hits_real(aw, v, t, o, d, 0.0, np.inf)
    return hw


def rays_at(rng, v, t, n):
    """n rays from random origins to random points inside random triangles (they hit), and n
    random rays."""
    v = np.asarray(v, np.float64)
    k = rng.integers(0, len(t), n)
    b = rng.dirichlet([1.0, 1.0, 1.0], n)
    target = np.einsum("nk,nkc->nc", b, v[np.asarray(t)[k]])
    lo, hi = v.min(0) - 0.5, v.max(0) + 0.5
    o = rng.uniform(lo, hi, (2 * n, 3))
    d = np.concatenate([target - o[:n], rng.normal(size=(n, 3))])
    return f32(o), f32(d)


def test_single_triangle(rt):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    t = np.array([[0, 1, 2]])
    o = np.array([[0.25, 0.25, 1.0], [0.25, 0.25, -1.0], [2.0, 2.0, 1.0], [0.0, 0.0, 1.0],
                  [0.3, 0.6, 0.0], [0.25, 1.0, 1.0]])
    d = np.array([[0, 0, -2.0], [0, 0, 1.0], [0, 0, -1.0], [0, 0, -1.0], [1.0, 0, 0],
                  [0, -1.0, -1.0]])   # in the plane: no hit; onto the edge's midpoint: a hit
    got = compare_layouts(rt, v, t, o, d)
    assert np.array_equal(got["prim"], [0, 0, -1, 0, -1, 0])  # the vertex itself counts
    assert np.allclose(got["t"][[0, 1, 3, 5]], [0.5, 1.0, 1.0, 1.0])
    assert np.allclose(got["u"][:2], 0.25) and np.allclose(got["v"][:2], 0.25)
    w = make_scene(rt, "wide", [(v, t)]).blas(0).wide.host_arrays()
    assert int(w["info"]["n_nodes"]) == 1 and int(w["info"]["n_blocks"]) == 1
    assert np.array_equal(w["nodes"][0]["cnt"], [1] + [-1] * 7)
    assert np.array_equal(w["blocks"][0]["prim"], [0, 0, 0, 0])   # padded with triangle 0


def test_all_triangles_at_one_point(rt):
    n = 3000
    v = np.full((3 * n, 3), 0.3, np.float32)
    t = np.arange(3 * n).reshape(n, 3)
    o = np.array([[0.3, 0.3, -1.0], [0.0, 0.0, 0.0], [0.3, 0.3, 0.3], [0.3, -1.0, 0.3]])
    d = np.array([[0.0, 0.0, 1.0], [1.0, 1.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    got = compare_layouts(rt, v, t, o, d)
    assert np.all(got["prim"] == -1)   # a point has no area: never hit
    w = make_scene(rt, "wide", [(v, t)]).blas(0).wide.host_arrays()
    # equal keys split by position: a balanced tree of ~n/4 leaves, 8 wide, a few levels deep
    assert np.count_nonzero(w["info"]["level_count"]) <= 6


def test_degenerate_triangles_among_good_ones(rt):
    rng = np.random.default_rng(8)
    v, t = mesh_with_degenerate_triangles(rng)
    t[2::8] = t[2::8, :1]                                 # three equal vertices
    p = v[t].astype(np.float64)
    good = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1) > 1e-3
    o, d = rays_at(rng, v, t[good], 800)   # aimed at good triangles: slivers are ill-posed
    got = compare_layouts(rt, v, t, o, d)
    assert 0.4 < np.mean(got["prim"] >= 0) < 0.95


@pytest.mark.parametrize("leaf_size", [1, 4, 15])
@pytest.mark.parametrize("n", [4, 5, 8, 9])
def test_small_meshes_and_leaf_sizes(rt, n, leaf_size):
    v, t = soup(n, 100 + n)
    rng = np.random.default_rng(n * leaf_size)
    o, d = rays_at(rng, v, t, 150)
    got = compare_layouts(rt, v, t, o, d, leaf_size=leaf_size)
    assert np.mean(got["prim"][:150] >= 0) > 0.95   # the rays aimed at triangles hit
    assert len(np.unique(got["prim"][got["prim"] >= 0])) == n


@pytest.mark.parametrize("layout", ["wide", "binary"])
def test_rays_in_the_bounding_box_faces_hit(rt, layout):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    t = np.array([[0, 1, 2]])
    # straight down onto each corner and edge midpoint of the triangle
    xy = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [0, 0.5], [0.5, 0.5]])
    # +0 and -0 direction components: the ray lies in an upper or a lower face of the boxes
    # (0 x inf = NaN in the slab test, which must not cull the box)
    o = np.tile(np.c_[xy, np.ones(len(xy))], (2, 1))
    d = np.r_[np.tile([0.0, 0.0, -1.0], (len(xy), 1)), np.tile([-0.0, -0.0, -1.0], (len(xy), 1))]
    xy = np.r_[xy, xy]
    assert np.all(intersect_reference(v, t, o, d)["prim"] == 0)
    got = trace(rt, make_scene(rt, layout, [(v, t)]), o, d)
    assert np.all(got["prim"] == 0), f"missed: {xy[got['prim'] < 0].tolist()}"


# -- 5. the choice of layout ----------------------------------------------------------------------
def build_options(rtx, source="trace_query.cl", defines=None):
    prg = rtx.program(source, defines)
    return prg.get_build_info(rtx.device, cl.program_build_info.OPTIONS).split()


def test_runtime_layout_sets_trace_wide(rt):
    binary_rt = Runtime(rt.device, bvh_layout="binary")
    wide_rt = Runtime(rt.device, bvh_layout="wide")
    assert binary_rt.bvh_layout == "binary" and wide_rt.bvh_layout == "wide"
    assert "-DTRACE_WIDE=0" in build_options(binary_rt)
    assert "-DTRACE_WIDE=1" not in build_options(binary_rt)
    assert "-DTRACE_WIDE=1" in build_options(wide_rt)
    # a kernel's own define wins over the runtime's
    own = build_options(binary_rt, defines={"TRACE_WIDE": 1})
    assert "-DTRACE_WIDE=1" in own and "-DTRACE_WIDE=0" not in own
    # a scene on the binary runtime is binary (leaves of 1, no wide tree) and traces right
    v, t = soup(50, 9)
    scene = make_scene(binary_rt, None, [(v, t)])
    assert scene.layout == "binary" and scene.trace_defines == {"TRACE_WIDE": 0}
    assert scene.leaf_size == 1 and scene.blas(0).wide is None
    wscene = make_scene(wide_rt, None, [(v, t)])
    assert wscene.layout == "wide" and wscene.leaf_size == 4 and wscene.blas(0).wide is not None
    o, d = rays_at(np.random.default_rng(2), v, t, 200)
    ref = intersect_reference(v, t, o, d)
    assert_matches_reference(trace(binary_rt, scene, o, d), ref, v, t, d)
    assert_matches_reference(trace(wide_rt, wscene, o, d), ref, v, t, d)


def test_runtime_default_and_environment(rt, monkeypatch):
    monkeypatch.delenv("LBWATER_BVH_LAYOUT", raising=False)
    default = Runtime(rt.device)
    assert default.bvh_layout == ("binary" if default.is_gpu else "wide")
    if rt.is_pocl:
        assert default.bvh_layout == "wide"
    for layout in ("binary", "wide"):
        monkeypatch.setenv("LBWATER_BVH_LAYOUT", layout)
        fresh = Runtime(rt.device)
        assert fresh.bvh_layout == layout
        assert f"-DTRACE_WIDE={int(layout == 'wide')}" in build_options(fresh, "bvh_wide.cl")
        assert Scene(fresh).layout == layout
        other = "wide" if layout == "binary" else "binary"
        assert Runtime(rt.device, bvh_layout=other).bvh_layout == other   # the argument wins
    monkeypatch.setenv("LBWATER_BVH_LAYOUT", "bogus")
    with pytest.raises(ValueError, match="bogus"):
        Runtime(rt.device)


def test_scene_rejects_unknown_layout(rt):
    with pytest.raises(ValueError) as err:
        Scene(rt, layout="bogus")
    msg = str(err.value)
    assert "binary" in msg and "wide" in msg and "bogus" in msg


def test_renderer_refuses_a_scene_of_the_other_layout(rt):
    from raytrace.render import Renderer, RenderSettings
    from raytrace.render_scene import RenderScene

    other = "binary" if rt.bvh_layout == "wide" else "wide"
    other_rt = Runtime(rt.device, bvh_layout=other)
    settings = RenderSettings(width=8, height=8, spp=1, bounces=0, aov=True)
    v, t = height_field_grid(9)

    def renderer(rtx, layout):
        sc = RenderScene(rtx, layout=layout)
        sc.add_instance(sc.add_mesh(v, t))
        sc.add_light("directional", direction=(0, -1, 0), color=(1, 1, 1))
        r = Renderer(rtx, sc, settings)
        r.set_camera((0.1, 1.5, 0.2), (0, 0, 0), (0, 0, 1), 40)
        return r

    prims = []
    for rtx, layout in ((rt, rt.bvh_layout), (other_rt, other)):
        r = renderer(rtx, layout)
        r.render()
        prims.append(r.read_aov()["prim"])
    assert np.all(prims[0] >= 0)                  # the grid fills the view
    assert np.array_equal(prims[0], prims[1])     # both layouts see the same triangles
    for rtx, layout in ((rt, other), (other_rt, rt.bvh_layout)):
        with pytest.raises(ValueError, match=f"scene's BVH layout is '{layout}'"):
            renderer(rtx, layout).render()


# -- 6. watertightness in the wide layout ---------------------------------------------------------
@pytest.mark.parametrize("leaf_size", [1, 4, 15])
@pytest.mark.parametrize("bumpy", [False, True])
def test_closed_mesh_never_leaks(rt, bumpy, leaf_size):
    v, f, o, d, n_targets = leak_rays(bumpy)
    scene = make_scene(rt, "wide", [(v, f)], leaf_size=leaf_size)
    check_wide(scene.blas(0), v, f)
    hits = trace(rt, scene, o, d)
    assert len(o) > 5000
    assert np.all(hits["prim"] >= 0), f"{np.sum(hits['prim'] < 0)} rays leaked"
    assert np.all(trace(rt, scene, o, d, any_hit=True)["prim"] >= 0)
    assert_same_hits(hits, trace(rt, make_scene(rt, "binary", [(v, f)]), o, d))
    if not bumpy:  # from the centre of a convex sphere the first hit is the target (t = 1)
        assert np.allclose(hits["t"][: len(v)], 1.0, atol=1e-5)
        assert np.all(hits["t"][:n_targets] <= 1.0 + 1e-5)
