"""The public API: the choice of e, dt and tau, units, and one-line errors for bad input."""

import math

import numpy as np
import pytest

import lbm
from kernels import get_runtime
from lbm.lattice import Options, choose_lattice

NX, NY, DX = 12, 10, 0.05


@pytest.fixture()
def sim(rt):
    return lbm.ShallowWater(NX, NY, DX, device=rt)


def _one_line(exc: pytest.ExceptionInfo) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize("depth", [0.01, 0.3, 1.0, 5.0, 100.0])
@pytest.mark.parametrize("speed", [None, 0.01, 0.5, 3.0, 30.0])
@pytest.mark.parametrize("viscosity", [None, 1e-6, 1e-3, 1.0])
def test_lattice_choice_keeps_conditions_with_margin(depth, speed, viscosity):
    """tau > 1/2, u^2/e^2 < 1, f0_eq >= 0 and g h/e^2 below the stability limit hold with
    margin at the design point; nu = e dx (2 tau - 1)/6 and dt = dx/e."""
    dx = 0.01
    opts = Options.from_kwargs(expected_speed=speed, viscosity=viscosity)
    lat = choose_lattice(dx, depth, 0.0, opts)
    u = lat.design_speed
    assert lat.design_depth == pytest.approx(1.5 * depth)
    assert lat.tau > 0.5
    assert (u / lat.e) ** 2 <= 0.3**2 + 1e-12
    assert lat.f0_margin(lat.design_depth, u) <= 0.8 + 1e-12
    assert lat.gravity * lat.design_depth / lat.e**2 <= 0.5 + 1e-12
    assert lat.dt == pytest.approx(dx / lat.e)
    assert lat.viscosity == pytest.approx(lat.e * dx * (2 * lat.tau - 1) / 6)
    if viscosity is not None:
        assert lat.viscosity == pytest.approx(viscosity)
    # e is the smallest that meets the design conditions: one of them is tight
    tight = [lat.gravity * lat.design_depth / lat.e**2 / 0.5,
             lat.f0_margin(lat.design_depth, u) / 0.8, u / lat.e / 0.3]
    assert max(tight) == pytest.approx(1.0)


def test_dt_time_and_units(sim):
    assert sim.dt == pytest.approx(DX / sim.e)
    assert sim.time == 0.0
    sim.step(7)
    assert sim.time == pytest.approx(7 * sim.dt) and sim.stats()["steps"] == 7
    sim.step(0)
    assert sim.time == pytest.approx(7 * sim.dt)
    h = np.full((NY, NX), 0.4)
    u = np.full((NY, NX), 0.1)
    sim.set_state(h, u=u)
    assert sim.time == 0.0
    f = sim.fields()
    assert set(f) == {"h", "u", "v", "bed"} and all(a.shape == (NY, NX) for a in f.values())
    np.testing.assert_allclose(f["h"], 0.4, rtol=1e-6)
    np.testing.assert_allclose(f["u"], 0.1, rtol=1e-5)
    np.testing.assert_allclose(f["v"], 0.0, atol=1e-7)
    assert sim.stats()["mass"] == pytest.approx(0.4 * NX * NY * DX * DX, rel=1e-6)
    assert sim.size == (NX * DX, NY * DX)


def test_device_spec_and_runtime_accepted(rt):
    a = lbm.ShallowWater(NX, NY, DX, device="cpu")
    assert a.rt is get_runtime("cpu")
    assert lbm.ShallowWater(NX, NY, DX, device=rt).rt is rt


def test_boundary_enum():
    assert lbm.Boundary.from_str("slip") is lbm.Boundary.SLIP
    assert lbm.Boundary.from_str(" NoSlip ") is lbm.Boundary.NOSLIP
    assert lbm.Boundary.from_str(lbm.Boundary.NOSLIP) is lbm.Boundary.NOSLIP
    assert [int(b) for b in lbm.Boundary] == [0, 1]   # LBM_SLIP, LBM_NOSLIP


@pytest.mark.parametrize("kwargs, match", [
    (dict(boundary="periodic"), r"unknown boundary 'periodic'; valid: slip, noslip"),
    (dict(boundary=3), r"unknown boundary 3"),
    (dict(nx=2), r"nx=2 must be an integer in \[3, 65536\]"),
    (dict(ny=10.0), r"ny=10.0 must be an integer"),
    (dict(dx=0.0), r"dx=0.0 must be > 0"),
    (dict(dx=float("nan")), r"dx=nan must be finite"),
    (dict(gravity=-1), r"option gravity=-1 is out of range; allowed \(0, 1000\]"),
    (dict(viscosity=0.0), r"option viscosity=0.0 is out of range; allowed \(0, 1e\+06\]"),
    (dict(viscosity="a"), r"option viscosity='a' must be a number or None"),
    (dict(expected_speed=float("inf")), r"option expected_speed=inf is out of range"),
    (dict(depth=-0.5), r"option depth=-0.5 is out of range"),
    (dict(max_froude=1.5), r"option max_froude=1.5 is out of range; allowed \(0, 1\]"),
    (dict(guard_interval=0), r"option guard_interval=0 is out of range; allowed \[1, 1e\+09\]"),
    (dict(guard_interval=2.5), r"option guard_interval=2.5 must be an integer"),
    (dict(local_size=(0, 1)), r"option local_size=\(0, 1\) must be None or two integers"),
    (dict(drag=1e5), r"option drag=100000 1/s is too large for dt"),
    (dict(lattice_speed=0.5), r"option lattice_speed=0.5 m/s is too small"),
    (dict(min_depth=2.0), r"option min_depth=2 m must be below the water depth 1 m"),
    (dict(colour="blue"), r"unknown option 'colour'; valid options: gravity, viscosity"),
])
def test_constructor_errors_are_one_line(rt, kwargs, match):
    args = dict(nx=NX, ny=NY, dx=DX)
    for k in ("nx", "ny", "dx"):
        if k in kwargs:
            args[k] = kwargs.pop(k)
    with pytest.raises(ValueError, match=match) as exc:
        lbm.ShallowWater(args["nx"], args["ny"], args["dx"], device=rt, **kwargs)
    _one_line(exc)


def _good():
    return np.ones((NY, NX))


@pytest.mark.parametrize("state, match", [
    (dict(h=np.ones((NX, NY))), r"h has shape \(12, 10\); expected \(ny, nx\) = \(10, 12\)"),
    (dict(h=np.ones(NX * NY)), r"h has shape"),
    (dict(h=-_good()), r"depth h\[0, 0\] = -1 m is not positive; .*negative depth is invalid"),
    (dict(h=0 * _good()), r"not positive; dry cells are not supported"),
    (dict(h=np.where(np.eye(NY, NX) > 0, np.nan, 1.0)), r"h is not finite at \[j, i\]"),
    (dict(h=_good(), u=np.full((NY, NX), np.inf)), r"u is not finite"),
    (dict(h=_good(), bed=np.full((NY, NX), np.nan)), r"bed is not finite"),
    (dict(h=_good(), v=np.ones((3, 3))), r"v has shape"),
    (dict(h=_good().astype(complex)), r"h must be real numbers"),
    (dict(h=np.full((NY, NX), "a")), r"h must be real numbers"),
    (dict(h=np.where(np.eye(NY, NX) > 0, 1e-4, 1.0)), r"below min_depth=0.01 m"),
    (dict(h=_good(), u=np.full((NY, NX), 4.0)), r"Froude number 1.28 .* exceeds max_froude=1"),
])
def test_set_state_errors_are_one_line(sim, state, match):
    before = sim.populations()
    with pytest.raises(ValueError, match=match) as exc:
        sim.set_state(**state)
    _one_line(exc)
    np.testing.assert_array_equal(sim.populations(), before)   # nothing changed


@pytest.mark.parametrize("call, match", [
    (lambda s: s.step(-1), r"step: n=-1 must be an integer >= 0"),
    (lambda s: s.step(1.5), r"step: n=1.5 must be an integer"),
    (lambda s: s.add_drop(5.0, 0.1, 0.1, 0.1), r"add_drop: point \(5, 0.1\) m is outside the box"),
    (lambda s: s.add_drop(0.1, 0.1, 0.01, 0.1), r"add_drop: radius=0.01 m is below half a cell"),
    (lambda s: s.add_drop(0.1, 0.1, 0.1, np.nan), r"add_drop: height=nan must be finite"),
    (lambda s: s.add_drop(0.1, "y", 0.1, 0.1), r"add_drop: y='y' must be a number"),
    (lambda s: s.push(0.1, 0.1, 0.1, 0.0, np.inf), r"push: strength=inf must be finite"),
    (lambda s: s.push(0.1, 0.1, np.nan, 0.0, 1.0), r"push: dx=nan must be finite"),
    (lambda s: s.set_rain(-1.0, 0.1, 0.01, 0), r"set_rain: rate=-1 must be >= 0"),
    (lambda s: s.set_rain(1.0, 0.1, 0.01, -3), r"set_rain: seed=-3 must be an integer >= 0"),
    (lambda s: s.set_rain(1.0, 0.0, 0.01, 1), r"set_rain: radius=0.0 m is below half a cell"),
    (lambda s: s.write_surface(np.zeros(4)), r"write_surface: vertices_buf must be a pyopencl "
                                             r"Buffer, got ndarray"),
    (lambda s: s.write_surface(s.rt.buffer(16)), r"vertices_buf holds 16 bytes; needs 1920"),
    (lambda s: s.write_surface(s.rt.buffer(1920), s.rt.buffer(8)), r"normals_buf holds 8"),
    (lambda s: s.write_surface(s.rt.buffer(1920), origin=(0, 1)), r"origin=\(0, 1\) must be"),
    (lambda s: s.write_surface(s.rt.buffer(1920), origin=(0, 1, np.nan)), r"three finite"),
])
def test_method_errors_are_one_line(sim, call, match):
    with pytest.raises(ValueError, match=match) as exc:
        call(sim)
    _one_line(exc)


def test_zero_length_push_does_nothing(sim):
    before = sim.populations()
    sim.push(0.2, 0.2, 0.0, 0.0, 5.0)
    np.testing.assert_array_equal(sim.populations(), before)


def test_rain_rate_zero_stops_rain(sim):
    sim.set_rain(500.0, 0.05, 0.02, 1)
    sim.set_rain(0.0, 0.05, 0.02, 1)
    m0 = sim.stats()["mass"]
    sim.step(30)
    assert sim.stats()["mass"] == pytest.approx(m0, rel=1e-6)


@pytest.mark.parametrize("nx, ny", [(1, 4), (3, 0), (2.0, 3)])
def test_grid_triangles_rejects_bad_sizes(nx, ny):
    with pytest.raises(ValueError, match="grid_triangles"):
        lbm.grid_triangles(nx, ny)


def test_lattice_speed_option_fixes_e(rt):
    sim = lbm.ShallowWater(NX, NY, DX, device=rt, lattice_speed=12.0, viscosity=1e-3)
    assert sim.e == 12.0 and sim.dt == pytest.approx(DX / 12.0)
    assert sim.tau == pytest.approx(0.5 + 3 * 1e-3 / (12.0 * DX))
    assert math.isclose(sim.lattice.g_lat, 9.81 / 144.0)
