"""The wavefront renderer against independent references: the float64 NumPy pipeline, Snell and
the Fresnel equations in float64, raytrace.intersect for primary hits, analytic lighting."""

import numpy as np
import pyopencl as cl
import pytest

from raytrace import render_reference as ref
from raytrace.render import Renderer, RenderSettings, jitter_cols
from raytrace.render_scene import Material, RenderScene
from raytrace.render_types import RAY

IOR = 1.333


def box(lo, hi):
    """Closed box, outward winding."""
    V = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                  for z in (lo[2], hi[2])], np.float32)
    F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return V, F


def quad(center, size, up=True):
    cx, cy, cz = center
    h = size / 2
    V = np.array([[cx - h, cy, cz - h], [cx + h, cy, cz - h], [cx + h, cy, cz + h],
                  [cx - h, cy, cz + h]], np.float32)
    F = np.array([[0, 2, 1], [0, 3, 2]]) if up else np.array([[0, 1, 2], [0, 2, 3]])
    return V, F


def tiny_scene(rt):
    """Floor (textured), a half mirror, a glass box with absorption; a sun and a spot."""
    sc = RenderScene(rt)
    checker = np.kron(np.indices((4, 4)).sum(axis=0) % 2, np.ones((1, 1)))[..., None] \
        * np.array([0.7, 0.6, 0.5]) + 0.2
    tex = sc.add_texture(checker)
    floor = sc.add_material(Material(diffuse=(0.9, 0.8, 0.7), specular=(0.2, 0.2, 0.2),
                                     shininess=20, texture=tex, uv_scale=(2.0, 2.0)))
    mirror = sc.add_material(Material(diffuse=(0.2, 0.2, 0.8), reflectivity=0.5))
    glass = sc.add_material(Material(diffuse=(0, 0, 0), specular=(1, 1, 1), shininess=200,
                                     ior=IOR, absorption=(0.5, 0.2, 0.1)))
    V, F = quad((0, 0, 0), 4)
    uv = (V[:, [0, 2]] + 2) / 4
    sc.add_instance(sc.add_mesh(V, F, uvs=uv, material=floor))
    Vm = np.array([[-1, 0, -1], [1, 0, -1], [1, 1.5, -1.3], [-1, 1.5, -1.3]], np.float32)
    sc.add_instance(sc.add_mesh(Vm, np.array([[0, 1, 2], [0, 2, 3]]), material=mirror))
    Vb, Fb = box((-0.5, 0.2, 0.0), (0.5, 0.6, 0.8))
    rot = np.eye(4)
    c, s = np.cos(0.3), np.sin(0.3)
    rot[[0, 0, 2, 2], [0, 2, 0, 2]] = c, s, -s, c
    cz, sz = np.cos(0.25), np.sin(0.25)
    tilt = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    # non-uniform scale of a tilted box: its normals need the inverse transpose
    rot[:3, :3] = rot[:3, :3] @ np.diag([1.3, 0.7, 1.0]) @ tilt
    rot[:3, 3] = (0.1, 0.05, 0.0)
    sc.add_instance(sc.add_mesh(Vb, Fb, material=glass), rot)
    sc.add_light("directional", direction=(-0.3, -1, -0.2), color=(1, 1, 1))
    sc.add_light("spot", position=(1, 2, 1), direction=(-0.4, -1, -0.4), color=(2, 2, 2),
                 inner_angle=20, outer_angle=35)
    return sc


def compare_with_reference(rt, settings, eye=(0.5, 1.5, 3.0), target=(0, 0.3, 0)):
    sc = tiny_scene(rt)
    r = Renderer(rt, sc, settings)
    r.set_camera(eye, target, (0, 1, 0), 50)
    img = r.render()
    fb = r.read_framebuffer()
    stats = r.read_stats()
    out = ref.render(sc.tables(), r.camera, r.params(), sc.lights)
    ok = ~out["fragile"]
    assert ok.mean() > 0.95
    err = np.abs(fb - out["framebuffer"]).max(axis=2)
    scale = np.maximum(1.0, out["framebuffer"].max(axis=2))
    assert np.all(err[ok] <= 2e-4 * scale[ok]), f"max error {err[ok].max()}"
    diff8 = np.abs(img.astype(int) - out["rgba"].astype(int))
    assert diff8[ok].max() <= 1
    assert np.isfinite(fb).all()
    return stats


@pytest.mark.parametrize("fused", [False, True], ids=["trace+shade", "trace_shade"])
def test_matches_float64_pipeline_with_reflection_and_refraction(rt, fused):
    s = RenderSettings(width=24, height=20, spp=1, bounces=3, fuse_trace_shade=fused)
    stats = compare_with_reference(rt, s)
    # reflective and refractive bounces happened: children at depths 1..3
    assert stats["rays_per_depth"][1] > 50 and stats["rays_per_depth"][3] > 0
    assert stats["dropped"] == 0


def test_matches_float64_pipeline_jittered_rows_schlick_tiled_chunks(rt):
    s = RenderSettings(width=20, height=12, spp=2, bounces=2, order="rows", fresnel="schlick",
                       tonemap="reinhard", exposure=1.5, seed=7, max_chunk_rays=96)
    r = Renderer(rt, tiny_scene(rt), s)
    assert len(r.chunks) > 1
    compare_with_reference(rt, s)


def test_jitter_grid_covers_spp():
    for spp in (1, 2, 3, 4, 6, 8, 16, 64):
        c = jitter_cols(spp)
        assert spp % c == 0 and c * c <= spp


def flat_water(rt, y=0.0, center=(0.0, 0.0)):
    sc = RenderScene(rt)
    water = sc.add_material(Material(diffuse=(0, 0, 0), ior=IOR))
    V, F = quad((center[0], y, center[1]), 400.0)
    sc.add_instance(sc.add_mesh(V, F, material=water))
    return sc


@pytest.mark.parametrize("from_below", [False, True])
def test_flat_water_snell_fresnel_tir(rt, from_below):
    """Children of camera rays at a flat water plane far from the origin: Snell directions,
    Fresnel weights in float64, total reflection past the critical angle from below, and no
    child ever hits the plane it left."""
    cx, cz, y = 300.0, -200.0, 50.0
    sc = flat_water(rt, y, (cx, cz))
    s = RenderSettings(width=32, height=32, spp=1, bounces=1, min_weight=0.0)
    r = Renderer(rt, sc, s)
    eye = (cx, y - 1.0 if from_below else y + 1.0, cz)
    r.set_camera(eye, (cx + 0.01, y, cz), (1, 0, 0), 120)
    r.enqueue_frame()
    counts = rt.to_host(r.counts, np.uint32, 3)
    prim = rt.to_host(r.rays[0], RAY, int(counts[0]))
    kids = rt.to_host(r.rays[1], RAY, int(counts[1]))
    hit = np.dtype([("t", "f4"), ("u", "f4"), ("v", "f4"), ("prim", "i4"), ("inst", "i4")])
    hits = rt.to_host(r.hits[1], hit, int(counts[1]))   # level 1's hits (odd parity)
    assert (hits["prim"] == -1).all(), "a child ray hit the plane it left"
    by_pixel = {int(p["pixel"]): p for p in prim}
    n = np.array([0.0, 1.0, 0.0])
    eta = IOR if from_below else 1 / IOR
    n_tir = n_two = 0
    for pix in np.unique(kids["pixel"]):
        p = by_pixel[int(pix)]
        d = np.array([p["dx"], p["dy"], p["dz"]], np.float64)
        d /= np.linalg.norm(d)
        cosi = abs(d[1])
        mine = kids[kids["pixel"] == pix]
        F = float(ref.fresnel_exact(cosi, eta))
        sin_t2 = eta**2 * (1 - cosi**2)
        refl = mine[np.sign(mine["dy"]) != np.sign(d[1])]
        refr = mine[np.sign(mine["dy"]) == np.sign(d[1])]
        assert len(refl) == 1
        rd = np.array([refl["dx"][0], refl["dy"][0], refl["dz"][0]])
        np.testing.assert_allclose(rd, d * [1, -1, 1], atol=2e-6)
        if sin_t2 >= 1 + 1e-5:
            n_tir += 1
            assert len(refr) == 0
            np.testing.assert_allclose(refl["wr"][0], 1.0, rtol=1e-6)
            continue
        if sin_t2 > 1 - 1e-3:
            continue  # within float32 reach of the critical angle
        n_two += 1
        assert len(refr) == 1
        # float32 Fresnel loses digits near the critical angle (1 - sin^2 t cancels)
        np.testing.assert_allclose(refl["wr"][0], F, rtol=2e-5, atol=3e-5)
        np.testing.assert_allclose(refr["wr"][0], 1 - F, rtol=2e-5, atol=3e-5)
        assert abs(refl["wr"][0] + refr["wr"][0] - 1.0) < 1e-6  # energy is split, not lost
        t = np.array([refr["dx"][0], refr["dy"][0], refr["dz"][0]], np.float64)
        # Snell: n1 sin(i) = n2 sin(t), in the plane of incidence, on the far side
        sin_i = np.linalg.norm(np.cross(d, n))
        sin_t = np.linalg.norm(np.cross(t, n))
        np.testing.assert_allclose(sin_t, eta * sin_i, atol=3e-6)
        assert abs(np.dot(np.cross(d, n), t)) < 3e-6
        assert np.sign(t[1]) == np.sign(d[1])
        assert abs(np.linalg.norm(t) - 1) < 1e-6
    assert n_two > 100
    if from_below:
        assert n_tir > 50  # the wide view reaches past the critical angle
    else:
        assert n_tir == 0


@pytest.mark.parametrize("fused", [False, True], ids=["trace+shade", "trace_shade"])
def test_aov_equals_intersect_on_camera_rays(rt, fused):
    from app.meshes import load_mesh
    from raytrace import intersect

    V, F = load_mesh("bunny_5k.obj")
    sc = RenderScene(rt)
    sc.add_instance(sc.add_mesh(V, F))
    s = RenderSettings(width=48, height=40, spp=1, bounces=0, aov=True, fuse_trace_shade=fused)
    r = Renderer(rt, sc, s)
    c = V.mean(axis=0)
    ext = float(np.ptp(V, axis=0).max())
    r.set_camera(c + np.array([0.3, 0.4, 1.5]) * ext, c, (0, 1, 0), 45)
    r.enqueue_frame()
    rays = rt.to_host(r.rays[0], RAY, r.n_q)
    live = np.abs(rays["dx"]) + np.abs(rays["dy"]) + np.abs(rays["dz"]) > 0
    rays = rays[live]
    orig = np.stack([rays["ox"], rays["oy"], rays["oz"]], 1)
    D = np.stack([rays["dx"], rays["dy"], rays["dz"]], 1)
    hits = intersect(V, F, orig, D, device=rt)
    x, y, _ = ref.pixel_of(r.camera, rays["pixel"])
    aov = r.read_aov()
    prim = aov["prim"][y, x]
    depth = aov["depth"][y, x]
    assert (hits["prim"] >= 0).mean() > 0.2
    assert (prim == hits["prim"]).mean() >= 0.999
    both = (prim >= 0) & (hits["prim"] >= 0)
    np.testing.assert_allclose(depth[both], hits["t"][both], rtol=1e-5)
    assert (aov["inst"][y, x][prim >= 0] == 0).all()
    n = aov["normal"][y, x][prim >= 0]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    assert (np.sum(n * D[prim >= 0], axis=1) <= 1e-6).all()  # normals face the camera


def test_contributions_never_exceed_one(rt):
    sc = tiny_scene(rt)
    s = RenderSettings(width=24, height=16, spp=4, bounces=2, min_weight=0.0)
    r = Renderer(rt, sc, s)
    r.set_camera((0.5, 1.5, 3.0), (0, 0.3, 0), (0, 1, 0), 50)
    r.enqueue_frame()
    counts = rt.to_host(r.counts, np.uint32, 3)
    assert counts[1] > 0 and counts[2] > 0
    for depth, buf in ((1, r.rays[1]), (2, r.rays[0])):  # the ping-pong buffers
        rays = rt.to_host(buf, RAY, int(counts[depth]))
        w = np.stack([rays["wr"], rays["wg"], rays["wb"]], 1).astype(np.float64)
        assert (w >= 0).all() and (w <= 1.0 / s.spp + 1e-7).all()
        per_pixel = np.zeros((int(rays["pixel"].max()) + 1, 3))
        np.add.at(per_pixel, rays["pixel"], w)
        assert per_pixel.max() <= 1.0 + 1e-6
        assert np.all(np.diff(rays["pixel"].astype(np.int64)) >= 0)  # still sorted by pixel


def test_shadow_rays_do_not_hit_their_own_surface(rt):
    """A lit plane far from the origin under a grazing sun: every pixel equals the unshadowed
    float64 shading (a shadow ray re-hitting its triangle would darken it)."""
    sc = RenderScene(rt)
    mat = sc.add_material(Material(diffuse=(0.8, 0.8, 0.8), specular=(0.5, 0.5, 0.5),
                                   shininess=8))
    V, F = quad((1000.0, 250.0, -700.0), 50.0)
    sc.add_instance(sc.add_mesh(V, F, material=mat))
    sc.add_light("directional", direction=(1.0, -0.12, 0.3), color=(2, 2, 2))
    s = RenderSettings(width=24, height=24, spp=1, bounces=0)
    r = Renderer(rt, sc, s)
    r.set_camera((1000.0, 260.0, -690.0), (1000.0, 250.0, -700.0), (0, 1, 0), 60)
    r.render()
    fb = r.read_framebuffer()
    lit_ref = ref.render(sc.tables(), r.camera, r.params(), sc.lights)["framebuffer"]
    ambient_only = 0.05 * 0.8
    hit = lit_ref.max(axis=2) > ambient_only * 1.5
    assert hit.mean() > 0.9
    np.testing.assert_allclose(fb[hit], lit_ref[hit], rtol=1e-4)


def test_every_level_is_launched_and_size_hints_never_change_the_image(rt):
    """All levels up to bounces run in every frame (the first one included); sizing launches
    from the last frame's counts gives the same image as full-size launches."""
    sc = tiny_scene(rt)
    full = Renderer(rt, sc, RenderSettings(width=24, height=16, bounces=12, size_hints=False))
    hinted = Renderer(rt, sc, RenderSettings(width=24, height=16, bounces=12))
    for r in (full, hinted):
        r.set_camera((0.5, 1.5, 3.0), (0, 0.3, 0), (0, 1, 0), 50)
    full.render()
    ref_fb = full.read_framebuffer()
    per_depth = full.read_stats()["rays_per_depth"]
    assert len(per_depth) == 13 and per_depth[1] > 0
    for _ in range(3):
        hinted.render()
        st = hinted.read_stats()
        assert st["levels"] == 12 and st["rays_per_depth"] == per_depth
        np.testing.assert_array_equal(hinted.read_framebuffer(), ref_fb)
    assert hinted._last_hint is not None and hinted._last_hint[0] == per_depth[0]


def test_multi_block_compaction_equals_small_chunks(rt):
    """Wavefronts of several scan blocks (the last block scans the block totals) give the same
    image, ray counts and pixel-sorted wavefronts as chunks small enough for one block."""
    from raytrace.render_types import SCAN_BLOCK

    sc = tiny_scene(rt)
    kw = dict(width=40, height=32, spp=4, bounces=2, size_hints=False)
    whole = Renderer(rt, sc, RenderSettings(**kw))
    small = Renderer(rt, sc, RenderSettings(**kw, max_chunk_rays=256))
    for r in (whole, small):
        r.set_camera((0.5, 1.5, 3.0), (0, 0.3, 0), (0, 1, 0), 50)
        r.render()
    assert len(whole.chunks) == 1 and len(small.chunks) == 20
    counts = rt.to_host(whole.counts, np.uint32, 3)
    assert counts[0] > 4 * SCAN_BLOCK and counts[1] > SCAN_BLOCK and counts[2] > 0
    for depth, buf in ((1, whole.rays[1]), (2, whole.rays[0])):  # the ping-pong buffers
        kids = rt.to_host(buf, RAY, int(counts[depth]))
        assert np.all(np.diff(kids["pixel"].astype(np.int64)) >= 0)
        assert (kids["wr"] + kids["wg"] + kids["wb"] > 0).all()  # no gap left unwritten
    st_w, st_s = whole.read_stats(), small.read_stats()
    assert st_w["rays_per_depth"] == st_s["rays_per_depth"] and st_w["dropped"] == 0
    assert st_w["rays_per_depth"][1:] == [int(counts[1]), int(counts[2])]
    fb = whole.read_framebuffer()
    np.testing.assert_array_equal(fb, small.read_framebuffer())
    np.testing.assert_array_equal(whole.read_rgba(), small.read_rgba())
    # launched for far fewer work-items than rays (a stale count hint): the grid-stride loops
    # still trace, shade and gather every ray
    whole._last_hint = (0, 0, 0)
    sizes = whole._launch_sizes(whole._plan[0][3], whole._last_hint)
    assert sizes[1][0][0] < counts[1]
    whole.render()
    np.testing.assert_array_equal(whole.read_framebuffer(), fb)
    assert whole.read_stats()["rays_per_depth"] == st_w["rays_per_depth"]


@pytest.mark.parametrize("n", [0, 5, 1024, 1025, 5000, 70000])
def test_scan_kernel_offsets_counts_and_stats(rt, n):
    """render_scan in one launch: exclusive offsets (block offset + offset in block) equal
    NumPy's cumulative sum, the total becomes the next count and the stats, the ticket is 0."""

    from raytrace.render_types import SCAN_BLOCK, SCAN_WG, STAT_DROPPED, STATS_LEN

    k = rt.kernel_launcher("render_secondary.cl", "render_scan", stage="test.scan")
    cc = np.random.default_rng(n).integers(0, 3, max(n, 1)).astype(np.uint32)
    child = rt.to_device(cc)
    counts = rt.to_device(np.array([n, 0, 0], np.uint32))
    blocks = max(1, -(-n // SCAN_BLOCK))
    sums = rt.buffer(4 * blocks)
    ticket = rt.to_device(np.zeros(1, np.uint32))
    stats = rt.to_device(np.zeros(STATS_LEN, np.uint32))
    total = int(cc[:n].sum())
    k.bind(child_counts=child, counts=counts, depth=0, capacity=max(total - 3, 0),
           block_sums=sums, ticket=ticket, stats=stats)
    k.launch((blocks + 1) * SCAN_WG, SCAN_WG)
    off = rt.to_host(child, np.uint32, max(n, 1))[:n].astype(np.int64)
    off += rt.to_host(sums, np.uint32, blocks)[np.arange(n) // SCAN_BLOCK]
    np.testing.assert_array_equal(off, np.cumsum(cc[:n], dtype=np.int64) - cc[:n])
    kept = max(total - 3, 0)
    assert rt.to_host(counts, np.uint32, 3)[1] == kept
    st = rt.to_host(stats, np.uint32, STATS_LEN)
    assert (st[0], st[1], st[STAT_DROPPED]) == (n, kept, total - kept)
    assert rt.to_host(ticket, np.uint32, 1)[0] == 0


CAMERAS = [((0.0, 1.0, 3.0), (0.0, 0.0, 6.0)),   # the floor and sky only: no secondary rays
           ((0.5, 1.5, 3.0), (0.0, 0.3, 0.0)),   # the glass box and the mirror appear
           ((-1.0, 1.2, 2.5), (0.0, 0.4, -0.5))]


def test_frame_does_not_depend_on_the_previous_frame(rt):
    """A frame rendered by a fresh renderer equals the same frame inside a sequence, byte for
    byte, including the frame where reflections and refractions first appear."""
    sc = tiny_scene(rt)
    kw = dict(width=24, height=16, bounces=4)
    seq = Renderer(rt, sc, RenderSettings(**kw))
    frames = []
    for eye, target in CAMERAS:
        seq.set_camera(eye, target, (0, 1, 0), 50)
        seq.enqueue_frame()
        frames.append((seq.read_rgba(), seq.read_stats()))
    assert frames[0][1]["secondary_rays"] == 0 and frames[1][1]["secondary_rays"] > 0
    for (eye, target), (rgba, stats) in zip(CAMERAS, frames, strict=True):
        alone = Renderer(rt, sc, RenderSettings(**kw))
        alone.set_camera(eye, target, (0, 1, 0), 50)
        alone.enqueue_frame()
        assert alone.read_stats() == stats
        np.testing.assert_array_equal(alone.read_rgba(), rgba)


def test_non_blocking_reads_two_in_flight(rt):
    """enqueue_read_rgba/enqueue_read_stats copy into pinned memory without a wait; two images
    in flight each hold their own frame; a third read reuses the first's slot, whose handle
    then refuses to read."""
    from kernels.pinned import StaleReadError

    sc = tiny_scene(rt)
    r = Renderer(rt, sc, RenderSettings(width=24, height=16, bounces=3))
    want = []
    for eye, target in CAMERAS[1:]:  # the blocking path, frame by frame
        r.set_camera(eye, target, (0, 1, 0), 50)
        r.enqueue_frame()
        want.append((r.read_rgba().copy(), r.read_stats()))
    handles = []
    for eye, target in CAMERAS[1:]:  # two frames in flight, nothing waited on
        r.set_camera(eye, target, (0, 1, 0), 50)
        r.enqueue_frame()
        handles.append((r.enqueue_read_rgba(), r.stats_handle))
    assert not np.array_equal(want[0][0], want[1][0])
    for (h_img, h_stats), (img, stats) in zip(handles, want, strict=True):
        assert h_img.array.shape == (16, 24, 4) and isinstance(h_img.event, cl.Event)
        np.testing.assert_array_equal(h_img.wait(), img)
        assert r.stats_from(h_stats.wait()) == stats
    r.enqueue_read_rgba()  # a third read reuses the first one's slot
    with pytest.raises(StaleReadError, match="reused"):
        handles[0][0].wait()
    np.testing.assert_array_equal(handles[1][0].wait(), want[1][0])
    assert r.stats_from(r.enqueue_read_stats().wait()) == want[1][1]
