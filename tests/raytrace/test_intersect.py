"""raytrace.intersect against a float64 brute-force reference on small meshes."""

import numpy as np
import pytest

from app.meshes import height_field_grid as grid_mesh
from raytrace import intersect
from raytrace.query import intersect_reference as brute_force


def assert_hits_match(got, ref, scale):
    hit_ref = ref["prim"] >= 0
    assert np.array_equal(got["prim"] >= 0, hit_ref)
    both = hit_ref
    # same triangle, or (a tie on a shared edge) the same distance
    same = (got["prim"][both] == ref["prim"][both])
    close = np.abs(got["t"][both] - ref["t"][both]) <= 1e-5 * scale
    assert np.all(same | close)
    assert np.allclose(got["t"][both], ref["t"][both], rtol=1e-5, atol=1e-6 * scale)
    s = both & (got["prim"] == ref["prim"])
    assert np.allclose(got["u"][s], ref["u"][s], atol=1e-4)
    assert np.allclose(got["v"][s], ref["v"][s], atol=1e-4)
    assert np.all(np.isinf(got["t"][~hit_ref])) and np.all(got["prim"][~hit_ref] == -1)


def test_random_soup_random_rays(rt):
    rng = np.random.default_rng(1)
    v = rng.random((300, 3)).astype(np.float32)
    t = rng.integers(0, 300, (100, 3))
    o = rng.random((1500, 3)) * 1.4 - 0.2
    d = rng.normal(size=(1500, 3))
    got = intersect(v, t, o, d, device=rt)
    ref = brute_force(v, t, o, d)
    assert 0.2 < np.mean(ref["prim"] >= 0) < 0.9   # the test sees both hits and misses
    assert_hits_match(got, ref, 1.0)


def test_axis_parallel_rays_and_inside_starts_on_a_grid(rt):
    v, t = grid_mesh(17)
    rng = np.random.default_rng(2)
    n = 600
    o = np.stack([rng.uniform(-1, 1, n), rng.uniform(-0.02, 0.02, n), rng.uniform(-1, 1, n)], -1)
    axes = np.eye(3)[rng.integers(0, 3, n)] * rng.choice([-1.0, 1.0], (n, 1))
    got = intersect(v, t, o, axes, device=rt)
    ref = brute_force(v, t, o, axes)
    assert np.mean(ref["prim"] >= 0) > 0.2
    assert_hits_match(got, ref, 1.0)


def test_tmin_tmax_and_any_hit(rt):
    rng = np.random.default_rng(3)
    v = rng.random((240, 3)).astype(np.float32)
    t = np.arange(240).reshape(80, 3)
    o = rng.random((800, 3)) * 1.4 - 0.2
    d = rng.normal(size=(800, 3))
    tmin = rng.uniform(0, 0.3, 800)
    tmax = rng.uniform(0.3, 2.0, 800)
    got = intersect(v, t, o, d, tmin=tmin, tmax=tmax, device=rt)
    ref = brute_force(v, t, o, d, tmin, tmax)
    assert_hits_match(got, ref, 1.0)
    anyh = intersect(v, t, o, d, tmin=tmin, tmax=tmax, any_hit=True, device=rt)
    assert np.array_equal(anyh["hit"], ref["prim"] >= 0)
    h = anyh["hit"]
    assert np.all((anyh["t"][h] >= tmin[h] * (1 - 1e-6)) & (anyh["t"][h] < tmax[h]))


@pytest.mark.parametrize("bad, match", [
    (dict(origins=np.zeros((2, 2))), "origins must have shape"),
    (dict(directions=np.zeros((3, 3))), "direction 0 is zero"),
    (dict(vertices=np.full((3, 3), np.nan)), "non-finite"),
    (dict(triangles=np.array([[0, 1, 5]])), "indices must lie"),
])
def test_bad_input_one_line_errors(rt, bad, match):
    args = dict(vertices=np.eye(3), triangles=np.array([[0, 1, 2]]), origins=np.zeros((3, 3)),
                directions=np.ones((3, 3)))
    args.update(bad)
    with pytest.raises(ValueError, match=match) as e:
        intersect(args["vertices"], args["triangles"], args["origins"], args["directions"],
                  device=rt)
    assert "\n" not in str(e.value)
