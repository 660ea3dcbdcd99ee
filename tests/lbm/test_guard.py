"""The guard where the method fails: tau next to 1/2, huge drops, violent pushes and NaN. Fields
and surface vertices never hold a NaN, and stats() says what the guard did. Also the sources'
physics (drop volume, push direction, deterministic rain)."""

import numpy as np
import pytest

import lbm
from lbm import reference as ref

N, DX = 40, 0.025


def _mesh(n, dx):
    jj, ii = np.mgrid[0:n, 0:n]
    return (ii + 0.5) * dx, (jj + 0.5) * dx


def _assert_finite_everywhere(sim, rt):
    for name, a in sim.fields().items():
        assert np.isfinite(a).all(), name
    verts, norms = rt.buffer(16 * sim.n_cells), rt.buffer(16 * sim.n_cells)
    sim.write_surface(verts, norms)
    assert np.isfinite(rt.to_host(verts, np.float32, 4 * sim.n_cells)).all()
    assert np.isfinite(rt.to_host(norms, np.float32, 4 * sim.n_cells)).all()


def _assert_within_limits(sim):
    """The state (not the peak the limiter saw before clipping) is within the limits."""
    lat, f = sim.lattice, sim.fields()
    speed = np.hypot(f["u"], f["v"])
    assert speed.max() / lat.e <= lat.max_speed_ratio * (1 + 1e-5)
    assert (speed / np.sqrt(lat.gravity * f["h"])).max() <= lat.max_froude * (1 + 1e-4)
    assert f["h"].min() >= lat.min_depth * (1 - 1e-5)
    assert f["h"].max() * lat.g_lat <= 0.6 * (1 + 1e-5)


def _assert_budget(s, rel=2e-6):
    """volume_initial + volume_sources - volume_clipped + volume_created == volume."""
    budget = s["volume_initial"] + s["volume_sources"] - s["volume_clipped"] + s["volume_created"]
    assert s["volume"] == pytest.approx(budget, rel=rel, abs=1e-9)


def test_tau_next_to_half_is_limited_locally_never_nan(rt):
    """A supercritical 2D dam break (1 m | 0.1 m) with tau - 1/2 ~ 1e-11 (no viscosity to speak
    of): the limiter clips and reports the Froude number it saw, tau stays the user's, and the
    water calms."""
    sim = lbm.ShallowWater(N, N, DX, device=rt, viscosity=1e-12)
    assert sim.tau - 0.5 < 1e-9
    x, _ = _mesh(N, DX)
    sim.set_state(np.where(x < 0.5, 1.0, 0.1))
    reports = []
    for _ in range(12):
        sim.step(100)
        s = sim.stats()
        reports.append(s)
        assert s["tau"] == pytest.approx(sim.tau, rel=1e-7)   # never a global change
        _assert_finite_everywhere(sim, rt)
        _assert_within_limits(sim)
        _assert_budget(s)
    first = reports[0]
    assert first["acted"] and first["cells_limited"] > 0 and first["clamped"] > 0
    assert first["max_froude"] > 1.2   # what the limiter saw, reported
    assert "limited" in first["report"]
    assert sum(r["cells_limited"] for r in reports[-3:]) < first["cells_limited"] / 20


def test_tall_drops_are_clipped_and_booked_never_nan(rt):
    """Drops of the largest accepted height, piled on one spot, break the depth cap: clipped,
    and the volume clipped is in the budget (nothing silently lost)."""
    sim = lbm.ShallowWater(N, N, DX, device=rt, viscosity=1e-5)
    for _k in range(4):
        for _ in range(3):
            sim.add_drop(0.5, 0.5, 0.12, sim.max_drop_height)
        sim.step(5)
        s = sim.stats()
        _assert_finite_everywhere(sim, rt)
        _assert_within_limits(sim)
        _assert_budget(s)
    assert s["volume_clipped"] > 0.05 * s["volume_sources"] > 0


def test_violent_pushes_are_clamped_never_nan(rt):
    sim = lbm.ShallowWater(N, N, DX, device=rt, viscosity=1e-5)
    for k in range(8):
        sim.push(0.1, 0.1 + 0.1 * k, 0.8, 0.3, 1e4)       # 10 km/s drags
        sim.step(25)
        s = sim.stats()
        assert s["clamped"] > 0 and s["acted"]
        assert s["volume_sources"] == 0
        _assert_finite_everywhere(sim, rt)
        _assert_within_limits(sim)
        _assert_budget(s)


def test_damping_is_local_viscosity_elsewhere_unchanged(rt):
    """After a strong push, the next step relaxes the damped cells with tau = 1 and every other
    cell with the user's tau: equal to the float64 reference run with that per-cell tau."""
    nx, ny, dx = 13, 9, 0.05
    sim = lbm.ShallowWater(nx, ny, dx, device=rt, viscosity=2e-3)
    sim.step(1)
    sim.push(0.2, 0.2, 0.15, 0.05, 200.0, radius=0.08)   # far beyond the limits: clipped
    s = sim.stats()
    assert s["cells_limited"] > 0
    damped = sim.damped_cells()
    assert 0 < damped.sum() < damped.size // 4          # local, not the grid
    f = sim.populations().astype(np.float64)
    lat = sim.lattice
    kw = dict(boundary="slip", g=lat.gravity, e=lat.e, drag_dt=0.0, with_bed=False,
              h_min=lat.min_depth, u_ratio_max=lat.max_speed_ratio, froude_max=lat.max_froude)
    bed = np.zeros((ny, nx))
    f_user, _, _ = ref.step(f, f.sum(0), bed, tau=lat.tau, **kw)
    f_damp, _, _ = ref.step(f, f.sum(0), bed, tau=max(lat.tau, 1.0), **kw)
    expect = np.where(damped[None], f_damp, f_user)
    sim.step(1)
    got = sim.populations()
    np.testing.assert_allclose(got, expect, rtol=0, atol=3e-6)
    assert np.abs(f_damp - f_user)[:, ~damped].max() > 1e-4   # the two taus differ there
    assert sim.stats()["tau"] == pytest.approx(lat.tau, rel=1e-7)


def test_budget_holds_for_rain_drops_and_pushes(rt):
    sim = lbm.ShallowWater(N, N, DX, device=rt, viscosity=1e-4)
    sim.set_rain(300.0, 0.05, 0.02, seed=2)
    sim.add_drop(0.3, 0.3, 0.1, 0.1)
    sim.push(0.5, 0.5, 0.2, 0.1, 3.0)
    sim.add_drop(0.7, 0.6, 0.1, -0.9)      # a dip to 10 cm
    for _ in range(3):
        sim.step(40)
        s = sim.stats()
        _assert_budget(s)
    shape = np.pi / 2 - 2 / np.pi   # a drop's volume is height radius^2 shape
    drops = (0.1 - 0.9) * 0.1**2 * shape
    rain = s["volume_sources"] - drops
    assert rain > 0.5 * 300 * s["time"] * 0.02 * 0.05**2 * shape   # most of the rain, counted


def test_rain_deepening_the_water_rechooses_the_lattice(rt):
    """Rain that raises the water well past the depth e was chosen for: e is chosen again (and
    said so), the water keeps its volume, and the budget still holds."""
    sim = lbm.ShallowWater(20, 20, 0.05, device=rt, depth=0.2, viscosity=1e-4)
    e0 = sim.e
    sim.set_rain(2000.0, 0.15, 0.05, seed=1)
    notes = []
    for _ in range(30):
        sim.step(20)
        s = sim.stats()
        _assert_budget(s, rel=1e-5)
        if s["lattice"]:
            notes.append(s)
            break
    assert notes, "the lattice was never re-chosen"
    s = notes[0]
    assert "re-chose e" in s["report"] and sim.e > e0
    v = sim.stats()["volume"]
    assert v == pytest.approx(s["volume"], rel=1e-5)
    assert sim.max_drop_height > 0


def test_plain_solver_reports_nan_and_limits_nothing(rt):
    """guard=False: the supercritical dam break goes non-finite; stats() says so, the guard did
    not act (no limiting, no restore) and fields show the NaN."""
    sim = lbm.ShallowWater(N, N, DX, device=rt, viscosity=1e-12, guard=False)
    x, _ = _mesh(N, DX)
    sim.set_state(np.where(x < 0.5, 1.0, 0.1))
    sim.step(300)
    s = sim.stats()
    assert s["nan"] and not s["acted"] and s["cells_limited"] == 0 and s["restored"] == 0
    assert "guard off" in s["report"]
    assert not np.isfinite(sim.fields()["h"]).all()


def test_nan_inside_a_long_step_call_is_restored(rt):
    """A NaN appearing mid-call is caught by the next in-call check (guard_interval) and
    restored from the checkpoint; time keeps counting steps."""
    sim = lbm.ShallowWater(N, N, DX, device=rt, guard_interval=50, checkpoint_interval=50)
    sim.add_drop(0.5, 0.5, 0.2, 0.05)
    sim.step(100)
    f = sim.populations()
    f[:, 10:12, 20] = np.nan
    sim._load_populations(f)
    sim.step(250)
    s = sim.stats()
    assert s["nan"] and s["restored"] == 1 and s["steps"] == 350
    assert s["time"] == pytest.approx(350 * sim.dt)
    assert "restored the checkpoint" in s["report"]
    _assert_finite_everywhere(sim, rt)


def test_drop_adds_its_volume(rt):
    """A raised-cosine drop of height H and radius R adds H R^2 (pi/2 - 2/pi) of water."""
    sim = lbm.ShallowWater(N, N, DX, device=rt)
    m0 = sim.stats()["mass"]
    radius, height = 12 * DX, 0.04
    sim.add_drop(0.5, 0.5, radius, height)
    added = sim.stats()["mass"] - m0
    assert added == pytest.approx(height * radius**2 * (np.pi / 2 - 2 / np.pi), rel=5e-3)
    sim.step(200)
    assert sim.stats()["mass"] - m0 == pytest.approx(added, rel=1e-4)


def test_push_moves_water_along_the_drag(rt):
    sim = lbm.ShallowWater(N, N, DX, device=rt)
    sim.push(0.3, 20.5 * DX, 0.4, 0.0, 0.5, radius=0.1)   # along the centres of row j = 20
    f = sim.fields()
    px, py = (f["h"] * f["u"]).sum(), (f["h"] * f["v"]).sum()
    assert px > 0 and abs(py) < 1e-4 * px
    assert f["u"].max() == pytest.approx(0.5, rel=1e-3)   # strength at the centre line


def test_rain_is_deterministic_and_adds_water(rt):
    """Same seed, same drops at the same times, however the steps are grouped; another seed
    differs; the volume grows."""
    def run(seed, chunks):
        sim = lbm.ShallowWater(N, N, DX, device=rt)
        sim.set_rain(200.0, 0.05, 0.01, seed)
        m0 = sim.stats()["mass"]
        for n in chunks:
            sim.step(n)
        return sim.populations(), sim.stats()["mass"] - m0

    a, added = run(3, [60])
    b, _ = run(3, [7, 13, 1, 39])
    c, _ = run(4, [60])
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert added > 0
