"""Every lbm kernel against the float64 reference (tests/lbm/reference.py) at small sizes, and the
layout of every device struct the lbm package declares."""

import numpy as np
import pyopencl as cl
import pytest

import lbm
from kernels.layout import check_struct
from lbm import reference as ref
from lbm.structs import STRUCTS

NX, NY, DX = 13, 9, 0.05


def _params(sim):
    lat = sim.lattice
    return dict(g=lat.gravity, e=lat.e)


def _limits(sim):
    lat = sim.lattice
    return dict(h_min=lat.min_depth, u_ratio_max=lat.max_speed_ratio, froude_max=lat.max_froude)


def _random_state(rng, bed_on: bool):
    jj, ii = np.mgrid[0:NY, 0:NX]
    bed = 0.2 * rng.random((NY, NX)) if bed_on else np.zeros((NY, NX))
    h = 1.0 - bed + 0.05 * np.sin(ii / 2.0) * np.cos(jj / 3.0)
    u = 0.2 * rng.standard_normal((NY, NX))
    v = 0.2 * rng.standard_normal((NY, NX))
    return h, u, v, bed


def _perturbed(sim, rng, h, u, v):
    """Equilibrium plus a non-equilibrium part that conserves nothing in particular."""
    lat = sim.lattice
    f = ref.feq_si(h, u, v, lat.gravity, lat.e)
    return f * (1.0 + 0.02 * rng.standard_normal(f.shape))


def _load_perturbed(sim, rng, h, u, v, bed=None):
    """Set the state, then overwrite the populations with perturbed ones; returns them."""
    sim.set_state(h, u, v, bed)
    f = _perturbed(sim, rng, h, u, v)
    sim._load_populations(f)
    return f


@pytest.mark.parametrize("header, name, dtype", STRUCTS, ids=[s[1] for s in STRUCTS])
def test_struct_layout_matches_dtype(rt, header, name, dtype):
    check_struct(rt, header, name, dtype)


@pytest.mark.parametrize("boundary", ["slip", "noslip"])
@pytest.mark.parametrize("bed_on", [False, True], ids=["flat", "bed"])
def test_steps_match_reference(rt, boundary, bed_on):
    """Three fused steps (both ping-pong parities) equal the float64 push-stream reference, with
    walls on every side, drag, the bed force and non-equilibrium populations."""
    rng = np.random.default_rng(1 + bed_on)
    sim = lbm.ShallowWater(NX, NY, DX, boundary=boundary, device=rt, drag=2.0,
                           viscosity=2e-3)
    h, u, v, bed = _random_state(rng, bed_on)
    f = _load_perturbed(sim, rng, h, u, v, bed)
    f = f.astype(np.float32).astype(np.float64)
    h_prev = f.sum(0)
    lat = sim.lattice
    kw = dict(boundary=boundary, tau=lat.tau, drag_dt=lat.drag * lat.dt, with_bed=bed_on,
              **_params(sim), **_limits(sim))
    for _ in range(3):
        f, h_prev, hit = ref.step(f, h_prev, bed.astype(np.float32), **kw)
        assert not hit.any()
        sim.step(1)
        got = sim.populations()
        np.testing.assert_allclose(got, f, rtol=0, atol=2e-6)
    assert sim.stats()["clamped"] == 0
    fields = sim.fields()
    np.testing.assert_allclose(fields["h"], f.sum(0), atol=2e-6)
    _, u_ref, v_ref = ref.macro(f, lat.e)
    np.testing.assert_allclose(fields["u"], u_ref, atol=2e-5 * lat.e)
    np.testing.assert_allclose(fields["v"], v_ref, atol=2e-5 * lat.e)


def test_step_limiter_matches_reference(rt):
    """Cells beyond the limits (too fast, too deep for f0_eq >= 0, too shallow) are clamped
    exactly as the reference limiter says, set to their equilibrium, and counted."""
    rng = np.random.default_rng(7)
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, viscosity=2e-3, min_depth=0.2)
    h, u, v, bed = _random_state(rng, False)
    sim.set_state(h, 0 * u, 0 * v)
    lat = sim.lattice
    u, v = 0.1 * u, 0.1 * v
    u[4, 6] = 0.9 * lat.e                       # |u|/e above max_speed_ratio
    v[2, 3] = 1.4 * np.sqrt(lat.gravity * h[2, 3])  # supercritical
    h[6, 9] = 2.0 * 6 * lat.e**2 / (5 * lat.gravity)  # f0_eq < 0
    h[1, 1] = 0.05                               # below min_depth
    f = ref.feq_si(h, u, v, lat.gravity, lat.e)
    sim._load_populations(f)
    f_ref, _, hit = ref.step(f.astype(np.float32), f.astype(np.float32).sum(0), bed,
                             boundary="slip", tau=lat.tau, drag_dt=0.0, with_bed=False,
                             **_params(sim), **_limits(sim))
    sim.step(1)
    np.testing.assert_allclose(sim.populations(), f_ref, rtol=2e-6, atol=2e-6)
    s = sim.stats()
    assert s["clamped"] == hit.sum() >= 4
    assert "limited" in s["report"]


def test_drop_matches_reference(rt):
    rng = np.random.default_rng(3)
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, viscosity=2e-3)
    h, u, v, _ = _random_state(rng, False)
    f = _load_perturbed(sim, rng, h, 0.3 * u, 0.3 * v)
    sim.add_drop(0.31, 0.2, 0.17, 0.08)
    f_ref, _, hit = ref.drop(f.astype(np.float32), x=0.31, y=0.2, radius=0.17, height=0.08,
                             dx=DX, **_params(sim), limits=_limits(sim))
    assert not hit.any()
    got = sim.populations()
    np.testing.assert_allclose(got, f_ref, rtol=0, atol=2e-6)
    assert np.count_nonzero(np.abs(got - f.astype(np.float32)).sum(0) > 1e-6) > 20
    s = sim.stats()
    assert s["clamped"] == 0
    assert s["mass"] == pytest.approx(f_ref.sum() * DX**2, rel=1e-6)


def test_deep_dip_is_clipped_like_reference(rt):
    """A dip to 5 mm in 1 m of water breaks min_depth (1 cm): clipped as the reference clips it,
    counted, and the volume the limiter created is booked in the budget."""
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, viscosity=2e-3)
    f = sim.populations()
    sim.add_drop(0.325, 0.225, 0.12, -0.995)
    f_ref, h_ref, hit = ref.drop(f, x=0.325, y=0.225, radius=0.12, height=-0.995, dx=DX,
                                 **_params(sim), limits=_limits(sim))
    assert hit.sum() >= 1
    np.testing.assert_allclose(sim.populations(), f_ref, rtol=2e-6, atol=2e-6)
    s = sim.stats()
    assert s["clamped"] == s["cells_limited"] == hit.sum() and s["acted"]
    asked = s["volume_sources"]
    assert asked < 0 and s["volume_clipped"] == 0
    assert s["volume_created"] == pytest.approx(
        (h_ref.sum() - f.astype(np.float64).sum()) * DX**2 - asked, rel=1e-3)
    budget = s["volume_initial"] + asked - s["volume_clipped"] + s["volume_created"]
    assert s["volume"] == pytest.approx(budget, rel=1e-6)


def test_impossible_drops_are_refused(rt):
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, viscosity=2e-3)
    with pytest.raises(ValueError, match="above the stability limit"):
        sim.add_drop(0.3, 0.2, 0.12, 50.0)
    with pytest.raises(ValueError, match="deeper than the water"):
        sim.add_drop(0.3, 0.2, 0.12, -1.0)
    s = sim.stats()
    assert s["volume_sources"] == 0 and not s["acted"]


@pytest.mark.parametrize("strength", [0.4, 200.0], ids=["gentle", "violent"])
def test_push_matches_reference(rt, strength):
    rng = np.random.default_rng(5)
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, viscosity=2e-3)
    h, u, v, _ = _random_state(rng, False)
    f = _load_perturbed(sim, rng, h, 0.2 * u, 0.2 * v)
    sim.push(0.12, 0.1, 0.3, 0.15, strength, radius=0.13)
    f_ref, _, hit = ref.push(f.astype(np.float32), x=0.12, y=0.1, ddx=0.3, ddy=0.15,
                             strength=strength, radius=0.13, dx=DX, **_params(sim),
                             limits=_limits(sim))
    np.testing.assert_allclose(sim.populations(), f_ref, rtol=2e-6, atol=2e-6)
    s = sim.stats()
    assert s["clamped"] == hit.sum()
    assert (hit.sum() > 0) == (strength > 100)


def test_reduction_matches_numpy(rt):
    rng = np.random.default_rng(11)
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, viscosity=2e-3)
    h, u, v, _ = _random_state(rng, False)
    sim.set_state(h, 0.5 * u, 0.5 * v)
    f = sim.populations().astype(np.float64)
    hh, uu, vv = ref.macro(f, sim.e)
    s = sim.stats()
    speed = np.hypot(uu, vv)
    assert s["mass"] == pytest.approx(hh.sum() * DX**2, rel=1e-6)
    assert s["max_speed_ratio"] == pytest.approx(speed.max() / sim.e, rel=1e-5)
    assert s["max_froude"] == pytest.approx((speed / np.sqrt(9.81 * hh)).max(), rel=1e-5)
    assert s["min_depth"] == pytest.approx(hh.min(), rel=1e-6)
    assert s["nan"] is False and s["report"] == "ok"


def test_guard_restores_checkpoint_on_nan(rt):
    """A NaN anywhere: the check restores the last checkpoint bit for bit (device copy), marks the
    cell that was non-finite for local damping, and reports it; fields never show the NaN."""
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, viscosity=1e-3, checkpoint_interval=4,
                           guard_interval=4)
    assert sim.stats()["saved"] == 1   # the initial state
    sim.add_drop(0.3, 0.2, 0.15, 0.05)
    sim.step(4)  # clean interval: saved
    assert sim.stats()["saved"] == 1
    ckpt = sim.populations()
    poisoned = ckpt.copy()
    poisoned[3, 4, 5] = np.nan
    sim._load_populations(poisoned)
    sim.step(3)
    s = sim.stats()
    assert s["nan"] and s["restored"] == 1 and s["acted"]
    assert s["tau"] == pytest.approx(sim.tau, rel=1e-7)   # no global change of tau
    assert "restored the checkpoint" in s["report"]
    damped = sim.damped_cells()
    # the cells the NaN reached in 3 steps (at most 3 cells away) are damped, the rest are not
    jj, ii = np.nonzero(damped)
    assert damped[4, 5] and 9 <= damped.sum() <= 49
    assert np.abs(jj - 4).max() <= 3 and np.abs(ii - 5).max() <= 3
    np.testing.assert_array_equal(sim.populations(), ckpt)
    assert s["mass"] == pytest.approx(ckpt.astype(np.float64).sum() * DX**2, rel=1e-6)
    assert all(np.isfinite(a).all() for a in sim.fields().values())
    s2 = sim.stats()
    assert s2["restored"] == 0 and not s2["nan"]


def test_guard_saves_only_clean_intervals(rt):
    # strong drag so the clamped jet dies down within a few steps
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, viscosity=1e-3, checkpoint_interval=1,
                           drag=20.0)
    sim.stats()
    sim.step(2)
    assert sim.stats()["saved"] == 1
    sim.push(0.3, 0.2, 0.1, 0.0, 500.0)   # clamps: the interval is not clean
    sim.step(1)
    s = sim.stats()
    assert s["clamped"] > 0 and s["saved"] == 0
    for _ in range(20):   # the jet is clamped for a while; the first clean step saves
        sim.step(1)
        s = sim.stats()
        assert s["saved"] == (s["clamped"] == 0)
        if s["saved"]:
            break
    assert s["saved"] == 1


def test_surface_matches_reference(rt):
    rng = np.random.default_rng(2)
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, viscosity=2e-3)
    h, u, v, bed = _random_state(rng, True)
    sim.set_state(h, 0.1 * u, 0.1 * v, bed)
    sim.step(2)
    verts = rt.buffer(16 * NX * NY)
    norms = rt.buffer(16 * NX * NY)
    origin = (-1.5, 0.25, 2.0)
    sim.write_surface(verts, norms, origin=origin)
    fields = sim.fields()
    v_ref, n_ref = ref.surface(fields["h"], fields["bed"], DX, origin)
    got_v = rt.to_host(verts, np.float32, 4 * NX * NY).reshape(NY, NX, 4)
    got_n = rt.to_host(norms, np.float32, 4 * NX * NY).reshape(NY, NX, 4)
    np.testing.assert_allclose(got_v, v_ref, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(got_n, n_ref, atol=2e-6)
    assert np.ptp(got_n[..., 0]) > 0.05   # the test surface is not flat
    # vertices only: the normals buffer is untouched
    cl.enqueue_fill_buffer(rt.queue, norms, np.float32(7.0), 0, 16 * NX * NY)
    sim.write_surface(verts)
    assert np.all(rt.to_host(norms, np.float32, 4 * NX * NY) == 7.0)


def test_surface_never_shows_nan(rt):
    """Even a state that was never checked (NaN loaded behind the guard's back) gives finite
    vertices and unit normals."""
    sim = lbm.ShallowWater(NX, NY, DX, device=rt)
    f = sim.populations()
    f[:, 3, 4] = np.nan
    f[0, 5, 5] = np.inf
    sim._load_populations(f)
    verts, norms = rt.buffer(16 * NX * NY), rt.buffer(16 * NX * NY)
    sim.write_surface(verts, norms)
    v = rt.to_host(verts, np.float32, 4 * NX * NY).reshape(NY, NX, 4)
    n = rt.to_host(norms, np.float32, 4 * NX * NY).reshape(NY, NX, 4)
    assert np.isfinite(v).all() and np.isfinite(n).all()
    assert v[3, 4, 1] == 0.0   # bed level where the depth was not finite
    np.testing.assert_allclose(np.linalg.norm(n[..., :3], axis=-1), 1.0, atol=1e-6)


def test_grid_triangles_face_up():
    nx, ny = 5, 4
    tri = lbm.grid_triangles(nx, ny)
    assert tri.dtype == np.uint32 and tri.shape == (2 * (nx - 1) * (ny - 1), 3)
    assert tri.max() == nx * ny - 1 and len(np.unique(tri)) == nx * ny
    jj, ii = np.mgrid[0:ny, 0:nx]
    pos = np.stack([ii, np.zeros_like(ii), jj], -1).reshape(-1, 3).astype(float)  # Y up
    a, b, c = pos[tri[:, 0]], pos[tri[:, 1]], pos[tri[:, 2]]
    normal = np.cross(b - a, c - a)
    np.testing.assert_allclose(normal, np.tile([0.0, 1.0, 0.0], (len(tri), 1)))
    # each quad is covered once: total area = (nx-1)(ny-1)
    assert 0.5 * np.linalg.norm(normal, axis=1).sum() == pytest.approx((nx - 1) * (ny - 1))
