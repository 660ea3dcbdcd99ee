"""The light buffer (kernels/light_buffer.cl, raytrace/light_buffer.py): its cells list every
triangle whose shadow meets them and few more (a float64 NumPy raster of the same projection),
their depth bounds hold over the cell (float64 clipping), its answers are the BVH's any-hit
answers, and frames rendered with it are the frames rendered without it, byte for byte."""

import dataclasses
import types

import numpy as np
import pyopencl as cl
import pytest

from kernels.layout import check_struct
from raytrace.light_buffer import (
    LB_FINE,
    LB_FINE_SLOTS,
    LB_SLOTS,
    LIGHT_BUFFER,
    PAIRS_PER_GRID,
    LightBuffer,
)
from raytrace.render import Renderer, RenderSettings
from raytrace.render_scene import Material, RenderScene
from raytrace.render_types import MASK_OPAQUE
from tests.raytrace.test_render_dynamic import grid, surface
from tests.raytrace.test_render_plans import BOX, CAMERAS

SUN = (-0.45, -0.8, -0.35)


def test_layout_matches_the_device(rt):
    from kernels.runtime import KERNEL_DIR

    check_struct(rt, "light_buffer.h", "LightBuffer", LIGHT_BUFFER)
    assert LIGHT_BUFFER.itemsize == 96
    header = (KERNEL_DIR / "light_buffer.h").read_text()
    for name, value in (("LB_SLOTS", LB_SLOTS), ("LB_FINE", LB_FINE),
                        ("LB_FINE_SLOTS", LB_FINE_SLOTS)):
        assert f"#define {name} {value}\n" in header


def rotation(yaw: float, pitch: float) -> np.ndarray:
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    return ry @ rx


def clutter(rt, *, glass: bool = True, spot: bool = False, seed: int = 3,
            stacks: bool = False) -> RenderScene:
    """A floor, two boxes (one turned and scaled), 60 small random triangles above the floor,
    a glass box (a dielectric: the opaque instances alone are mapped) and the sun; with
    ``stacks``, two stacks of 24 and 48 small triangles along the light (as a boat's rigging's
    stack), whose fine cells list more than a cell's room."""
    rng = np.random.default_rng(seed)
    sc = RenderScene(rt)
    floor = sc.add_material(Material(diffuse=(0.8, 0.7, 0.5)))
    red = sc.add_material(Material(diffuse=(0.7, 0.2, 0.1), specular=(0.4, 0.4, 0.4),
                                   shininess=30, reflectivity=0.2))
    quad = np.array([[-1.5, 0, -1.5], [1.5, 0, -1.5], [1.5, 0, 1.5], [-1.5, 0, 1.5]])
    sc.add_instance(sc.add_mesh(quad, [[0, 2, 1], [0, 3, 2]], material=floor))
    box = sc.add_mesh(*BOX, material=red)
    sc.add_instance(box, np.array([[1, 0, 0, 0.7], [0, 1, 0, 0], [0, 0, 1, -0.4], [0, 0, 0, 1]]))
    m = np.eye(4)
    m[:3, :3] = 0.6 * rotation(0.7, 0.3)
    m[:3, 3] = (-0.6, 0.35, 0.5)
    sc.add_instance(box, m)
    centres = rng.uniform((-1.2, 0.3, -1.2), (1.2, 1.2, 1.2), (60, 1, 3))
    tris = (centres + rng.normal(0, 0.08, (60, 3, 3))).reshape(-1, 3)
    sc.add_instance(sc.add_mesh(tris, np.arange(180).reshape(60, 3), material=red))
    if stacks:
        toward = -np.asarray(SUN) / np.linalg.norm(SUN)
        tri = rng.normal(0, 0.03, (3, 3))
        parts = [c + k * 0.015 * toward + tri + rng.normal(0, 0.003, (3, 3))
                 for c, n in (((0.3, 0.05, 0.9), 24), ((-0.9, 0.05, -0.2), 48))
                 for k in range(n)]
        sc.add_instance(sc.add_mesh(np.concatenate(parts), np.arange(3 * len(parts)).reshape(-1, 3),
                                    material=red))
    if glass:
        g = sc.add_material(Material(diffuse=(0.1, 0.2, 0.3), ior=1.33, reflectivity=0.1))
        sc.add_instance(sc.add_mesh(*BOX, material=g),
                        np.array([[1, 0, 0, -0.2], [0, 1, 0, 0], [0, 0, 1, -0.9], [0, 0, 0, 1]]))
    sc.add_light("directional", direction=SUN, color=(1.2, 1.1, 1.0))
    if spot:
        sc.add_light("spot", position=(0.5, 2.5, 0.8), direction=(0, -1, 0), color=(3, 3, 3),
                     inner_angle=25, outer_angle=40)
    return sc


def built(rt, sc, cells: int, **kw) -> LightBuffer:
    sc.update()
    lb = LightBuffer(rt, cells, **kw)
    lb.plan(sc, MASK_OPAQUE if sc.has_dielectric else 0xFFFFFFFF)
    lb.enqueue(sc.transform_buffer)
    return lb


# -- the float64 reference ------------------------------------------------------------------
def world_triangles(sc, lb) -> tuple[np.ndarray, np.ndarray]:
    """The listed triangles in world space (n, 3, 3) float64 and their instances."""
    q = np.frombuffer(lb.rt.to_host(lb.tris_buf, np.float32, 4 * 3 * lb.n_tris).tobytes(),
                      np.float32).reshape(-1, 3, 4)
    inst = q[:, 0, 3].copy().view(np.int32)
    rows = sc.scene.read_transforms().astype(np.float64)[inst]
    p = q[:, :, :3].astype(np.float64)
    return np.einsum("nij,nkj->nki", rows[:, :, :3], p) + rows[:, None, :, 3], inst


def clip_max_depth(poly: np.ndarray, lo, hi) -> float:
    """Most depth (column 2) over the 2D polygon (columns 0-1) clipped to [lo, hi]; -inf when
    they do not meet (Sutherland-Hodgman, float64)."""
    for axis in (0, 1):
        for bound, keep in ((lo[axis], np.greater_equal), (hi[axis], np.less_equal)):
            out = []
            for k in range(len(poly)):
                a, b = poly[k], poly[(k + 1) % len(poly)]
                ina, inb = keep(a[axis], bound), keep(b[axis], bound)
                if ina:
                    out.append(a)
                if ina != inb:
                    t = (bound - a[axis]) / (b[axis] - a[axis])
                    out.append(a + t * (b - a))
            poly = np.array(out)
            if len(poly) == 0:
                return -np.inf
    return float(poly[:, 2].max())


def reference_cells(lb, light, world, grow: float):
    """Per cell: {triangle: most depth over the triangle and the cell grown by ``grow``}."""
    m = lb.maps[light]
    u, v, t = (m[k].astype(np.float64) for k in ("u", "v", "toward"))
    out: dict = {}
    for k, tri in enumerate(world):
        cu, cv, d = tri @ u[:3] + u[3], tri @ v[:3] + v[3], tri @ t[:3]
        poly = np.stack([cu, cv, d], 1)
        for j in range(max(0, int(np.floor(cv.min() - grow))),
                       min(int(m["n_v"]), int(np.floor(cv.max() + grow)) + 1)):
            for i in range(max(0, int(np.floor(cu.min() - grow))),
                           min(int(m["n_u"]), int(np.floor(cu.max() + grow)) + 1)):
                depth = clip_max_depth(poly, (i - grow, j - grow), (i + 1 + grow, j + 1 + grow))
                if depth > -np.inf:
                    out.setdefault((j, i), {})[k] = depth
    return out


def tris_of(cells, j, i) -> int:
    return next(iter(cells[(j, i)]))


def covers(lb, tri, j, i, grow: float) -> bool:
    """Whether the triangle's footprint holds cell (j, i) grown by ``grow`` (float64)."""
    m = lb.maps[0]
    u, v = m["u"].astype(np.float64), m["v"].astype(np.float64)
    p = np.stack([tri @ u[:3] + u[3], tri @ v[:3] + v[3]], 1)
    corners = np.array([[i - grow, j - grow], [i + 1 + grow, j - grow],
                        [i - grow, j + 1 + grow], [i + 1 + grow, j + 1 + grow]])
    side = np.array([(p[(k + 1) % 3] - p[k])[0] * (corners - p[k])[:, 1]
                     - (p[(k + 1) % 3] - p[k])[1] * (corners - p[k])[:, 0] for k in range(3)])
    return bool((np.all(side >= 0, 0) | np.all(side <= 0, 0)).all())


def test_cells_list_what_a_float64_raster_finds(rt):
    sc = clutter(rt)
    lb = built(rt, sc, 40)
    assert lb.active and lb.reason == "" and lb.n_tris == 2 + 12 + 12 + 60
    world, inst = world_triangles(sc, lb)
    assert set(inst) == {0, 1, 2, 3}   # the glass box is crossed, not mapped
    got = lb.read(0)
    assert got["outside"] == 0 and got["big"] >= 2   # the floor's two halves by work-groups
    must, may = reference_cells(lb, 0, world, 0.0), reference_cells(lb, 0, world, 0.25)
    count, depth, slots = got["count"], got["depth"], got["slots"]
    assert (count > 0).sum() >= len(must) > 0.3 * count.size
    toward = lb.maps[0]["toward"][:3].astype(np.float64)
    nearest = (world @ toward).max(1)   # each triangle's nearest vertex to the light
    planar = 0
    for (j, i), tris in must.items():
        n = count[j, i]
        assert n >= len(tris), (j, i)
        assert n <= len(may[(j, i)]), (j, i)   # none beyond a quarter cell
        if n <= LB_SLOTS:
            assert set(tris) <= set(slots[j, i, :n].tolist()), (j, i)
        # the bound holds over the cell, and is no looser than the nearest vertex
        assert depth[j, i] >= max(tris.values()), (j, i)
        assert depth[j, i] <= nearest[list(may[(j, i)])].max() + 1e-3, (j, i)
        if len(may[(j, i)]) == 1 and covers(lb, world[tris_of(may, j, i)], j, i, 0.25):
            # one triangle over the whole cell (the floor): its plane's bound
            assert depth[j, i] <= max(may[(j, i)].values()) + 1e-3, (j, i)
            planar += 1
    assert planar > 0.2 * len(must)
    listed = {(j, i) for j, i in zip(*np.nonzero(count), strict=True)}
    assert listed <= set(may)
    assert (count <= LB_SLOTS).mean() > 0.9
    coarse = built(rt, sc, 6).read(0)["count"]   # cells of more than LB_SLOTS there
    assert (coarse > LB_SLOTS).any()


@pytest.mark.parametrize("stacks", [False, True])
def test_fine_cells_list_what_a_float64_raster_finds(rt, stacks):
    """A coarse map's full cells (3 of 9 or more) each get a fine grid whose cells list every
    triangle that meets them (the float64 raster of the map LB_FINE times finer) and none beyond
    a quarter cell; a cell that is not full has none. With the stacks, fine cells list more than
    a cell's 16 slots, and some more than their own 32."""
    sc = clutter(rt, stacks=stacks)
    lb = built(rt, sc, 3)
    got = lb.read(0)
    fc = got["fine_count"]
    past_a_cell = ((fc > LB_SLOTS) & (fc <= LB_FINE_SLOTS)).any()
    assert (past_a_cell and (fc > LB_FINE_SLOTS).any()) == stacks
    full = got["count"] > LB_SLOTS
    assert 0 < full.sum() == got["fine_grids"] <= lb.maps[0]["fine_grids"]
    assert (got["grid"][~full] == -1).all()
    grids = got["grid"][full]
    assert sorted(grids.tolist()) == list(range(full.sum()))   # one each, none twice
    fine_map = types.SimpleNamespace(maps=lb.maps.copy())
    for k in ("u", "v"):
        fine_map.maps[0][k] *= LB_FINE
    for k in ("n_u", "n_v"):
        fine_map.maps[0][k] *= LB_FINE
    world, _ = world_triangles(sc, lb)
    must = reference_cells(fine_map, 0, world, 0.0)
    may = reference_cells(fine_map, 0, world, 2.0)
    checked = 0
    for j, i in zip(*np.nonzero(full), strict=True):
        g = got["grid"][j, i]
        for b in range(LB_FINE):
            for a in range(LB_FINE):
                key = (j * LB_FINE + b, i * LB_FINE + a)
                tris, n = must.get(key, {}), got["fine_count"][g, b, a]
                assert len(tris) <= n <= len(may.get(key, {})), key
                if n <= LB_FINE_SLOTS:
                    assert set(tris) <= set(got["fine_slots"][g, b, a, :n].tolist()), key
                checked += len(tris)
    assert checked > 0
    assert (got["fine_count"] <= LB_FINE_SLOTS).mean() > 0.9   # what a fine cell is for


def answers(rt, sc, lb, light, org):
    k = rt.kernel_launcher("light_buffer.cl", "light_buffer_answers", stage="test",
                           defines=sc.scene.trace_defines)
    org4 = np.zeros((len(org), 4), np.float32)
    org4[:, :3] = org
    out = rt.buffer(8 * len(org))
    k.bind(**sc.scene.trace_bindings(), **lb.bindings(), light=light,
           mask=MASK_OPAQUE if sc.has_dielectric else 0xFFFFFFFF, org=rt.to_device(org4),
           n=len(org), out=out)
    k.launch(len(org), 64)
    return rt.to_host(out, np.int32, 2 * len(org)).reshape(-1, 2)


def brute_force_blocked(world, org, toward) -> np.ndarray:
    """float64 any-hit of rays org + t toward, t > 0, against every triangle (Moeller-Trumbore),
    and whether each ray passes within 1e-5 of a triangle's edge (too close to call)."""
    a, b, c = world[:, 0], world[:, 1], world[:, 2]
    e1, e2 = b - a, c - a
    p = np.cross(toward, e2)
    det = (e1 * p).sum(1)
    s = org[:, None, :] - a[None]
    inv = 1.0 / np.where(det == 0, np.inf, det)
    u = (s * p[None]).sum(2) * inv
    q = np.cross(s, e1[None])
    v = (q @ toward) * inv
    t = (q * e2[None]).sum(2) * inv
    hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-4)
    near = np.minimum(np.minimum(np.abs(u), np.abs(v)), np.abs(1 - u - v)) < 1e-5
    return hit.any(1), (near & (t > 0)).any(1)


@pytest.mark.parametrize("cells,stacks", [(40, False), (3, False), (3, True)])
def test_answers_are_the_bvh_any_hit(rt, cells, stacks):
    """At 3 cells a third of the map is full cells: their fine grids answer; with the stacks,
    through fine cells of up to 32 triangles too, and the fullest walk."""
    sc = clutter(rt, stacks=stacks)
    lb = built(rt, sc, cells)
    if cells == 3:
        assert (lb.read(0)["count"] > LB_SLOTS).mean() > 0.3
    rng = np.random.default_rng(7)
    world, _ = world_triangles(sc, lb)
    # points on the floor (offset up), on the triangles, and in the air
    n = 3000
    floor = np.c_[rng.uniform(-1.6, 1.6, n), np.full(n, 1e-3), rng.uniform(-1.6, 1.6, n)]
    pick = rng.integers(0, len(world), n)
    w = rng.dirichlet((1, 1, 1), n)
    on_tris = np.einsum("nk,nki->ni", w, world[pick]) - 2e-3 * np.asarray(SUN)
    air = rng.uniform((-2.5, 0, -2.5), (2.5, 1.5, 2.5), (n, 3))
    org = [floor, on_tris, air]
    if stacks:   # under the stacks, along the light
        toward = -np.asarray(SUN) / np.linalg.norm(SUN)
        org.append(np.einsum("nk,nki->ni", w, world[-72:][pick % 72])
                   - rng.uniform(0.05, 0.3, (n, 1)) * toward)
    org = np.concatenate(org).astype(np.float32)
    got = answers(rt, sc, lb, 0, org)
    known = got[:, 0] >= 0
    assert known.mean() > (0.7 if stacks else 0.9)
    if stacks:
        under = got[3 * n:, 0]
        assert (under == -1).mean() > 0.2 and (under >= 0).mean() > 0.2
    assert np.array_equal(got[known, 0], got[known, 1])   # the BVH's answer, bit for bit
    assert 0.1 < got[known, 1].mean() < 0.9               # both kinds of answer occur
    toward = -np.asarray(SUN, np.float64) / np.linalg.norm(SUN)
    blocked, near = brute_force_blocked(world, org.astype(np.float64), toward)
    sure = known & ~near
    assert sure.mean() > (0.65 if stacks else 0.85)
    assert np.array_equal(got[sure, 0] == 1, blocked[sure])


@pytest.mark.parametrize("grids,pairs", [(None, PAIRS_PER_GRID), (1, 1000), (None, 1)])
def test_counters_say_how_each_query_was_answered(rt, grids, pairs):
    """TRACE_COUNT builds count the map's answers by kind (Scene.trace_counts()
    ["light_buffer"]): they add up to the queries and agree with the answers given, with a
    float64 look-up of the origins' cells, and with the triangles the listed cells hold. The
    full cells' origins look in their fine grids (grids=1: one grid, the others' walk; pairs=1:
    the pairs that fill the grids overflow their list, so none is read)."""
    from kernels.runtime import Runtime

    counting = Runtime(rt.device, defines={"TRACE_COUNT": 1})
    sc = clutter(counting)
    lb = built(counting, sc, 6, fine_grids=grids, pairs_per_grid=pairs)   # full cells too
    rng = np.random.default_rng(5)
    n = 4000
    org = rng.uniform((-2.2, 0.0, -2.2), (2.2, 1.4, 2.2), (n, 3)).astype(np.float32)
    sc.scene.reset_trace_counts()
    got = answers(counting, sc, lb, 0, org)[:, 0]
    c = sc.scene.trace_counts()["light_buffer"]
    kinds = ("empty", "nearer", "tested_clear", "blocked", "full", "off_map")
    assert sum(c[k] for k in kinds) == n
    assert c["blocked"] == (got == 1).sum() > 0
    assert c["full"] == (got == -1).sum()   # nothing reaches off this map: full cells only
    assert c["empty"] + c["nearer"] + c["tested_clear"] + c["off_map"] == (got == 0).sum()
    assert min(c[k] for k in kinds if k != "full") > 0
    # float64: the origins' cells (a few on a cell's edge may round the other way)
    m, cells = lb.maps[0], lb.read(0)
    o = org.astype(np.float64)
    cu = o @ m["u"][:3].astype(np.float64) + m["u"][3]
    cv = o @ m["v"][:3].astype(np.float64) + m["v"][3]
    on = (cu >= 0) & (cu < m["n_u"]) & (cv >= 0) & (cv < m["n_v"])
    assert abs(c["off_map"] - (~on).sum()) <= 0.01 * n
    count = np.zeros(n, np.int64)
    count[on] = cells["count"][cv[on].astype(int), cu[on].astype(int)]
    assert abs(c["empty"] - (on & (count == 0)).sum()) <= 0.01 * n
    # the origins in full cells: those with a grid look in it; with none, or in a full fine
    # cell, they walk
    grid = np.full(n, -1)
    grid[on] = cells["grid"][cv[on].astype(int), cu[on].astype(int)]
    overflow = cells["fine_pairs"] > lb.maps[0]["fine_pairs"]
    assert overflow == (pairs == 1)
    if overflow:
        grid[:] = -1   # no grid is read
    full = on & (count > LB_SLOTS)
    assert full.sum() > 0.05 * n
    assert abs(c["fine"] - (full & (grid >= 0)).sum()) <= 0.01 * n
    fu = np.minimum(((cu - np.floor(cu)) * LB_FINE).astype(int), LB_FINE - 1)
    fv = np.minimum(((cv - np.floor(cv)) * LB_FINE).astype(int), LB_FINE - 1)
    fine = np.zeros(n, np.int64)
    in_grid = full & (grid >= 0)
    fine[in_grid] = cells["fine_count"][grid[in_grid], fv[in_grid], fu[in_grid]]
    left = full & ((grid < 0) | (fine > LB_FINE_SLOTS))
    assert abs(c["full"] - left.sum()) <= 0.01 * n
    if overflow:
        assert c["fine"] == 0 and c["full"] > 0.02 * n
    elif grids is None:   # room for every full cell: the fine cells answer most
        assert cells["fine_grids"] == (cells["count"] > LB_SLOTS).sum() <= lb.maps[0]["fine_grids"]
        assert c["full"] < 0.1 * c["fine"]
    else:
        assert cells["fine_grids"] > 1 and (cells["grid"] >= 0).sum() == 1
        assert c["full"] > 0
    # a cell tested clear tests all its triangles, a blocked one at least one
    listed = np.where(full, fine, count)
    room = np.where(full, LB_FINE_SLOTS, LB_SLOTS)
    tested = listed[on & (listed > 0) & (listed <= room)]
    assert (c["tested_clear"] + c["blocked"] <= c["triangles"]
            <= tested.sum() + 0.01 * n * LB_FINE_SLOTS)


def test_rays_off_the_map_walk_the_bvh_once_a_triangle_leaves_it(rt):
    sc = clutter(rt, glass=False)
    lb = built(rt, sc, 32)
    far = np.array([[40.0, 0.5, 40.0], [-40.0, 0.2, 10.0]], np.float32)
    assert answers(rt, sc, lb, 0, far)[:, 0].tolist() == [0, 0]   # nothing out there
    sc.set_transform(3, np.array([[1, 0, 0, 30.0], [0, 1, 0, 0], [0, 0, 1, 30.0],
                                  [0, 0, 0, 1]]))
    sc.update()
    lb.enqueue(sc.transform_buffer)   # the live rows: the moved instance is followed
    assert lb.read(0)["outside"] > 0
    got = answers(rt, sc, lb, 0, far)
    assert got[:, 0].tolist() == [-1, -1]


# -- frames with and without it ----------------------------------------------------------
def frames_alike(rt, sc, settings, camera=CAMERAS[1], moves=(), cells=48):
    """The frames of ``sc`` with a map of ``cells`` and without one, the instances moved
    between them."""
    start = sc.scene.read_host_transforms()
    out = []
    for n in (0, cells):
        r = Renderer(rt, sc, dataclasses.replace(settings, light_buffer=n))
        r.set_camera(*camera, (0, 1, 0), 50)
        imgs = [r.render()]
        for inst, m in moves:
            sc.set_transform(inst, m)
            imgs.append(r.render())
        for inst, _ in moves:   # back where they started for the next renderer
            sc.set_transform(inst, np.vstack([start[inst], [0, 0, 0, 1]]))
        out.append((imgs, r))
    (off, _), (on, r_on) = out
    for a, b in zip(off, on, strict=True):
        assert np.array_equal(a, b)
        assert a[..., :3].std() > 5
    return r_on


@pytest.mark.parametrize("chunk,coop_from,bins,cells", [
    (None, None, False, 48), (96, None, False, 48), (None, 1, True, 48), (None, None, False, 3),
    (None, 1, True, 3)])
def test_frames_are_the_frames_without_it(rt, chunk, coop_from, bins, cells):
    """Every shadow kernel: alone, with the next level's trace, binned, cooperative; at 3
    cells, through the full cells' fine grids."""
    s = RenderSettings(width=24, height=18, bounces=3, spp=4, max_chunk_rays=chunk,
                       coop_from=coop_from, cost_bins=bins, overlap_from=0)
    r = frames_alike(rt, clutter(rt), s, cells=cells)
    got = r.light_buffer.read(0)
    assert r.light_buffer.active and got["count"].sum() > 0
    assert (cells == 3) == (got["fine_grids"] > 0)


@pytest.mark.parametrize("cells", [48, 3])
def test_frames_follow_a_moved_instance(rt, cells):
    """At 3 cells each build hands the full cells their fine grids again, emptied."""
    s = RenderSettings(width=24, height=18, bounces=2)
    m = np.array([[0, 0, 1, -0.3], [0, 1, 0, 0.1], [-1, 0, 0, 0.2], [0, 0, 0, 1]])
    frames_alike(rt, clutter(rt, glass=False), s, moves=[(1, m)], cells=cells)


def test_spot_lights_walk_the_bvh_and_directional_ones_use_their_map(rt):
    s = RenderSettings(width=24, height=18, bounces=2)
    r = frames_alike(rt, clutter(rt, spot=True), s)
    assert r.light_buffer.maps["n_u"][:2].tolist()[1] == 0 and r.light_buffer.maps["n_u"][0] > 0
    with pytest.raises(ValueError, match="light 1 has no map"):
        r.light_buffer.read(1)


def test_a_device_written_mesh_leaves_every_light_without_a_map(rt):
    sc = clutter(rt, glass=False)
    v, _ = surface(6, 0.7)
    mesh, vbuf, _ = sc.add_dynamic_mesh(len(v), grid(6))
    cl.enqueue_copy(rt.queue, vbuf, v)
    sc.add_instance(mesh)
    r = frames_alike(rt, sc, RenderSettings(width=20, height=14, bounces=1))
    assert not r.light_buffer.active and "device writes" in r.light_buffer.reason


def test_settings_reject_a_size_out_of_range():
    with pytest.raises(ValueError, match=r"light_buffer must be an integer in \[0, 8192\]"):
        RenderSettings(light_buffer=-1).resolved()
    with pytest.raises(ValueError, match="light_buffer must be"):
        RenderSettings(light_buffer=1.5).resolved()


def test_a_floating_boat_moved_on_the_device_is_followed(rt):
    """scenes/pool.toml: the boat's transform row is written by the bodies stage (no host copy);
    the frames with the map are the frames without it while it moves."""
    from app.errors import InputError
    from app.world import World

    frames, poses = {}, {}
    for cells in (0, 64):
        w = World("scenes/pool.toml", rt, width=64, height=36, cells=40, light_buffer=cells)
        builds = w.renderer.light_buffer.builds
        frames[cells] = [w.frame(1 / 30)]
        first = w.boat_poses()[0]
        frames[cells] += [w.frame(1 / 30) for _ in range(2)]
        poses[cells] = w.boat_poses()[0]
        assert not np.array_equal(first, poses[cells])   # the boat moved meanwhile
        if cells:
            assert w.renderer.light_buffer.active
            assert w.renderer.light_buffer.read(0)["count"].max() > 0
            assert w.renderer.light_buffer.builds == builds + 3   # every frame: it moves
    for a, b in zip(frames[0], frames[64], strict=True):
        assert np.array_equal(a, b)
    assert np.array_equal(poses[0], poses[64])
    assert not np.array_equal(frames[64][0], frames[64][2])   # the water and boat moved
    with pytest.raises(InputError, match=r"light_buffer -1 out of range; allowed None or an "
                                         r"integer in \[0, 8192\]"):
        World("scenes/pool.toml", rt, light_buffer=-1)


def test_a_still_scene_builds_its_map_once(rt):
    """Built again only when the rows were written: by the host (set_transform) here."""
    from app.world import World

    w = World("bench/scenes/pool_static_boat.toml", rt, width=48, height=27, cells=32,
              light_buffer=64)
    lb = w.renderer.light_buffer
    first = [w.frame(1 / 30) for _ in range(3)]
    assert lb.builds == 1
    boat = next(i for i, name in w.instances.items() if "sailboat" in name)
    rows = w.render_scene.scene.read_host_transforms()[boat]
    rows[:, 3] += (0.3, 0.0, -0.2)
    w.render_scene.set_transform(boat, np.vstack([rows, [0, 0, 0, 1]]))
    moved = w.frame(1 / 30)
    assert lb.builds == 2
    ref = World("bench/scenes/pool_static_boat.toml", rt, width=48, height=27, cells=32,
                light_buffer=0)
    want = [ref.frame(1 / 30) for _ in range(3)]
    ref.render_scene.set_transform(boat, np.vstack([rows, [0, 0, 0, 1]]))
    assert all(np.array_equal(a, b) for a, b in zip(first, want, strict=True))
    assert np.array_equal(moved, ref.frame(1 / 30))
