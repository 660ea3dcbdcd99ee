"""Hard inputs: coincident and degenerate triangles, one triangle, over 2^21 triangles, NaN
vertices. The build always finishes, its depth stays bounded, and hits stay exact."""

import math

import numpy as np
import pyopencl as cl
import pytest

from app.bench_bvh import check_grid_hits, rays_incoherent
from app.meshes import height_field_grid
from raytrace import Blas, Scene, intersect
from raytrace.bvh import expected_depth_bound, tree_report, vertices_to_float4
from raytrace.query import intersect_reference


def built(rt, v, t, **kw):
    blas = Blas(rt, rt.to_device(vertices_to_float4(v)), rt.to_device(np.asarray(t, np.uint32)),
                len(v), len(t), **kw)
    blas.rebuild()
    h = blas.host_arrays()
    return blas, h, tree_report(h["nodes"], h["tris"], int(h["info"]["root"]))


def test_all_triangles_at_one_point(rt):
    n = 5000
    v = np.full((3 * n, 3), 0.3, np.float32)
    t = np.arange(3 * n).reshape(n, 3)
    blas, h, rep = built(rt, v, t)
    assert rep["leaf_count"].sum() == n and rep["max_leaf_size"] <= blas.leaf_size
    # equal keys split by position: a balanced tree, not a ladder
    assert rep["depth"] <= math.ceil(math.log2(n / blas.leaf_size)) + 1
    o = np.array([[0.3, 0.3, -1.0], [0.0, 0.0, 0.0]])
    d = np.array([[0.0, 0.0, 1.0], [1.0, 1.0, 1.0]])
    hits = intersect(v, t, o, d, device=rt)
    assert np.all(hits["prim"] == -1)  # a point has no area: never hit


def mesh_with_degenerate_triangles(rng):
    """200 random triangles over 600 vertices; every 4th has two equal vertices and the next
    one three collinear vertices."""
    v = rng.random((600, 3)).astype(np.float32)
    t = rng.integers(0, 600, (200, 3))
    t[::4, 2] = t[::4, 1]                                 # two equal vertices
    v[t[1::4, 2]] = 0.5 * (v[t[1::4, 0]] + v[t[1::4, 1]])  # collinear
    return v, t


def test_degenerate_triangles_among_good_ones(rt):
    rng = np.random.default_rng(8)
    v, t = mesh_with_degenerate_triangles(rng)
    o = rng.random((1500, 3)) * 1.4 - 0.2
    d = rng.normal(size=(1500, 3))
    got = intersect(v, t, o, d, device=rt)
    ref = intersect_reference(v, t, o, d)
    assert np.array_equal(got["prim"] >= 0, ref["prim"] >= 0)
    hit = ref["prim"] >= 0
    assert np.allclose(got["t"][hit], ref["t"][hit], rtol=1e-5, atol=1e-6)


def test_single_triangle(rt):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    t = np.array([[0, 1, 2]])
    blas, h, rep = built(rt, v, t)
    assert rep["n_leaves"] == 1 and rep["depth"] == 1
    o = np.array([[0.25, 0.25, 1.0], [0.25, 0.25, -1.0], [2.0, 2.0, 1.0], [0.0, 0.0, 1.0]])
    d = np.array([[0, 0, -2.0], [0, 0, 1.0], [0, 0, -1.0], [0, 0, -1.0]])
    got = intersect(v, t, o, d, device=rt)
    assert np.array_equal(got["prim"], [0, 0, -1, 0])       # the vertex itself counts
    assert np.allclose(got["t"][[0, 1, 3]], [0.5, 1.0, 1.0])
    assert np.allclose(got["u"][:2], 0.25) and np.allclose(got["v"][:2], 0.25)


def test_more_than_2_pow_21_triangles(rt):
    n = 1026                                  # 2 * 1025^2 = 2,101,250 > 2^21 triangles
    v, t = height_field_grid(n)
    assert len(t) > 2**21
    scene = Scene(rt)
    scene.add_instance(scene.add_mesh(v, t))
    scene.update()
    blas = scene.blas(0)
    h = blas.host_arrays()
    rep = tree_report(h["nodes"], h["tris"], int(h["info"]["root"]))
    assert rep["leaf_count"].sum() == len(t) and rep["depth"] <= expected_depth_bound(len(t))
    prim = h["tris"]["p0"][:, 3].view(np.int32)
    assert np.array_equal(np.bincount(prim, minlength=len(t)), np.ones(len(t)))
    o, d = rays_incoherent(2000, np.random.default_rng(1))
    got = intersect(v, t, o, d, device=rt)
    chk = check_grid_hits(n, v, t, o, d, got, np.inf, 300)
    assert chk["hit_agreement"] == 1.0 and chk["prim_or_t_agreement"] == 1.0


def test_nan_vertices_are_a_clear_error(rt):
    v = np.random.default_rng(0).random((30, 3)).astype(np.float32)
    t = np.arange(30).reshape(10, 3)
    v[7, 1] = np.nan
    with pytest.raises(ValueError, match="vertex 7 has a non-finite coordinate"):
        intersect(v, t, np.zeros((1, 3)), np.ones((1, 3)), device=rt)
    # device buffers are not read back by the build: it finishes, and check() reports
    vbuf = rt.to_device(vertices_to_float4(v))
    scene = Scene(rt)
    scene.add_instance(scene.add_mesh(vbuf, rt.to_device(t.astype(np.uint32)), n_vertices=30,
                                      n_triangles=10, dynamic=True))
    scene.update()
    with pytest.raises(ValueError, match="mesh 0: 1 triangles have a NaN"):
        scene.check()
    v[7, 1] = 0.5
    cl.enqueue_copy(rt.queue, vbuf, vertices_to_float4(v))
    scene.update()
    assert scene.check() == {"overflows": 0, "bad_triangles": 0}


@pytest.mark.parametrize("n_tris, leaf_size", [(200, 1), (3, 4)])  # (3, 4): the one-leaf root
def test_refit_counts_nan_triangles_afresh(rt, n_tris, leaf_size):
    """A refit has no header reset: the launch's count is handed over at the root, so each refit
    reports exactly its own non-finite triangles, never the sum over refits."""
    rng = np.random.default_rng(5)
    v = rng.random((3 * n_tris, 3)).astype(np.float32)
    t = np.arange(3 * n_tris).reshape(n_tris, 3)
    vbuf = rt.to_device(vertices_to_float4(v))
    blas = Blas(rt, vbuf, rt.to_device(t.astype(np.uint32)), len(v), n_tris,
                leaf_size=leaf_size)
    blas.rebuild()
    assert int(blas.info()["n_bad"]) == 0
    bad = v.copy()
    bad[[1, 4], 0] = np.nan                       # two triangles (vertices 1 and 4)
    cl.enqueue_copy(rt.queue, vbuf, vertices_to_float4(bad))
    for _ in range(3):
        blas.refit()
        assert int(blas.info()["n_bad"]) == (2 if n_tris > 1 else 1)
        with pytest.raises(ValueError, match="NaN or infinite"):
            blas.check()
    cl.enqueue_copy(rt.queue, vbuf, vertices_to_float4(v))
    blas.refit()
    assert int(blas.info()["n_bad"]) == 0
    blas.check()
    assert int(blas.info()["n_bad_pending"]) == 0


def test_clustered_input_depth_stays_bounded(rt):
    # coordinates spread over 30 octaves: Morton codes collide in long runs
    rng = np.random.default_rng(9)
    n = 20000
    c = (2.0 ** -rng.integers(0, 30, (n, 3))) * rng.choice([-1, 1], (n, 3))
    v = np.repeat(c, 3, axis=0).astype(np.float32) + rng.normal(scale=1e-9, size=(3 * n, 3))
    t = np.arange(3 * n).reshape(n, 3)
    blas, h, rep = built(rt, v.astype(np.float32), t)
    assert rep["leaf_count"].sum() == n
    assert rep["depth"] <= expected_depth_bound(n)
