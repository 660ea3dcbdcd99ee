"""A grid mesh traced as a height field (raytrace.heightfield, kernels/traverse_heightfield.h)
gives the BVH's hits bit for bit: the same scene with the grid added as a plain mesh is the
oracle (and the float64 brute force behind it), over random, grazing, vertical, upward and
edge-aimed rays, closest and any hit, the cooperative walk too; its bounds pass equals NumPy's
block ranges; bad grids are one-line errors."""

import numpy as np
import pytest

from app.meshes import height_field_grid
from kernels.layout import check_struct, device_layout
from kernels.runtime import Runtime
from raytrace import Scene
from raytrace.heightfield import (
    HEIGHTFIELD_DTYPE,
    HF_BLOCK,
    HF_NONE,
    HF_SLOPE_MARGIN,
    HF_WG,
    grid_blocks,
)
from raytrace.query import intersect_reference
from tests.raytrace.test_intersect import assert_hits_match
from tests.raytrace.test_render_plans import BOX
from tests.raytrace.test_trace_coop import sphere, trace
from tests.raytrace.test_trace_flavours import as_result


@pytest.fixture(scope="module")
def binary_rt(rt):
    return Runtime(rt.device, bvh_layout="binary")


def test_struct_and_defines_match_the_header(rt):
    assert HEIGHTFIELD_DTYPE.itemsize == 128
    check_struct(rt, "heightfield.h", "HeightField", HEIGHTFIELD_DTYPE)
    size, _ = device_layout(rt, "heightfield.h", "HeightField", [])
    assert size == 128
    src = (rt_dir := __import__("kernels.runtime", fromlist=["KERNEL_DIR"]).KERNEL_DIR)
    text = (src / "heightfield.h").read_text()
    for name, value in (("HF_BLOCK", HF_BLOCK), ("HF_WG", HF_WG), ("HF_NONE", f"({HF_NONE})"),
                        ("HF_SLOPE_MARGIN", f"{HF_SLOPE_MARGIN}f")):
        assert f"#define {name} {value}" in text, name
    assert rt_dir is src


def grid(n=41, t=0.0, skew=(1.0, 1.0), offset=(0.0, 0.0)):
    """A wavy n x n grid, stretched by ``skew`` and moved by ``offset`` in x and z."""
    v, tri = height_field_grid(n, t)
    v = v.copy()
    v[:, 0] = v[:, 0] * skew[0] + offset[0]
    v[:, 2] = v[:, 2] * skew[1] + offset[1]
    return v, tri


def scenes(rt, v, tri, n, xform=None):
    """The same three instances twice: the grid as a height field, then as a BVH mesh."""
    out = []
    for as_grid in (True, False):
        scene = Scene(rt, leaf_size=2)
        scene.add_instance(scene.add_mesh(v, tri, grid=(n, n) if as_grid else None), xform)
        m = np.eye(4)
        m[:3, :3] *= 0.5
        m[:3, 3] = (0.3, -0.05, -0.2)
        scene.add_instance(scene.add_mesh(*BOX), m)
        m = np.eye(4)
        m[:3, 3] = (-0.4, 0.2, 0.3)
        scene.add_instance(scene.add_mesh(*sphere()), m)
        scene.update()
        out.append(scene)
    return out


def ray_set(v, n_random=1500, seed=4):
    """Random rays from above and below, grazing rays over the waves, vertical rays, rays aimed
    at vertices and at edge midpoints (ties), rays inside the slab, some with a short tmax."""
    rng = np.random.default_rng(seed)
    lo, hi = v.min(0), v.max(0)
    k = n_random
    o = np.stack([rng.uniform(lo[0] - 0.3, hi[0] + 0.3, k), rng.uniform(-0.4, 0.6, k),
                  rng.uniform(lo[2] - 0.3, hi[2] + 0.3, k)], -1)
    d = rng.normal(size=(k, 3))
    g = k // 3   # grazing: just above the waves, nearly level, any azimuth
    o[:g, 1] = rng.uniform(0.03, 0.05, g)
    d[:g, 1] = rng.uniform(-0.03, 0.01, g)
    s = k // 10  # in the slab, along the grid's axes and diagonals
    az = rng.integers(0, 8, s) * np.pi / 4
    o[g:g + s, 1] = rng.uniform(-0.02, 0.02, s)
    d[g:g + s] = np.stack([np.cos(az), rng.uniform(-0.05, 0.05, s), np.sin(az)], -1)
    targets = np.concatenate([v[rng.integers(0, len(v), 200)],
                              0.5 * (v[rng.integers(0, len(v) - 1, 200)]
                                     + v[rng.integers(0, len(v) - 1, 200) + 1])])
    starts = targets + np.stack([rng.uniform(-0.5, 0.5, 400), rng.uniform(0.2, 1.0, 400),
                                 rng.uniform(-0.5, 0.5, 400)], -1)
    vert = np.concatenate([v[rng.integers(0, len(v), 100)] + [0, 1, 0],
                           [[0.013, 0.5, -0.41], [0.2, -0.5, 0.3]]])
    up = np.concatenate([v[rng.integers(0, len(v), 100)] - [0, 0.3, 0]])
    o = np.concatenate([o, starts, vert, up])
    d = np.concatenate([d, targets - starts, np.tile([0.0, -1.0, 0.0], (len(vert) - 1, 1)),
                        [[0.0, 1.0, 0.0]],
                        rng.normal(size=(len(up), 3)) * [1, 0, 1] + [0, 1.5, 0]])
    tmax = np.where(rng.random(len(o)) < 0.25, rng.uniform(0.05, 2.0, len(o)), np.inf)
    return o, d, tmax


def assert_identical(walk, bvh):
    """The same hit bit for bit except at a tie, a shared vertex or edge hit at one distance
    (rays aimed at vertices make nearly all of them): there the walk keeps the smallest prim of
    the triangles hit, at a distance no larger than the BVH's by rounding, while the BVH walk,
    whose box test can drop a box entered at exactly the hit's distance or touched at a corner,
    may keep another one."""
    assert np.array_equal(walk["inst"], bvh["inst"])
    same = walk["prim"] == bvh["prim"]
    for field in ("t", "u", "v"):
        assert np.array_equal(walk[field][same], bvh[field][same]), field
    tie = ~same
    assert np.mean(tie) < 0.01
    assert np.all((walk["prim"][tie] < bvh["prim"][tie]) | (walk["t"][tie] < bvh["t"][tie]))
    assert np.all(walk["t"][tie] <= bvh["t"][tie])
    assert np.allclose(walk["t"][tie], bvh["t"][tie], rtol=1e-6, atol=0)


@pytest.mark.parametrize("shape", ["square", "stretched", "far"])
def test_walk_gives_the_bvh_hits_bit_for_bit(binary_rt, shape):
    n = 41 if shape != "stretched" else 33
    skew, offset = {"square": ((1, 1), (0, 0)), "stretched": ((1.7, 0.6), (0, 0)),
                    "far": ((1, 1), (40.0, -25.0))}[shape]
    v, tri = grid(n, 0.3, skew, offset)
    hf, bvh = scenes(binary_rt, v, tri, n)
    o, d, tmax = ray_set(v)
    a, b = trace(hf, o, d, tmax, False), trace(bvh, o, d, tmax, False)
    assert_identical(a, b)
    assert 0.3 < np.mean(a["inst"] == 0) < 0.9   # the grid is hit often, and missed
    for any_hit in (True,):
        x = trace(hf, o, d, tmax, False, any_hit=any_hit)
        y = trace(bvh, o, d, tmax, False, any_hit=any_hit)
        assert np.array_equal(x["prim"] >= 0, y["prim"] >= 0)
        assert np.array_equal(x["prim"] >= 0, a["prim"] >= 0)


def test_walk_under_an_instance_transform(binary_rt):
    n = 33
    v, tri = grid(n, 1.1)
    m = np.eye(4)
    m[:3, :3] = [[0.0, 0.0, 1.2], [0.0, 0.8, 0.0], [-1.2, 0.0, 0.0]]  # a turn about y, scaled
    m[:3, 3] = (0.2, 0.1, -0.3)
    hf, bvh = scenes(binary_rt, v, tri, n, m)
    o, d, tmax = ray_set(v, seed=8)
    assert_identical(trace(hf, o, d, tmax, False), trace(bvh, o, d, tmax, False))


def test_walk_matches_the_float64_reference(rt):
    """On the device's own layout (PoCL: wide) against brute force in float64."""
    n = 33
    v, tri = grid(n, 0.7)
    scene = Scene(rt)
    scene.add_instance(scene.add_mesh(v, tri, grid=(n, n)))
    scene.update()
    o, d, tmax = (a[:900] for a in ray_set(v, 900, seed=11))  # not those aimed at vertices
    got = trace(scene, o, d, tmax, False)
    ref = intersect_reference(v, tri, o, d, 0.0, tmax)
    assert 0.2 < np.mean(ref["prim"] >= 0) < 0.95
    assert_hits_match(as_result(got), ref, 1.0)


def test_cooperative_walk_enters_the_height_field(binary_rt):
    n = 41
    v, tri = grid(n, 2.0)
    hf, bvh = scenes(binary_rt, v, tri, n)
    o, d, tmax = ray_set(v, 900, seed=6)
    serial = trace(bvh, o, d, tmax, False)
    assert_identical(trace(hf, o, d, tmax, True), serial)
    anys = trace(hf, o, d, tmax, True, any_hit=True)
    assert np.array_equal(anys["prim"] >= 0, serial["prim"] >= 0)
    assert hf.coop_redos() == 0


def long_walks(v, n=600, seed=12):
    """Rays that cross the grid nearly level (past 32 spans of HF_BLOCK columns), from above
    and from inside the slab, any azimuth."""
    rng = np.random.default_rng(seed)
    lo, hi = v.min(0), v.max(0)
    az = rng.uniform(0, 2 * np.pi, n)
    c = 0.5 * (lo + hi)
    r = 0.505 * (hi[0] - lo[0])   # at the box's edge
    o = np.stack([c[0] - r * np.cos(az), rng.uniform(-0.02, 0.05, n),
                  c[2] - r * np.sin(az)], -1)
    d = np.stack([np.cos(az), rng.uniform(-0.02, 0.004, n), np.sin(az)], -1)
    return o, d, np.full(n, np.inf)


def test_long_walks_alone_and_cooperative(binary_rt):
    """A 321 x 321 grid (40 blocks a side), rays that walk most of it: the serial walk gives the
    BVH's hits, the cooperative walk the serial walk's, through the TLAS and of the grid alone
    (`only`: a shadow ray's crossings)."""
    n = 321
    v, tri = grid(n, 0.7)
    hf, bvh = scenes(binary_rt, v, tri, n)
    o, d, tmax = long_walks(v)
    ro, rd, rt_ = ray_set(v, 600, seed=13)
    o, d, tmax = np.concatenate([o, ro]), np.concatenate([d, rd]), np.concatenate([tmax, rt_])
    serial = trace(hf, o, d, tmax, False)
    assert_identical(serial, trace(bvh, o, d, tmax, False))
    far = np.abs(np.where(serial["prim"][:600] >= 0, serial["t"][:600], 0) * d[:600, 0]) \
        + np.abs(np.where(serial["prim"][:600] >= 0, serial["t"][:600], 0) * d[:600, 2])
    cell = (v[:, 0].max() - v[:, 0].min()) / (n - 1)
    # hits past 32 spans, and misses after every span
    assert (far > 33 * HF_BLOCK * cell).mean() > 0.02
    assert (serial["prim"][:600] < 0).mean() > 0.05
    coop = trace(hf, o, d, tmax, True)
    for field in ("t", "u", "v", "prim", "inst"):
        assert np.array_equal(coop[field], serial[field]), field
    alone = [trace(hf, o, d, tmax, c, only=0) for c in (False, True)]
    for field in ("t", "u", "v", "prim", "inst"):
        assert np.array_equal(alone[0][field], alone[1][field]), field
    grid_hits = serial["inst"] == 0
    assert np.array_equal(alone[1]["t"][grid_hits], serial["t"][grid_hits])
    for c in (False, True):
        anys = trace(hf, o, d, tmax, c, any_hit=True, only=0)
        assert np.array_equal(anys["prim"] >= 0, alone[0]["prim"] >= 0)
    anys = trace(hf, o, d, tmax, True, any_hit=True)
    assert np.array_equal(anys["prim"] >= 0, serial["prim"] >= 0)
    assert hf.coop_redos() == 0


def test_moved_vertices_are_seen_after_update(binary_rt):
    """A dynamic grid: new heights written to its buffer, update(), the hits of a fresh BVH."""
    n = 33
    v0, tri = grid(n, 0.0)
    v1, _ = grid(n, 2.5)
    v1[:, 1] *= 3.0
    rt = binary_rt
    vbuf = rt.to_device(np.c_[v0, np.zeros(len(v0))].astype(np.float32))
    tbuf = rt.to_device(tri.astype(np.uint32))
    scene = Scene(rt)
    scene.add_instance(scene.add_mesh(vbuf, tbuf, dynamic=True, n_vertices=len(v0),
                                      n_triangles=len(tri), grid=(n, n)))
    scene.update()
    import pyopencl as cl
    cl.enqueue_copy(rt.queue, vbuf, np.c_[v1, np.zeros(len(v1))].astype(np.float32))
    scene.update()
    fresh = Scene(rt)
    fresh.add_instance(fresh.add_mesh(v1, tri))
    fresh.update()
    o, d, tmax = ray_set(v1, 900, seed=2)
    assert_identical(trace(scene, o, d, tmax, False), trace(fresh, o, d, tmax, False))


def test_bounds_pass_equals_numpy(rt):
    n, m = 29, 20   # blocks that do not divide the cells
    x = np.linspace(-1.0, 1.5, n, dtype=np.float32)
    z = np.linspace(0.5, 1.9, m, dtype=np.float32)
    X, Z = np.meshgrid(x, z)
    rng = np.random.default_rng(0)
    Y = rng.normal(size=X.shape).astype(np.float32) * 0.1
    v = np.stack([X, Y, Z], -1).reshape(-1, 3)
    i = np.arange(n * m).reshape(m, n)
    a, b, c, d = i[:-1, :-1], i[:-1, 1:], i[1:, :-1], i[1:, 1:]
    tri = np.stack([np.stack([a, c, b], -1), np.stack([b, c, d], -1)], -2).reshape(-1, 3)
    scene = Scene(rt)
    mesh = scene.add_mesh(v, tri, grid=(n, m))
    scene.add_instance(mesh)
    for _ in range(2):   # the pass leaves its scratch ready for the next
        scene.update()
        rec = scene.heightfield.read()
        assert rec["mesh"] == mesh and rec["n_bad"] == 0 and rec["ticket"] == 0
        assert np.array_equal(rec["lo"][:3], v.min(0)) and np.array_equal(rec["hi"][:3], v.max(0))
        assert rec["x0"] == x[0] and rec["z0"] == z[0]
        blocks = scene.heightfield.read_blocks()
        nbx, nby = grid_blocks(n, m)
        assert blocks.shape == (nby, nbx, 4)
        grid_v = v.reshape(m, n, 3)
        for bj in range(nby):
            for bi in range(nbx):
                rows = slice(bj * HF_BLOCK, bj * HF_BLOCK + HF_BLOCK + 1)
                cols = slice(bi * HF_BLOCK, bi * HF_BLOCK + HF_BLOCK + 1)
                ys = Y[rows, cols]
                assert blocks[bj, bi, 0] == ys.min() and blocks[bj, bi, 1] == ys.max()
                assert blocks[bj, bi, 2] == pytest.approx(
                    slope_bound(grid_v[rows, cols], *grid_spacing(v, n, m)), rel=1e-5)
                assert blocks[bj, bi, 3] == 0
        assert rec["slope"] == pytest.approx(
            slope_bound(v.reshape(m, n, 3), *grid_spacing(v, n, m)), rel=1e-5)
        assert steepest_slope(v, tri) <= rec["slope"] <= 1.5 * steepest_slope(v, tri)
        assert rec["acc_rise_x"] == rec["acc_rise_z"] == np.iinfo(np.int32).min
    assert scene.check() == {"overflows": 0, "bad_triangles": 0}


def steepest_slope(v, tri) -> float:
    """float64: the largest |grad y| over x and z of the triangles."""
    p = v.astype(np.float64)[tri]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return float(np.max(np.hypot(n[:, 0], n[:, 2]) / np.abs(n[:, 1])))


def grid_spacing(v, nx, ny) -> tuple[float, float]:
    """float64 dx, dz of an nx x ny grid, from its corners (as the bounds pass takes them)."""
    g = v.astype(np.float64).reshape(ny, nx, 3)
    return (g[0, -1, 0] - g[0, 0, 0]) / (nx - 1), (g[-1, 0, 2] - g[0, 0, 2]) / (ny - 1)


def slope_bound(patch, dx, dz) -> float:
    """float64: the bounds pass's slope bound over a (rows, cols, 3) patch of grid vertices
    (the whole grid: HeightField.slope; a block's: its blocks[...].z), the margin times the
    hypotenuse of the largest height steps along x and along z over the spacings."""
    y = patch[..., 1].astype(np.float64)
    sx = np.abs(np.diff(y, axis=1)).max(initial=0.0) / abs(dx)
    sz = np.abs(np.diff(y, axis=0)).max(initial=0.0) / abs(dz)
    return HF_SLOPE_MARGIN * float(np.hypot(sx, sz))


@pytest.mark.parametrize("fault", ["nan", "off_grid"])
def test_bad_vertices_are_reported(rt, fault):
    n = 17
    v, tri = grid(n)
    v = v.copy()
    if fault == "nan":
        v[40, 1] = np.nan
    else:
        v[40, 0] += 0.3 * (v[1, 0] - v[0, 0])
    scene = Scene(rt)   # device buffers, as a writer fills them (NumPy input is checked)
    vbuf = rt.to_device(np.c_[v, np.zeros(len(v))].astype(np.float32))
    scene.add_instance(scene.add_mesh(vbuf, rt.to_device(tri.astype(np.uint32)), dynamic=True,
                                      n_vertices=len(v), n_triangles=len(tri), grid=(n, n)))
    scene.update()
    rec = scene.heightfield.read()
    assert rec["n_bad"] == 1
    # a NaN height leaves no ray known to climb over the grid (a vertex off the grid leaves
    # the bound as it is: the check above refuses the grid)
    if fault == "nan":
        assert rec["slope"] == np.inf
    else:
        assert rec["slope"] == pytest.approx(
            slope_bound(v.reshape(n, n, 3), *grid_spacing(v, n, n)), rel=1e-5)
    with pytest.raises(ValueError, match="1 grid vertices are NaN, infinite or off"):
        scene.check()


def test_grid_errors_are_one_line(rt):
    v, tri = grid(9)
    scene = Scene(rt)
    with pytest.raises(ValueError, match="a 9x8 grid has 112 triangles, got 128"):
        scene.add_mesh(v, tri, grid=(9, 8))
    bad = tri.copy()
    bad[[6, 7]] = bad[[7, 6]]
    with pytest.raises(ValueError, match="triangles 6 and 7 are"):
        scene.add_mesh(v, bad, grid=(9, 9))
    with pytest.raises(ValueError, match="grid nx=1 must be an integer >= 2"):
        scene.add_mesh(v, tri, grid=(1, 81))
    mesh = scene.add_mesh(v, tri, grid=(9, 9))
    with pytest.raises(ValueError, match="one height field per scene"):
        scene.add_mesh(v, tri, grid=(9, 9))
    with pytest.raises(ValueError, match="is a height field"):
        scene.blas(mesh)
    assert scene.heightfield.mesh == mesh
    fresh = Scene(rt)
    assert fresh.heightfield.read()["mesh"] == HF_NONE
