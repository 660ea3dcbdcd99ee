"""lbm_step2 (two time steps in one launch, kernels/lbm_step.cl) against two lbm_step launches:
the same populations, depths and damping marks bit for bit and the same guard counts, for every
build (walls, bed, guard, storage), on grids that are no multiple of the tile, with the limiter
clipping cells; and the step loop's grouping around rain drops and guard checks."""

import numpy as np
import pytest

import lbm
from lbm import reference as ref
from lbm.solver import STEP2_TILE, Storage, step2_local_bytes

DX = 0.05


def _state(nx, ny, seed, bed_on):
    """Waves over an optional bed with a few cells the limiter must clip."""
    rng = np.random.default_rng(seed)
    jj, ii = np.mgrid[0:ny, 0:nx]
    bed = 0.2 * rng.random((ny, nx)) if bed_on else None
    h = 1.0 - (0 if bed is None else bed) + 0.05 * np.sin(ii / 2.0) * np.cos(jj / 3.0)
    u = 0.3 * rng.standard_normal((ny, nx))
    v = 0.3 * rng.standard_normal((ny, nx))
    u[ny // 2, nx // 3] = v[ny // 3, nx // 2] = 40.0      # 40: the lattice speed (_load)
    u[0, nx - 1] = v[ny - 1, 0] = -40.0                   # in corners, at two walls
    return h, u, v, bed


def _load(sim, h, u, v, bed):
    """The state, then populations at the equilibrium of (h, u, v), the violent cells too (a
    state set_state would refuse)."""
    sim.set_state(h, 0 * u, 0 * v, bed)
    lat = sim.lattice
    sim._load_populations(ref.feq_si(h, u * lat.e / 40, v * lat.e / 40, lat.gravity, lat.e))


def _sim(rt, nx, ny, steps_per_launch, **kw):
    return lbm.ShallowWater(nx, ny, DX, device=rt, steps_per_launch=steps_per_launch,
                            viscosity=2e-3, drag=1.0, **kw)


def _spy(sim):
    """Record, per launch, whether it was an lbm_step2 (two steps)."""
    calls, launch = [], sim._enqueue_step

    def spy(two=False):
        calls.append(two)
        return launch(two)

    sim._enqueue_step = spy
    return calls


def _raw_state(sim):
    """Populations, depths and marks as stored (bits), and the guard's integer counters."""
    rt, n = sim.rt, sim.n_cells
    words = np.uint16 if sim.storage is Storage.FP16S else np.uint32
    g = sim.guard_record()
    return dict(f=rt.to_host(sim.populations_buffer, words, 9 * n),
                h=rt.to_host(sim._h.current, np.uint32, n),
                mark=rt.to_host(sim._mark.current, np.uint8, n),
                counts=[int(g[k]) for k in ("clamped", "checks", "nan_cells", "restored")],
                volumes=[float(g[k]) for k in ("clipped", "created", "mass")])


def _assert_same(a, b, bed_on=True):
    """The same state; the depth buffer holds the state only where the step reads it (bed)."""
    for key in ("f", "mark") + (("h",) if bed_on else ()):
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert a["counts"] == b["counts"]
    np.testing.assert_allclose(a["volumes"], b["volumes"], rtol=1e-6)


BUILDS = [  # boundary, bed, guard, storage
    ("slip", False, True, "fp32"),
    ("slip", True, True, "fp32"),
    ("noslip", False, True, "fp32"),
    ("noslip", True, True, "fp32"),
    ("slip", True, False, "fp32"),
    ("noslip", True, True, "fp16s"),
    ("slip", False, False, "fp16s"),
]


@pytest.mark.parametrize("boundary, bed_on, guard, storage", BUILDS,
                         ids=["-".join(map(str, b)) for b in BUILDS])
def test_two_steps_per_launch_equal_two_launches(rt, boundary, bed_on, guard, storage):
    nx, ny = STEP2_TILE[0] + 13, 2 * STEP2_TILE[1] + 5    # partial tiles on both axes
    h, u, v, bed = _state(nx, ny, 3 + bed_on, bed_on)
    sims = [_sim(rt, nx, ny, k, boundary=boundary, guard=guard, storage=storage,
                 guard_interval=10**6) for k in (1, 2)]
    for sim in sims:
        _load(sim, h, u, v, bed)
    calls = _spy(sims[1])
    states = []
    for n in (5, 6):       # odd: pairs and one single launch
        for sim in sims:
            sim.step(n)
        states.append(_raw_state(sims[1]))
        _assert_same(_raw_state(sims[0]), states[-1], bed_on)
    assert calls == [True, True, False, True, True, True]
    if guard:   # the limiter clipped and its marks spread: the halo's marks were exercised
        assert states[0]["counts"][0] > 0
        assert (states[0]["mark"] > 0).sum() >= 4
    assert sims[1].steps == sims[0].steps == 11


def test_step_loop_groups_around_drops_and_checks(rt):
    """Rain drops due between two steps and guard checks every 5 steps split the pairs, so
    the state equals the one-step loop's."""
    nx, ny = 50, 30
    h, u, v, _ = _state(nx, ny, 9, False)
    sims = [_sim(rt, nx, ny, k, guard_interval=5) for k in (1, 2)]
    for sim in sims:
        _load(sim, h, u, v, None)
        sim.set_rain(400.0 / sim.dt / 1e4, 0.1, 0.01, seed=5)   # a drop every ~25 steps
    calls = _spy(sims[1])
    for sim in sims:
        sim.step(60)
    _assert_same(_raw_state(sims[0]), _raw_state(sims[1]), False)
    assert sims[1].steps == 60 and sum(1 + c for c in calls) == 60
    assert 0 < calls.count(False) < len(calls)
    assert sims[1].stats()["volume_sources"] > 0     # drops fell


def test_step_hooks_run_every_step(rt):
    """A step hook sees every step; steps are paired only where every hook says its coming
    call only counts (quiet_steps)."""
    sim = _sim(rt, 40, 20, 2)
    sim.set_state(np.full((20, 40), 0.5))
    calls, seen, quiet = _spy(sim), [], [0]
    sim.add_step_hook(seen.append)
    sim.step(6)
    assert calls == [False] * 6 and len(seen) == 6
    sim.remove_step_hook(seen.append)
    sim.add_step_hook(seen.append, lambda: quiet[0])
    sim.step(2)
    quiet[0] = 1
    sim.step(4)
    assert calls[6:] == [False, False, True, True] and len(seen) == 12
    sim.remove_step_hook(seen.append)
    sim.step(6)
    assert calls[10:] == [True] * 3 and len(seen) == 12


def test_coupled_boats_see_the_same_water(rt):
    """Boats updated every 3 water steps (a hook that acts on every third call): pairs run
    between their updates, and water, boats and transform rows are the bytes of one step per
    launch."""
    from lbm.bodies import Boats, BoatSpec
    from tests.lbm import bodies_ref as br

    out = []
    for spl in (1, 2):
        sim = br.pool(rt, dx=0.05, size=(2.0, 1.0), drag=0.0, steps_per_launch=spl)
        spec = BoatSpec(*br.box(0.5, 0.3, 0.3), mass=12.0, position=(0.6, 0.52, 0.5),
                        mass_height=0.08)
        rows = rt.buffer(48)
        boats = Boats(sim, [spec], rows, [0], max_substep=3 * sim.dt * (1 + 1e-6))
        boats.set_velocity(0, (2.0, 0.0, 0.3))
        calls = _spy(sim)
        sim.step(20)
        out.append((sim.populations().tobytes(), boats.state().tobytes(),
                    rt.to_host(rows, np.float32, 12).tobytes()))
    assert boats.every == 3 and True in calls and False in calls
    assert out[0] == out[1]


def test_steps_per_launch_option(rt):
    """1 or 2; by default two steps per launch on a GPU over an uneven bed only."""
    with pytest.raises(ValueError, match=r"steps_per_launch=3 is out of range; allowed \[1, 2\]"):
        _sim(rt, 16, 16, 3)
    sim = lbm.ShallowWater(16, 16, DX, device=rt)
    assert sim.steps_per_launch == 1
    sim.set_state(np.full((16, 16), 0.8), bed=np.full((16, 16), 0.1) + np.eye(16) * 0.05)
    assert sim.steps_per_launch == (2 if rt.is_gpu else 1)
    assert _sim(rt, 16, 16, 2).steps_per_launch == 2
    need = step2_local_bytes(Storage.FP32, True, True)
    assert need == (36 * 12 + 34 * 10) * (36 + 8 + 1)
    assert need <= 48 * 1024    # fits the local memory of NVIDIA's OpenCL work-groups
