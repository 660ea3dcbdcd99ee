"""Floating boats (lbm.bodies, kernels/lbm_bodies.cl) on PoCL at small sizes: Archimedes, settling,
two-way coupling (a wake, waves rocking a boat), exact volume, finite poses, and the device's
force/torque reduction against a float64 NumPy reference."""

import math
from pathlib import Path

import numpy as np
import pytest

import lbm
from lbm.bodies import Boats, BoatSpec, HullError, check_closed, matrix_from_quat, solid_properties

ROOT = Path(__file__).resolve().parents[2]


def box(lx, ly, lz):
    """A closed box [-lx/2, lx/2] x [0, ly] x [-lz/2, lz/2], outward triangles."""
    V = np.array([[x, y, z] for x in (-lx / 2, lx / 2) for y in (0, ly) for z in (-lz / 2, lz / 2)])
    F = np.array([(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7),
                  (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)])
    return V, F


def icosphere(r, levels=2):
    t = (1 + 5**0.5) / 2
    V = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    V = [np.array(v, float) / np.linalg.norm(v) for v in V]
    for _ in range(levels):
        mid, F2 = {}, []

        def m(a, b, mid=mid):
            key = (min(a, b), max(a, b))
            if key not in mid:
                v = V[a] + V[b]
                V.append(v / np.linalg.norm(v))
                mid[key] = len(V) - 1
            return mid[key]
        for a, b, c in F:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            F2 += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        F = F2
    return r * np.array(V), np.array(F)


def read_obj(path):
    V, F = [], []
    for line in Path(path).read_text().splitlines():
        if line.startswith("v "):
            V.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            F.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    return np.array(V), np.array(F)


def pool(rt, dx=0.1, size=(3.0, 2.0), depth=0.5, drag=1.0, **kw):
    nx, ny = round(size[0] / dx), round(size[1] / dx)
    return lbm.ShallowWater(nx, ny, dx, device=rt, depth=depth, viscosity=1e-3, drag=drag, **kw)


def run(sim, boats, seconds, k=4, every=None):
    """Frames of k water steps (each followed by a bodies step: the coupled boats' hook);
    yields (time, positions, speeds)."""
    frames = int(round(seconds / (k * sim.dt)))
    for i in range(frames):
        sim.step(k)
        if every and (i + 1) % every == 0:
            v, w = boats.velocities()
            yield sim.time, boats.poses()[0], np.abs(v).max(1)


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

