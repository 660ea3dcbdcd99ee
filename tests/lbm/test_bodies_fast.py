"""The bodies stage's cost structure on PoCL at small sizes: one launch per update for all
boats and all substeps, whose pressure pass covers the hulls' boxes only (equal to the
whole-grid pass, and to a float64 NumPy reference), substeps against a float64 reference, the
same bytes on a rerun, and coupled updates every k water steps (k dt <= max_substep) that behave
as updates after every step."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from lbm import bodies as lb
from lbm.bodies import Boats, BoatSpec
from tests.lbm import bodies_ref as br


def _rot(yaw=0.0, roll=0.0):
    c, s = math.cos(yaw), math.sin(yaw)
    Ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    c, s = math.cos(roll), math.sin(roll)
    Rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return Rx @ Ry


def test_header_constants_match_the_host():
    text = (Path(lb.__file__).parents[1] / "kernels" / "lbm_bodies.h").read_text()
    defs = dict(re.findall(r"#define (LBM_\w+) (\d+)", text))
    assert int(defs["LBM_BODY_WG"]) == lb.BODY_WG
    assert int(defs["LBM_PRESS_BATCH"]) == lb.PRESS_BATCH
    assert int(defs["LBM_MAX_BODIES"]) == lb.MAX_BOATS
    assert int(defs["LBM_BODY_MAX_SPEED"]) == lb.MAX_SPEED


def _three_boats(rt, sim, coupled=False, origin=(0.0, 0.0, 0.0)):
    """A tilted box, a turned box and a sphere, floating near their drafts."""
    oy = origin[1]
    specs = [
        BoatSpec(*br.box(0.6, 0.3, 0.4), mass=20.0, position=(0.55, oy + 0.52, 0.5),
                 rotation=_rot(0.5, 0.15), mass_height=0.1),
        BoatSpec(*br.box(0.5, 0.3, 0.3), mass=12.0, position=(1.3, oy + 0.52, 0.55),
                 rotation=_rot(1.0), mass_height=0.08),
        BoatSpec(*br.icosphere(0.2), density=500.0, position=(1.0, oy + 0.6, 1.1),
                 mass_height=0.1),
    ]
    specs = [BoatSpec(s.vertices, s.faces, mass=s.mass, density=s.density,
                      position=np.add(s.position, (origin[0], 0.0, origin[2])),
                      rotation=s.rotation, mass_height=s.mass_height) for s in specs]
    return Boats(sim, specs, rt.buffer(48 * 3), [0, 1, 2], origin=origin, coupled=coupled)


def _check_head(sim, boats, origin):
    st = boats.state()
    ref, unsure = br.pressure_head(sim, [br.body64(r) for r in st],
                                   [boats.hull(i) for i in range(len(st))], origin)
    got = boats.pressure_head().astype(np.float64)
    assert unsure.mean() < 0.03
    assert ref.max() > 0.05 and (ref > 0).sum() > 60          # three real depressions
    np.testing.assert_allclose(got[~unsure], ref[~unsure], rtol=0, atol=2e-5)


def test_pressure_head_matches_float64(rt):
    """The hulls' pressure head of three hulls (tilted, turned, a sphere; bodies off the grid's
    origin) equals the float64 NumPy reference, after the whole-grid pass (construction) and
    after box passes that follow the bodies as they move."""
    origin = (0.3, -0.1, 0.2)
    sim = br.pool(rt, dx=0.05, size=(2.0, 1.5))
    boats = _three_boats(rt, sim, origin=origin)
    _check_head(sim, boats, origin)
    boats.set_velocity(0, (0.8, 0.0, 0.3))
    for _ in range(4):
        boats.enqueue_step(0.04)
    assert boats.poses()[0][0, 0] > 0.55 + origin[0] + 0.1     # it moved 2+ cells
    _check_head(sim, boats, origin)


def test_box_pass_equals_the_whole_grid_pass_as_boats_move(rt):
    """Coupled water steps with a boat thrown at a wall, a rocking tilted boat, one dropped
    elsewhere (place) and two with overlapping boxes: after every update the box pass left the
    same pressure head as a whole-grid pass (the cells a hull left are restored; overlaps
    written once), while the boxes cover a fraction of the grid."""
    sim = br.pool(rt, dx=0.05, size=(2.0, 1.5), drag=0.0)
    boats = _three_boats(rt, sim, coupled=True)
    boats.set_velocity(0, (2.5, 0.0, 0.4))
    n = sim.nx * sim.ny
    boxes = []
    for i in range(40):
        if i == 10:
            boats.place(1, (0.45, 0.6, 1.15))    # the window's B key: far from where it was
        sim.step(1)
        got = boats.pressure_head()
        boats.enqueue_press()
        want = boats.pressure_head()
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
        st = boats.state()
        boxes.append(st["box"].copy())
    b = np.array(boxes)
    area = (b[..., 2] - b[..., 0] + 1) * (b[..., 3] - b[..., 1] + 1)
    assert area.max() < n / 3
    assert b[-1, 0, 2] == sim.nx - 1 and np.ptp(b[:, 0, 0]) >= 8      # boat 0 crossed to the wall
    assert (b[:, 1, 2] >= b[:, 2, 0]).any()                       # boxes 1 and 2 overlap


def test_substeps_in_one_launch_match_float64(rt):
    """Three substeps of a tilted, moving hull on uneven, moving water, in one launch, equal
    three float64 substeps (forces re-summed at each pose against the same water)."""
    sim = br.uneven_water(rt)
    origin = (0.3, -0.1, 0.2)
    spec = BoatSpec(*br.box(0.6, 0.3, 0.4), mass=20.0, position=(1.1, 0.3, 1.0),
                    rotation=_rot(0.2, 0.2), mass_height=0.1)
    boats = Boats(sim, [spec], rt.buffer(48), [0], origin=origin, coupled=False,
                  max_substep=0.01)
    boats.set_velocity(0, (0.3, -0.2, 0.1))
    zforce = boats.pressure_head() + sim.fields()["bed"]
    sample = br.water_sampler(sim, zforce, sim.populations(), origin)
    start = br.body64(boats.state()[0])

    def reference(rot_damping=1.0):
        ref = {k: v.copy() for k, v in start.items()}
        ref["damping"][2] *= rot_damping
        for _ in range(3):
            F, T, V = br.forces(ref, boats.hull(0), sample)
            ref = br.substep(ref, F, T, V, 0.01)
        return ref

    ref = reference()
    boats.enqueue_step(0.03)
    got = br.body64(boats.state()[0])
    # the quaternion's components are ~1 and each float32 operation rounds them by up to
    # 2**-24 relative (the GPU contracts to FMA, PoCL may not): 8 ulps of |q| = 1, far below
    # the change checked (and below a 10% change in rotation damping: asserted below)
    tols = {"pos": 1e-7, "vel": 1e-6, "omega": 2e-6, "quat": 8 * 2.0**-24}
    for key, tol in tols.items():
        change, want = got[key] - start[key], ref[key] - start[key]
        assert np.abs(want).max() > 100 * tol, key                 # it really moved
        np.testing.assert_allclose(change, want, rtol=1e-4, atol=tol, err_msg=key)
    # the tolerances could fail: 10% more rotation damping moves omega and quat beyond them
    off = reference(1.1)
    for key in ("omega", "quat"):
        err = np.abs((off[key] - start[key]) - (ref[key] - start[key]))
        assert err.max() > 3 * (tols[key] + 1e-4 * np.abs(ref[key] - start[key]).max()), key
    np.testing.assert_allclose(got["force"], ref["force"], rtol=1e-5, atol=1e-3)
    np.testing.assert_allclose(got["torque"][:3], ref["torque"][:3], rtol=1e-4, atol=1e-4)


def _spy(monkeypatch):
    import pyopencl as cl

    calls = []
    enqueue = cl.enqueue_nd_range_kernel

    def spy(queue, kernel, global_size, *args, **kw):
        calls.append((kernel.function_name, tuple(int(g) for g in global_size)))
        return enqueue(queue, kernel, global_size, *args, **kw)

    monkeypatch.setattr(cl, "enqueue_nd_range_kernel", spy)
    return calls


@pytest.mark.parametrize("n_boats", [1, 4])
def test_launches_per_update_do_not_grow_with_boats(rt, monkeypatch, n_boats):
    """Coupled to 12 water steps with max_substep = 3 dt: 4 updates of exactly one launch (all
    boats, all substeps, the pressure pass in one) of one work-group per boat, whatever the
    number of boats; five substeps are one launch."""
    sim = br.pool(rt, dx=0.025, size=(3.0, 2.0))
    V, F = br.box(0.3, 0.15, 0.2)
    specs = [BoatSpec(V, F, mass=3.0, position=(0.6 + 0.6 * k, 0.5, 1.0), mass_height=0.05)
             for k in range(n_boats)]
    boats = Boats(sim, specs, rt.buffer(48 * n_boats), list(range(n_boats)),
                  max_substep=3 * sim.dt * (1 + 1e-6))
    assert boats.every == 3
    calls = _spy(monkeypatch)
    sim.step(12)
    ours = [c for c in calls if c[0].startswith("lbm_bodies")]
    assert [c[0] for c in ours] == ["lbm_bodies_update"] * 4
    assert all(c[1] == (n_boats * boats.groups_per_boat(3 * sim.dt) * lb.BODY_WG,) for c in ours)
    calls.clear()
    boats.enqueue_step(5 * boats.max_substep)
    assert [c[0] for c in calls] == ["lbm_bodies_update"]


def _settle(rt, dx, k, seconds=8.0):
    """A 0.5 x 0.3 x 0.3 m box of 15 kg released 3 cm above its draft in a 1.5 x 1.0 m pool,
    its updates every k water steps: heave every 26 ms, |heave speed| in its last 2 s, final
    draft, relative volume change."""
    sim = br.pool(rt, dx=dx, size=(1.5, 1.0))
    spec = BoatSpec(*br.box(0.5, 0.3, 0.3), mass=15.0, position=(0.75, 0.58, 0.5),
                    mass_height=0.05)
    boats = Boats(sim, [spec], rt.buffer(48), [0], max_substep=k * sim.dt * (1 + 1e-6))
    assert boats.every == k
    v0 = sim.stats()["volume"]
    m = round(0.026 / sim.dt)
    ys, vs = [], []
    for _ in range(round(seconds / (m * sim.dt))):
        sim.step(m)
        ys.append(boats.poses()[0][0, 1])
        vs.append(boats.velocities()[0][0, 1])
    tail = np.abs(vs[-round(2.0 / (m * sim.dt)):]).max()
    draft = boats.state()["torque"][0, 3] - (ys[-1] - 0.05)
    return np.array(ys), tail, draft, sim.stats()["volume"] / v0 - 1


def test_coupling_depends_on_the_held_time_not_the_steps(rt):
    """Boats updated every k water steps hold the hulls' pressure k dt: the coupling's quality
    is set by that time, not by k. Measured (2026-12-01): the same 13 ms hold on a grid of
    5 cm (every step) and of 2.5 cm (every 2 steps) settles alike; on the 2.5 cm grid a 6.5 ms
    hold (every step) settles faster and heaves within 1 cm of the 13 ms one. All settle at the
    Archimedes draft 0.1 m (5%) and keep the water's volume (1e-6). The coarse tests above hold
    26 ms (dt at 10 cm); the default max_substep holds at most 8.3 ms."""
    coarse = _settle(rt, 0.05, 1)
    fine1 = _settle(rt, 0.025, 1)
    fine2 = _settle(rt, 0.025, 2)
    for ys, _, draft, dv in (coarse, fine1, fine2):
        assert ys.max() - ys.min() > 0.02                      # it fell in and bobbed
        assert draft == pytest.approx(0.1, rel=0.05)
        assert abs(dv) < 1e-6
    assert fine2[1] == pytest.approx(coarse[1], rel=0.25)      # same hold, same settling
    assert fine1[1] < 0.8 * fine2[1]                            # half the hold settles faster
    assert np.abs(fine1[0] - fine2[0]).max() < 0.01


def _circle_box(sim, origin, x, z, r):
    """kernels/lbm_bodies.cl lbm_body_box: the cells of a bounding circle, one cell of margin."""
    g = [(x - r - origin[0]) / sim.dx - 0.5, (z - r - origin[2]) / sim.dx - 0.5,
         (x + r - origin[0]) / sim.dx - 0.5, (z + r - origin[2]) / sim.dx - 0.5]
    b = [math.floor(g[0]) - 1, math.floor(g[1]) - 1, math.ceil(g[2]) + 1, math.ceil(g[3]) + 1]
    return np.clip(b, 0, [sim.nx - 1, sim.ny - 1, sim.nx - 1, sim.ny - 1])


def test_press_box_follows_the_footprint_not_the_circle(rt):
    """Long thin hulls (6:1) straight, turned 30 degrees and tilted: the box the step sets holds
    every cell the hull presses (the box pass equals the whole-grid pass) and, for the straight
    and the turned hull, fewer cells than the bounding circle's box (0.3 and 0.8 of it)."""
    origin = (0.2, -0.05, 0.1)
    sim = br.pool(rt, dx=0.025, size=(3.0, 2.0))
    V, F = br.box(0.9, 0.15, 0.15)
    poses = [((1.0, 0.5, 0.5), _rot(0.0)), ((2.0, 0.5, 0.7), _rot(math.pi / 6)),
             ((1.2, 0.5, 1.4), _rot(0.3, 0.35))]
    specs = [BoatSpec(V, F, mass=8.0, position=np.add(p, origin), rotation=R, mass_height=0.04)
             for p, R in poses]
    boats = Boats(sim, specs, rt.buffer(48 * 3), [0, 1, 2], origin=origin, coupled=False)
    boats.set_velocity(2, (0.3, 0.0, -0.2))
    for _ in range(3):
        boats.enqueue_step(sim.dt)
        got = boats.pressure_head()
        boats.enqueue_press()
        want = boats.pressure_head()
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    st = boats.state()
    head = boats.pressure_head()
    assert (head > 0).sum() > 400 and head.max() > 0.03              # three real hulls
    for k, r in enumerate(st):
        box = r["box"]
        area = (box[2] - box[0] + 1) * (box[3] - box[1] + 1)
        cb = _circle_box(sim, origin, r["pos"][0], r["pos"][2], r["damping"][3])
        circle = (cb[2] - cb[0] + 1) * (cb[3] - cb[1] + 1)
        assert np.all(box[:2] >= cb[:2]) and np.all(box[2:] <= cb[2:])
        if k < 2:   # straight: a quarter; turned 30 degrees: 3/4 (a rectangle's corners)
            assert area < (0.3, 0.8)[k] * circle, (k, area, circle)


def test_speed_limit_matches_float64(rt):
    """A boat thrown at 30 m/s horizontally (and 12 m/s down) moves at the horizontal speed
    limit, 5 m/s, as the float64 substep with that limit; the vertical speed is not limited."""
    sim = br.pool(rt, dx=0.1, size=(3.0, 2.0))
    spec = BoatSpec(*br.box(0.6, 0.3, 0.4), mass=20.0, position=(1.5, 0.52, 1.0),
                    mass_height=0.1)
    boats = Boats(sim, [spec], rt.buffer(48), [0], coupled=False)
    boats.set_velocity(0, (24.0, -12.0, 18.0))
    zforce = boats.pressure_head() + sim.fields()["bed"]
    sample = br.water_sampler(sim, zforce, sim.populations(), (0.0, 0.0, 0.0))
    start = br.body64(boats.state()[0])
    F, T, V = br.forces(start, boats.hull(0), sample)
    ref = br.substep(start, F, T, V, 0.005, max_speed=5.0)
    boats.enqueue_step(0.005)
    got = br.body64(boats.state()[0])
    assert math.hypot(got["vel"][0], got["vel"][2]) == pytest.approx(5.0, rel=1e-6)
    assert got["vel"][1] < -11.0
    np.testing.assert_allclose(got["vel"][:3], ref["vel"][:3], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(got["pos"][:3] - start["pos"][:3],
                               ref["pos"][:3] - start["pos"][:3], rtol=1e-5, atol=1e-7)


def test_updates_are_the_same_bytes_on_a_rerun(rt):
    """One boat alone (its own work-group) and two whose boxes overlap (one work-group for both,
    a cluster), coupled for 30 water steps with the lone one thrown across the pool: records,
    transform rows, pressure head and water are the same bytes on a rerun, and the box pass
    left what a whole-grid pass leaves."""
    def once():
        sim = br.pool(rt, dx=0.05, size=(4.0, 1.5), drag=0.0)
        V, F = br.box(0.5, 0.3, 0.3)
        specs = [BoatSpec(V, F, mass=12.0, position=p, mass_height=0.08)
                 for p in ((0.6, 0.52, 0.75), (3.0, 0.52, 0.6), (3.2, 0.52, 0.95))]
        T = rt.buffer(48 * 3)
        boats = Boats(sim, specs, T, [0, 1, 2])
        boats.set_velocity(0, (3.0, 0.0, 0.2))
        boats.set_velocity(2, (-0.5, 0.0, 0.0))
        sim.step(30)
        st = boats.state()
        head = boats.pressure_head()
        boats.enqueue_press()
        np.testing.assert_allclose(head, boats.pressure_head(), rtol=0, atol=1e-6)
        assert (st["box"][1, 2] >= st["box"][2, 0]) and st["pos"][0, 0] > 1.2
        return (st.tobytes(), rt.to_host(T, np.float32, 36).tobytes(), head.tobytes(),
                sim.populations().tobytes())

    assert once() == once()


def test_several_groups_per_boat_press_what_one_group_and_the_whole_grid_do(rt):
    """A lone boat thrown across the pool and two whose boxes overlap (a cluster), on a grid
    fine enough that a boat presses over 512 cells, updated by 3 work-groups per boat (each
    recomputes the cluster's update, then presses its tile): after every update the pressure
    head is the bytes the whole-grid pass leaves, and records, transform rows and pressure head
    are the bytes that one work-group per boat leaves, on a rerun too, whatever the press pass's
    batch of cells per work-item (a lone boat's and the cluster's code paths)."""
    def once(groups, press_batch=lb.PRESS_BATCH):
        sim = br.pool(rt, dx=0.02, size=(2.4, 1.2), drag=0.0)
        V, F = br.box(0.5, 0.3, 0.3)
        specs = [BoatSpec(V, F, mass=12.0, position=p, mass_height=0.08, rotation=_rot(r))
                 for p, r in (((0.6, 0.52, 0.6), 0.3), ((1.65, 0.52, 0.45), 0.0),
                              ((1.85, 0.52, 0.8), 0.5))]
        T = rt.buffer(48 * 3)
        boats = Boats(sim, specs, T, [0, 1, 2], coupled=False, press_batch=press_batch)
        boats.press_groups = groups
        boats.set_velocity(0, (3.0, 0.0, 0.4))
        boats.set_velocity(2, (-0.5, 0.0, 0.0))
        heads = []
        for _ in range(4):
            sim.step(2)
            boats.enqueue_step(2 * sim.dt)
            head = boats.pressure_head()
            boats.enqueue_press()
            assert head.tobytes() == boats.pressure_head().tobytes()
            heads.append(head.tobytes())
        st = boats.state()
        box = np.minimum(st["box"][:, :2], st["box_old"][:, :2])
        box_hi = np.maximum(st["box"][:, 2:], st["box_old"][:, 2:])
        area = np.prod(box_hi - box + 1, axis=1)
        assert area.min() > lb.BODY_WG                        # every boat's pass spans 2+ tiles
        assert st["box"][1, 2] >= st["box"][2, 0] and st["pos"][0, 0] > 0.65   # overlap; moved
        return st.tobytes(), rt.to_host(T, np.float32, 36).tobytes(), heads

    one = once(1)
    assert once(3) == one
    assert once(3) == one
    assert once(3, press_batch=1) == one
    assert once(2, press_batch=8) == one
    sim = br.pool(rt, dx=0.05, size=(2.0, 1.5), drag=0.0)
    with pytest.raises(ValueError, match="press_batch=3; allowed 1, 2, 4, 8"):
        Boats(sim, [], rt.buffer(48), [], press_batch=3)


def test_work_group_size_changes_only_the_reduction_order(rt):
    """Boats(work_group=...) (bench/bodies_stage.py --work-group): the same update within float32
    round-off of the sums' order; a size the kernel cannot take is a one-line ValueError."""
    def run(wg):
        sim = br.pool(rt, dx=0.05, size=(2.0, 1.5), drag=0.0)
        V, F = br.box(0.5, 0.3, 0.3)
        boats = Boats(sim, [BoatSpec(V, F, mass=12.0, position=(0.8, 0.55, 0.7),
                                     mass_height=0.08)],
                      rt.buffer(48), [0], work_group=wg)
        assert boats.work_group == wg
        boats.set_velocity(0, (0.5, 0.0, 0.1))
        sim.step(40)
        st = boats.state()
        return st["pos"][0, :3].copy(), st["vel"][0, :3].copy(), boats.pressure_head()

    pos, vel, head = run(512)
    for wg in (128, 1024):
        p, v, h = run(wg)
        np.testing.assert_allclose(p, pos, rtol=0, atol=1e-5)
        np.testing.assert_allclose(v, vel, rtol=0, atol=1e-4)
        np.testing.assert_allclose(h, head, rtol=0, atol=1e-5)
    sim = br.pool(rt, dx=0.05, size=(2.0, 1.5), drag=0.0)
    with pytest.raises(ValueError, match="work_group=300; allowed 128, 256, 512, 1024"):
        Boats(sim, [], rt.buffer(48), [], work_group=300)
