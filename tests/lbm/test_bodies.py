"""Floating boats (lbm.bodies, kernels/lbm_bodies.cl) on PoCL at small sizes: Archimedes, settling,
two-way coupling (a wake, waves rocking a boat), exact volume, finite poses, and the device's
force/torque reduction against a float64 NumPy reference."""

import math
from pathlib import Path

import numpy as np
import pytest

from lbm.bodies import Boats, BoatSpec, HullError, check_closed, matrix_from_quat, solid_properties
from tests.lbm.bodies_ref import (
    body64,
    box,
    forces,
    icosphere,
    pool,
    read_obj,
    run,
    uneven_water,
    water_sampler,
)

ROOT = Path(__file__).resolve().parents[2]


def test_solid_properties_of_a_box_are_analytic():
    V, F = box(1.0, 0.4, 0.5)
    check_closed(F)
    vol, c, inertia = solid_properties(V, F)
    assert vol == pytest.approx(0.2, rel=1e-12)
    np.testing.assert_allclose(c, (0, 0.2, 0), atol=1e-12)
    want = vol / 12 * np.array([0.4**2 + 0.5**2, 1.0 + 0.5**2, 1.0 + 0.4**2])
    np.testing.assert_allclose(np.diag(inertia), want, rtol=1e-12)


def test_open_or_heavy_hulls_are_refused(rt):
    sim = pool(rt)
    T = rt.buffer(48)
    V, F = box(1.0, 0.4, 0.5)
    with pytest.raises(HullError, match="not closed"):
        Boats(sim, [BoatSpec(V, F[:-1], mass=10.0, position=(1.5, 0.6, 1.0))], T, [0])
    with pytest.raises(HullError, match="sinks it"):
        Boats(sim, [BoatSpec(V, F, mass=250.0, position=(1.5, 0.6, 1.0))], T, [0])
    with pytest.raises(HullError, match="needs water deeper"):
        Boats(sim, [BoatSpec(*box(1.0, 1.0, 0.5), mass=250.0, position=(1.5, 0.6, 1.0))], T, [0])
    with pytest.raises(ValueError, match="exactly one of mass"):
        Boats(sim, [BoatSpec(V, F, position=(1.5, 0.6, 1.0))], T, [0])


def test_box_settles_at_archimedes_draft_and_stops(rt):
    """1.0 x 0.5 x 0.4 m, 100 kg (its mass centred 10 cm above the keel), released 5 cm above still
    water: settles at the draft 100 / (1000 x 0.5) = 0.2 m within 5% and moves < 1 mm/s
    within 20 s; the water's volume is unchanged (1e-6 relative)."""
    sim = pool(rt)
    T = rt.buffer(48 * 2)
    V, F = box(1.0, 0.4, 0.5)
    boats = Boats(sim, [BoatSpec(V, F, mass=100.0, position=(1.5, 0.55, 1.0),
                                 mass_height=0.1)], T, [1])
    v0 = sim.stats()["volume"]
    trace = list(run(sim, boats, 20.0, every=10))
    t, pos, speed = (np.array(a) for a in zip(*trace, strict=True))
    level = boats.state()["torque"][0, 3]       # the still-water level with the boat in it
    draft = level - (pos[:, 0, 1] - 0.1)          # the keel is 0.1 m below the centre of mass
    assert draft[-1] == pytest.approx(0.2, rel=0.05)
    assert speed[-1, 0] < 1e-3 and speed[t > 18.0, 0].max() < 1e-3
    assert draft.max() > 0.2                       # it did fall in and bob
    assert sim.stats()["volume"] == pytest.approx(v0, rel=1e-6)
    rows = rt.to_host(T, np.float32, 24).reshape(2, 3, 4)[1]   # row 1: world_from_mesh
    p, q = boats.poses()
    R = matrix_from_quat(q[0])
    np.testing.assert_allclose(rows[:, :3], R, atol=1e-6)
    np.testing.assert_allclose(rows[:, 3], p[0] + R @ [0, -0.1, 0], atol=1e-6)
    assert abs(R[1, 1]) > 0.9999   # upright


def test_sphere_settles(rt):
    """A sphere of radius 0.2 m at half the density of water (its mass centred 10 cm below its
    centre, so it stays upright) floats half submerged (8 cells across: the hull's depression
    must be resolved by the grid)."""
    sim = pool(rt, dx=0.05, size=(1.5, 1.5))
    V, F = icosphere(0.2)
    boats = Boats(sim, [BoatSpec(V, F, density=500.0, position=(0.75, 0.6, 0.75),
                                 mass_height=0.1)], rt.buffer(48), [0])
    vol = boats.hull(0).volume
    trace = list(run(sim, boats, 15.0, every=10))
    t, pos, speed = (np.array(a) for a in zip(*trace, strict=True))
    level = boats.state()["torque"][0, 3]
    centre = pos[-1, 0, 1] + 0.1
    assert centre == pytest.approx(level, abs=0.05 * 0.2)   # the centre at the water line
    assert speed[-1, 0] < 1e-3
    assert vol == pytest.approx(4 / 3 * math.pi * 0.2**3, rel=0.04)   # 320 flat triangles


def test_sailboat_settles(rt):
    """The pool scene's sailboat (its closed buoyancy proxy, 1.2 m long, 40 kg with its mass
    centred 5 cm above the keel: ballast) settles upright."""
    Vr, _ = read_obj(ROOT / "scenes/models/sailboat_15k.obj")
    V, F = read_obj(ROOT / "scenes/models/sailboat_15k_hull.obj")
    lo, hi = Vr.min(0), Vr.max(0)
    s = 1.2 / (hi - lo).max()
    c = (lo + hi) / 2
    c[1] = lo[1]
    base = np.hstack([s * np.eye(3), -s * c[:, None]])
    sim = pool(rt, size=(2.4, 2.0))
    boats = Boats(sim, [BoatSpec(V, F, mass=40.0, position=(1.2, 0.52, 1.0), base=base,
                                 mass_height=0.05)], rt.buffer(48), [0])
    trace = list(run(sim, boats, 15.0, every=10))
    t, pos, speed = (np.array(a) for a in zip(*trace, strict=True))
    _, q = boats.poses()
    up = matrix_from_quat(q[0])[:, 1]
    assert up[1] > 0.99                     # upright
    assert speed[-1, 0] < 2e-3
    st = boats.state()[0]
    assert st["force"][1] == pytest.approx(40.0 * 9.81, rel=0.02)   # buoyancy carries it



def _settled_box(rt, seconds=16.0):
    """The box of the Archimedes test, released 5 cm above the water, after ``seconds``."""
    sim = pool(rt)
    V, F = box(1.0, 0.4, 0.5)
    boats = Boats(sim, [BoatSpec(V, F, mass=100.0, position=(1.5, 0.55, 1.0), mass_height=0.1)],
                  rt.buffer(48), [0])
    for _ in run(sim, boats, seconds):
        pass
    return sim, boats


def test_moving_boat_leaves_a_wake_and_keeps_the_volume(rt):
    """A boat given 0.6 m/s along x on still water: behind it the water moves (a wake), the boat
    slows (it pays for the waves), and the volume changes < 1e-6."""
    sim = pool(rt, size=(4.0, 2.0), drag=0.0)
    V, F = box(0.6, 0.3, 0.3)
    boats = Boats(sim, [BoatSpec(V, F, mass=12.0, position=(1.0, 0.5, 1.0), mass_height=0.05)],
                  rt.buffer(48), [0])
    boats.set_velocity(0, (0.6, 0.0, 0.0))
    v0 = sim.stats()["volume"]
    for _ in run(sim, boats, 1.0):
        pass
    p, _ = boats.poses()
    v, _ = boats.velocities()
    f = sim.fields()
    x = (np.arange(sim.nx) + 0.5) * sim.dx
    speed = np.hypot(f["u"], f["v"])
    behind = speed[:, (x < p[0, 0] - 0.4) & (x > 0.3)]
    assert p[0, 0] > 1.3 and 0 < v[0, 0] < 0.6
    assert behind.max() > 1e-2                 # the wake
    assert sim.stats()["volume"] == pytest.approx(v0, rel=1e-6)


def test_wave_from_a_drop_rocks_a_boat_after_its_travel_time(rt):
    """A settled boat, a drop 1 m away: the heave and roll stay quiet until the wave can have
    arrived (1 m / sqrt(g h), less the hull's half width), then respond."""
    sim, boats = _settled_box(rt)
    p0, _ = boats.poses()
    v, w = boats.velocities()
    assert np.abs(v).max() < 2e-3 and np.abs(w).max() < 2e-3
    sim.add_drop(1.5, 0.0 + 2 * sim.dx, 0.25, 0.05)     # 1 m from the hull's centre (z)
    t0 = sim.time
    arrival = (1.0 - 2 * sim.dx - 0.25 - 0.25) / math.sqrt(9.81 * 0.5)
    quiet, moved = [], []
    for _ in range(int(2.0 / sim.dt)):
        sim.step(1)
        p, q = boats.poses()
        vv, ww = boats.velocities()
        dy = abs(p[0, 1] - p0[0, 1])
        (quiet if sim.time - t0 < 0.8 * arrival else moved).append((dy, np.abs(ww[0]).max(),
                                                                     abs(p[0, 2] - p0[0, 2])))
    quiet, moved = np.array(quiet), np.array(moved)
    assert moved[:, 0].max() > 1e-3 and moved[:, 0].max() > 10 * quiet[:, 0].max()   # heave
    assert moved[:, 1].max() > 1e-2 and moved[:, 1].max() > 10 * quiet[:, 1].max()   # roll


def test_many_frames_stay_finite(rt):
    """Coupled steps with drops and pushes around a boat: poses, transforms and water stay
    finite. 2,500 steps on CI (10 s on 2 cores); LBWATER_LONG_TESTS=1 runs the issue's 10,000
    (passed on PoCL, 42 s, 2026-12-01)."""
    import os

    chunks = 100 if os.environ.get("LBWATER_LONG_TESTS") == "1" else 25
    sim = pool(rt, dx=0.2, size=(2.4, 2.0), drag=0.0)
    V, F = box(0.8, 0.3, 0.4)
    T = rt.buffer(48)
    boats = Boats(sim, [BoatSpec(V, F, mass=30.0, position=(1.2, 0.55, 1.0), mass_height=0.08)],
                  T, [0])
    rng = np.random.default_rng(3)
    for k in range(chunks):
        sim.add_drop(*rng.uniform(0.2, 1.8, 2), 0.3, rng.uniform(-0.05, 0.05))
        sim.push(*rng.uniform(0.2, 1.8, 2), *rng.uniform(-0.3, 0.3, 2), 0.5)
        sim.step(100)
        if k % 5 == 0:
            assert np.isfinite(boats.state()["pos"]).all()
    p, q = boats.poses()
    assert np.isfinite(p).all() and np.isfinite(q).all() and sim.steps == 100 * chunks
    assert np.isfinite(rt.to_host(T, np.float32, 12)).all()
    assert all(np.isfinite(a).all() for a in sim.fields().values())
    assert 0.0 < p[0, 0] < 2.4 and 0.0 < p[0, 2] < 2.0


def test_force_torque_reduction_matches_float64(rt):
    """The device reduction over a tilted, moving hull on uneven, moving water equals the float64
    NumPy sum of the same column forces (N, N m) to float32 accuracy."""
    sim = uneven_water(rt)
    V, F = box(0.6, 0.3, 0.4)
    c, s = math.cos(0.2), math.sin(0.2)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ np.array([[c, 0, s], [0, 1, 0],
                                                                  [-s, 0, c]])
    origin = (0.3, -0.1, 0.2)
    boats = Boats(sim, [BoatSpec(V, F, mass=20.0, position=(1.1, 0.3, 1.0), rotation=R,
                                 mass_height=0.1)], rt.buffer(48), [0], origin=origin,
                  coupled=False)
    boats.set_velocity(0, (0.3, -0.2, 0.1))
    zforce = boats.pressure_head() + sim.fields()["bed"]
    sample = water_sampler(sim, zforce, sim.populations(), origin)
    F_ref, T_ref, V_ref = forces(body64(boats.state()[0]), boats.hull(0), sample)
    assert V_ref > 0.005 and abs(T_ref).max() > 1.0       # a real, lopsided load
    boats.enqueue_step(1e-6)
    st = boats.state()[0]
    np.testing.assert_allclose(st["force"][:3], F_ref, rtol=2e-4, atol=2e-3)
    np.testing.assert_allclose(st["torque"][:3], T_ref, rtol=2e-4, atol=2e-3)
    assert st["force"][3] == pytest.approx(V_ref, rel=2e-4)


def test_walls_stop_a_boat_and_boats_can_be_added_and_dropped(rt):
    """A boat thrown at 2 m/s towards the +x wall stops with its bounding circle inside; a second
    boat added later writes its own transform row; dropping the first leaves the second."""
    sim = pool(rt, size=(2.0, 1.5), drag=0.0)
    T = rt.buffer(48 * 3)
    V, F = box(0.6, 0.3, 0.3)
    boats = Boats(sim, [BoatSpec(V, F, mass=12.0, position=(1.0, 0.46, 0.75), mass_height=0.05,
                                 name="a")], T, [0])
    boats.set_velocity(0, (2.0, 0.0, 0.0))
    xs = np.array([pos[0, 0] for _, pos, _ in run(sim, boats, 1.5, k=1, every=1)])
    limit = 2.0 - boats.hull(0).radius
    assert xs.max() == pytest.approx(limit, abs=1e-4)    # it reached the wall ...
    assert (xs <= limit + 1e-4).all()                     # ... and never went through
    k = boats.add(BoatSpec(V, F, mass=12.0, position=(0.5, 0.46, 0.75), mass_height=0.05,
                           name="b"), 2)
    assert k == 1 and boats.names == ["a", "b"]
    for _ in run(sim, boats, 0.2):
        pass
    rows = rt.to_host(T, np.float32, 36).reshape(3, 3, 4)
    p, q = boats.poses()
    R = matrix_from_quat(q[1])
    np.testing.assert_allclose(rows[2, :, :3], R, atol=1e-5)
    np.testing.assert_allclose(rows[2, :, 3], p[1] + R @ [0, -0.05, 0], atol=1e-5)
    boats.drop(0)
    assert boats.names == ["b"] and boats.poses()[0].shape == (1, 3)
    for _ in run(sim, boats, 0.2):
        pass
    assert np.isfinite(boats.poses()[0]).all()


def test_boats_on_fp16s_water_match_fp32(rt):
    """The bodies kernels read the storage through lbm_load: a boat on fp16s water bobs as on
    fp32 water (heave within 1 mm after 2 s)."""
    ys = []
    for storage in ("fp32", "fp16s"):
        sim = pool(rt, storage=storage)
        V, F = box(1.0, 0.4, 0.5)
        boats = Boats(sim, [BoatSpec(V, F, mass=100.0, position=(1.5, 0.55, 1.0),
                                     mass_height=0.1)], rt.buffer(48), [0])
        for _ in run(sim, boats, 2.0):
            pass
        ys.append(boats.poses()[0][0, 1])
    assert ys[0] < 0.55 and ys[1] == pytest.approx(ys[0], abs=1e-3)
