"""BLAS structure after build and refit: every triangle in exactly one leaf, children inside
their parent's box, valid links, bounded depth; against the input geometry."""

import numpy as np
import pyopencl as cl
import pytest

from app.meshes import height_field_grid as grid_mesh
from raytrace.bvh import Blas, expected_depth_bound, tree_report, vertices_to_float4


def build(rt, vertices, triangles, **kw):
    blas = Blas(rt, rt.to_device(vertices_to_float4(vertices)),
                rt.to_device(np.ascontiguousarray(triangles, np.uint32)), len(vertices),
                len(triangles), **kw)
    blas.rebuild()
    return blas


def check_structure(blas, vertices, triangles):
    """Assert the invariants; return the report."""
    h = blas.host_arrays()
    n = len(triangles)
    rep = tree_report(h["nodes"], h["tris"], int(h["info"]["root"]))
    # every sorted slot is covered by exactly one leaf, and every triangle sits in one slot
    cover = np.zeros(n, np.int64)
    for first, count in zip(rep["leaf_first"], rep["leaf_count"], strict=True):
        cover[first:first + count] += 1
    assert cover.min() == 1 and cover.max() == 1
    prim = h["tris"]["p0"][:, 3].view(np.int32)
    assert np.array_equal(np.sort(prim), np.arange(n))
    # gathered vertices are the input triangle's vertices
    for k, name in enumerate(("p0", "p1", "p2")):
        assert np.array_equal(h["tris"][name][:, :3], vertices[triangles[prim, k]])
    # each child's box lies inside its parent's box; leaf boxes contain their triangles
    assert np.all(rep["child_lo"] >= rep["parent_lo"])
    assert np.all(rep["child_hi"] <= rep["parent_hi"])
    tri_lo = np.minimum(np.minimum(h["tris"]["p0"], h["tris"]["p1"]), h["tris"]["p2"])[:, :3]
    tri_hi = np.maximum(np.maximum(h["tris"]["p0"], h["tris"]["p1"]), h["tris"]["p2"])[:, :3]
    slot_leaf = np.repeat(np.arange(len(rep["leaf_first"])), rep["leaf_count"])
    slots = np.concatenate([np.arange(f, f + c) for f, c in zip(rep["leaf_first"],
                                                                 rep["leaf_count"], strict=True)])
    assert np.all(tri_lo[slots] >= rep["leaf_lo"][slot_leaf])
    assert np.all(tri_hi[slots] <= rep["leaf_hi"][slot_leaf])
    assert np.array_equal(rep["root_lo"], tri_lo.min(0))
    assert np.array_equal(rep["root_hi"], tri_hi.max(0))
    assert np.array_equal(h["info"]["lo"][:3], tri_lo.min(0))
    assert rep["max_leaf_size"] <= blas.leaf_size
    assert rep["depth"] <= expected_depth_bound(n)
    assert h["info"]["n_bad"] == 0
    return rep, h, tri_lo, tri_hi


@pytest.mark.parametrize("n", [1, 2, 4, 5, 37, 1000])
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_random_triangles_structure(rt, n, leaf_size):
    rng = np.random.default_rng(n)
    v = rng.random((3 * n, 3)).astype(np.float32)
    t = rng.permutation(3 * n).reshape(n, 3).astype(np.uint32)
    blas = build(rt, v, t, leaf_size=leaf_size)
    check_structure(blas, v, t)


def test_grid_refit_after_deformation(rt):
    v, t = grid_mesh(33)
    blas = build(rt, v, t)
    before = tree_report(*[blas.host_arrays()[k] for k in ("nodes", "tris")],
                         int(blas.info()["root"]))
    v2, _ = grid_mesh(33, t=1.7)
    v2[:, 1] *= 5.0
    cl.enqueue_copy(rt.queue, blas.vertices_buf, vertices_to_float4(v2))
    blas.refit()
    rep, h, _, _ = check_structure(blas, v2, t)
    # same topology: the same leaves in the same places
    assert np.array_equal(rep["leaf_first"], before["leaf_first"])
    assert rep["n_nodes"] == before["n_nodes"]


def test_rebuild_and_refit_are_bit_identical(rt):
    """Build and refit are deterministic, so repeats must match the first build node for node:
    a race between work-groups in the bottom-up pass shows up here (bench/stress_bvh.py runs the
    same check at 2M+ triangles on a GPU, where such races first appeared)."""
    from app.meshes import height_field_grid
    from raytrace import Scene

    v, t = height_field_grid(65)
    scene = Scene(rt)
    scene.add_instance(scene.add_mesh(v, t))
    scene.update()
    blas = scene.blas(0)
    first = blas.host_arrays()["nodes"].copy()
    for kind in ("rebuild", "refit", "rebuild", "refit"):
        getattr(blas, kind)()
        nodes = blas.host_arrays()["nodes"]
        assert np.array_equal(nodes.view(np.uint8), first.view(np.uint8)), kind
