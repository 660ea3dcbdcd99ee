"""The shallow-water LBM solver on an OpenCL device (D2Q9 LABSWE, Zhou 2004, float32).

Host side of ``kernels/lbm_*.cl``. One :class:`ShallowWater` owns its device buffers (two
population buffers that ping-pong, the depth buffers the bed force reads, the bed, a checkpoint
and the guard record) and one kernel object per launch, looked up once. A frame is

    sim.step(k)          # k x lbm_step (+ rain drops), then one guard check; no host sync
    sim.write_surface(vertex_buf, normal_buf)   # two launches into the caller's buffers
    sim.stats()          # reads the 112-byte guard record: the only host traffic of a frame

See docs/lbm.md for units, the choice of e, dt and tau, the streaming scheme and the guard.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import pyopencl as cl

from kernels import Runtime, get_runtime
from lbm.lattice import GH_LIMIT, Lattice, Options, choose_lattice, equilibrium, equilibrium_f32
from lbm.limits import check_grid
from lbm.structs import GUARD_DTYPE, PARAMS_DTYPE, PARTIAL_DTYPE, SOURCE_DTYPE, record


class Boundary(IntEnum):
    """Walls of the closed box; values equal LBM_SLIP / LBM_NOSLIP in kernels/lbm.h."""

    SLIP = 0     # specular reflection: free slip along the wall
    NOSLIP = 1   # bounce-back: no slip

    @classmethod
    def from_str(cls, name) -> Boundary:
        if isinstance(name, cls):
            return name
        valid = ", ".join(m.name.lower() for m in cls)
        if not isinstance(name, str) or name.strip().upper() not in cls.__members__:
            raise ValueError(f"unknown boundary {name!r}; valid: {valid}")
        return cls[name.strip().upper()]


class Storage(IntEnum):
    """How populations are stored (kernels/lbm.h LBM_FP16S): float32, or float16 holding the
    deviation from the lake at rest (arithmetic stays float32; FluidX3D's FP16S idea)."""

    FP32 = 0
    FP16S = 1

    @classmethod
    def from_str(cls, name) -> Storage:
        if isinstance(name, cls):
            return name
        valid = ", ".join(m.name.lower() for m in cls)
        if not isinstance(name, str) or name.strip().upper() not in cls.__members__:
            raise ValueError(f"unknown storage {name!r}; valid: {valid}")
        return cls[name.strip().upper()]

    @property
    def bytes(self) -> int:
        """Bytes per stored population."""
        return 2 if self is Storage.FP16S else 4


#: lbm_step2's work-group (LBM_TILE_X x LBM_TILE_Y in kernels/lbm_step.cl): one tile of cells.
STEP2_TILE = (32, 8)


def step2_local_bytes(storage: Storage, bed: bool, guard: bool) -> int:
    """Local memory of one lbm_step2 work-group: its tile with a halo of two cells (the state
    loaded) and of one (the first step's state), each cell's populations, with ``bed`` its depth
    and bed, with ``guard`` its damping mark."""
    n0 = (STEP2_TILE[0] + 4) * (STEP2_TILE[1] + 4)
    n1 = (STEP2_TILE[0] + 2) * (STEP2_TILE[1] + 2)
    return (n0 + n1) * (9 * storage.bytes + 8 * bed + guard)


class GuardAction(IntEnum):
    """LBM_GUARD_* in kernels/lbm.h."""

    NONE = 0
    SAVE = 1
    RESTORE = 2


class SaveRequest(IntEnum):
    """LBM_SAVE_* in kernels/lbm.h: what a guard check may do with the checkpoint."""

    NO = 0
    IF_CLEAN = 1
    FORCE = 2


@dataclass
class PingPong:
    """Two buffers of one field: ``current`` holds the state, ``other`` receives the next."""

    current: cl.Buffer
    other: cl.Buffer

    def swap(self) -> None:
        self.current, self.other = self.other, self.current


@dataclass
class _Rain:
    rate: float      # drops per second
    radius: float    # m
    height: float    # m
    rng: np.random.Generator
    next_time: float  # s, when the next drop falls


def _finite(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{name}={value!r} must be a number")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{name}={value!r} must be finite")
    return x


class ShallowWater:
    """Shallow water in a closed box of ``nx`` x ``ny`` square cells of ``dx`` metres.

    The bed is flat at 0 and the water a lake at rest of depth ``options['depth']`` (1 m) until
    :meth:`set_state`. ``boundary``: ``"slip"`` (specular walls, the default) or ``"noslip"``
    (bounce-back). ``device``: None (default device), a device spec string, or a
    :class:`kernels.Runtime`. ``guard``: True (the limiter, local damping and checkpoint
    restores) or False (the plain scheme: NaN is detected and reported, nothing is limited or
    restored; for stability studies). ``storage``: ``"fp32"`` or ``"fp16s"`` (populations as
    float16 deviations from the lake at rest; half the memory traffic). Options (SI units) are
    those of :class:`lbm.lattice.Options`.
    Grid x (index i) is world x, grid y (index j) is world z; arrays are indexed [j, i].
    """

    def __init__(self, nx: int, ny: int, dx: float, boundary: str = "slip", device=None, *,
                 guard: bool = True, storage: str = "fp32", **options):
        for name, v in (("nx", nx), ("ny", ny)):
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or not 3 <= v <= 65536:
                raise ValueError(f"{name}={v!r} must be an integer in [3, 65536]")
        self.nx, self.ny = int(nx), int(ny)
        self._step_size = (self.nx, self.ny)
        self._step2_size = tuple(-(-v // t) * t
                                 for v, t in zip(self._step_size, STEP2_TILE, strict=True))
        self.dx = _finite("dx", dx)
        if self.dx <= 0:
            raise ValueError(f"dx={dx!r} must be > 0 (cell size in metres)")
        self.boundary = Boundary.from_str(boundary)
        if not isinstance(guard, bool):
            raise ValueError(f"guard={guard!r} must be True or False")
        self.guard = guard
        self.storage = Storage.from_str(storage)
        self._defines = {"LBM_GUARD": int(guard), "LBM_FP16S": int(self.storage)}
        self.options = Options.from_kwargs(**options)
        self.rt: Runtime = device if isinstance(device, Runtime) else get_runtime(device)
        self._step2_allowed = self._check_steps_per_launch()
        n = self.n_cells = self.nx * self.ny
        check_grid(self.rt, self.nx, self.ny)  # 32-bit indices and device memory (lbm.limits)
        fb = 9 * self.storage.bytes * n
        if fb > self.rt.device.max_mem_alloc_size:
            raise ValueError(f"grid {nx}x{ny} needs {fb / 2**20:.0f} MiB per population "
                             f"buffer; the device allows {self.rt.device.max_mem_alloc_size >> 20}"
                             " MiB per buffer")

        # -- device buffers, allocated once -------------------------------------------------
        hb = 4 * n
        self._f = PingPong(self.rt.buffer(fb), self.rt.buffer(fb))
        self._h = PingPong(self.rt.buffer(hb), self.rt.buffer(hb))
        self._mark = PingPong(self.rt.buffer(n), self.rt.buffer(n))  # local damping marks
        self._bed = self.rt.buffer(hb)
        self._zforce = self._bed   # the bed the step's force sees (+ hull pressure: lbm.bodies)
        self._f_ckpt = self.rt.buffer(fb)
        self._h_ckpt = self.rt.buffer(hb)
        self._guard = self.rt.buffer(GUARD_DTYPE.itemsize)
        self._n_partials = int(min(1024, -(-n // 256)))
        self._partials = self.rt.buffer(self._n_partials * PARTIAL_DTYPE.itemsize)
        self._eta = None      # surface scratch, on first write_surface
        self._field_bufs = None  # h, u, v for fields(), on first call

        # -- kernels, looked up once --------------------------------------------------------
        self._k_steps: dict[bool, tuple] = {}
        self._k_drop = self._kernel("lbm_sources.cl", "lbm_drop", "lbm.sources")
        self._k_push = self._kernel("lbm_sources.cl", "lbm_push", "lbm.sources")
        self._k_partial = self._kernel("lbm_reduce.cl", "lbm_reduce_partial", "lbm.guard")
        self._k_final = self._kernel("lbm_reduce.cl", "lbm_reduce_final", "lbm.guard")
        self._k_apply = self._kernel("lbm_guard.cl", "lbm_guard_apply", "lbm.guard")
        self._k_height = self._kernel("lbm_surface.cl", "lbm_surface_height", "lbm.surface")
        self._k_mesh = self._kernel("lbm_surface.cl", "lbm_surface_mesh", "lbm.surface")
        self._k_fields = self._kernel("lbm_fields.cl", "lbm_fields", "lbm.fields")

        self._guard_host = np.zeros(1, GUARD_DTYPE)
        self._guard_evt: cl.Event | None = None
        self._guard_scratch = self.rt.buffer(GUARD_DTYPE.itemsize)
        #: Where every check also copies the guard record (None: a scratch buffer): a reader on
        #: another queue reads that copy, which the following steps' counts do not reach
        self.guard_snapshot: cl.Buffer | None = None
        #: Read the guard record after every check (False: a caller that reads it itself, as
        #: the World does into its pinned ring, spares the queue that copy; guard_record()
        #: then reads on demand)
        self.read_guard_each_check = True
        self._reported = np.zeros(1, GUARD_DTYPE)  # counters at the last stats() call
        self._rain: _Rain | None = None
        self._rain_seed = None
        self._step_hooks: dict = {}   # hook -> quiet_steps: called after every step of step(n)
        self.time = 0.0
        self.steps = 0
        d = self.options.depth
        self.set_state(np.full((self.ny, self.nx), d))

    # -- construction helpers ---------------------------------------------------------------
    def _check_steps_per_launch(self) -> bool:
        """Whether lbm_step2 may run: the option allows it and the device's work-groups hold
        its tile (an explicit steps_per_launch=2 on a device that cannot is an error)."""
        dev, want = self.rt.device, self.options.steps_per_launch
        need = step2_local_bytes(self.storage, True, self.guard)
        tile = STEP2_TILE[0] * STEP2_TILE[1]
        fits = dev.local_mem_size >= need and dev.max_work_group_size >= tile
        if want == 2 and not fits:
            raise ValueError(f"option steps_per_launch=2 needs {need} B of local memory and "
                             f"work-groups of {tile}; the device has {dev.local_mem_size} B and "
                             f"{dev.max_work_group_size}")
        return want != 1 and fits

    def _wants_step2(self, uneven: bool) -> bool:
        """Two steps per launch: as the option says, or by default on a GPU for the uneven bed
        only. On an H200 (BENCHMARKS.md, 2026-12-02, fifth and sixth sessions), at 1024x768
        cells, lbm_step2 takes 10% less time over an uneven bed and 4% more over a flat one,
        whose step is lighter; on a CPU it is 13-29% slower (the halo's second computation)."""
        if not self._step2_allowed:
            return False
        return self.options.steps_per_launch == 2 or (self.rt.is_gpu and uneven)

    @property
    def steps_per_launch(self) -> int:
        """2 while the step runs as lbm_step2 (two time steps per launch), else 1."""
        return 2 if self._k_step2_pair is not None else 1

    def _kernel(self, source: str, name: str, stage: str, defines: dict | None = None):
        """A :class:`kernels.launch.Kernel` (arguments bound by name, timed as ``stage``)."""
        return self.rt.kernel_launcher(source, name, stage=stage,
                                       defines={**self._defines, **(defines or {})})

    def _step_kernels(self, uneven: bool) -> tuple:
        """The fused steps for the current walls and bed kind, each bound for both parities:
        ((lbm_step, lbm_step), (lbm_step2, lbm_step2) or None)."""
        pairs = self._k_steps.get(uneven)
        if pairs is None:
            defines = {"LBM_BOUNDARY": int(self.boundary), "LBM_BED": int(uneven)}
            one = tuple(self._kernel("lbm_step.cl", "lbm_step", "lbm.step", defines)
                        for _ in range(2))
            two = None
            if self._wants_step2(uneven):
                defines.update(LBM_TILE_X=STEP2_TILE[0], LBM_TILE_Y=STEP2_TILE[1])
                two = tuple(self._kernel("lbm_step.cl", "lbm_step2", "lbm.step", defines)
                            for _ in range(2))
            pairs = self._k_steps[uneven] = (one, two)
        return pairs

    def _bind_steps(self) -> None:
        """Bind both parities once: parity 0 reads f.current, parity 1 reads f.other."""
        one, two = self._step_kernels(self._uneven or self._zforce is not self._bed)
        f, h, m = self._f, self._h, self._mark
        for pair in (one, two) if two else (one,):
            for k, (fs, fd, hs, hd, ms, md) in zip(pair, (
                    (f.current, f.other, h.current, h.other, m.current, m.other),
                    (f.other, f.current, h.other, h.current, m.other, m.current)), strict=True):
                k.bind(f_src=fs, f_dst=fd, h_src=hs, h_dst=hd, bed=self._zforce, mark_src=ms,
                       mark_dst=md, p=self._params, guard=self._guard)
        self._k_step_pair, self._k_step2_pair = one, two

    def add_step_hook(self, hook, quiet_steps=None) -> None:
        """Call ``hook(dt)`` after every step of :meth:`step` (it must only enqueue): how
        floating bodies (:class:`lbm.bodies.Boats`) follow the water step by step.
        ``quiet_steps()``, if given, says after how many of the coming steps the hook will only
        count, enqueueing nothing: two such steps may run as one launch (lbm_step2)."""
        if not callable(hook) or not (quiet_steps is None or callable(quiet_steps)):
            raise ValueError("add_step_hook: hook and quiet_steps must be callable")
        self._step_hooks[hook] = quiet_steps

    def remove_step_hook(self, hook) -> None:
        self._step_hooks.pop(hook, None)

    def pressure_head_buffer(self) -> cl.Buffer:
        """The device buffer (nx*ny float32, m) that the step's bed force reads as the bed: the
        bed plus a surface pressure head that floating bodies write (:mod:`lbm.bodies`). Made
        on the first call as a copy of the bed; from then on the step is the uneven-bed kernel.
        The force is antisymmetric per link, so a pressure head moves water but never adds or
        removes any."""
        if self._zforce is self._bed:
            self._zforce = self.rt.buffer(4 * self.n_cells)
            cl.enqueue_copy(self.rt.queue, self._zforce, self._bed)
            self._bind_steps()
        return self._zforce

    @property
    def bed_buffer(self) -> cl.Buffer:
        """The bed (nx*ny float32, m) on the device."""
        return self._bed

    @property
    def params(self) -> np.void:
        """The by-value ``LbmParams`` record every lbm kernel takes (kernels/lbm.h)."""
        return self._params

    @property
    def populations_buffer(self) -> cl.Buffer:
        """The current populations (storage as :attr:`storage`; read-only for other stages)."""
        return self._f.current

    @property
    def defines(self) -> dict:
        """Build defines of this solver's kernels (storage, guard)."""
        return dict(self._defines)

    # -- public properties ------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Time step in seconds (dx / e)."""
        return self.lattice.dt

    @property
    def e(self) -> float:
        """Lattice speed dx/dt in m/s."""
        return self.lattice.e

    @property
    def tau(self) -> float:
        """BGK relaxation time from the viscosity (the guard's damping is local: cells it marks
        relax with max(tau, 1) for a few steps; the rest of the grid keeps this tau)."""
        return self.lattice.tau

    @property
    def size(self) -> tuple[float, float]:
        """Extent of the box in metres (x, y)."""
        return self.nx * self.dx, self.ny * self.dx

    # -- state ------------------------------------------------------------------------------
    def _field(self, name: str, a, default: float) -> np.ndarray:
        shape = (self.ny, self.nx)
        if a is None:
            return np.full(shape, default)
        a = np.asarray(a)
        if a.shape != shape:
            raise ValueError(f"set_state: {name} has shape {a.shape}; expected (ny, nx) = {shape}")
        if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
            raise ValueError(f"set_state: {name} must be real numbers, got dtype {a.dtype}")
        a = a.astype(np.float64)
        if not np.all(np.isfinite(a)):
            bad = np.argwhere(~np.isfinite(a))[0]
            raise ValueError(f"set_state: {name} is not finite at [j, i] = {tuple(bad)}")
        return a

    def set_state(self, h, u=None, v=None, bed=None) -> None:
        """Replace the water: depth ``h`` (m, > 0), velocity ``u``, ``v`` (m/s, default 0) and bed
        ``bed`` (m, default flat 0), all (ny, nx) arrays. Populations start at equilibrium.

        Chooses the lattice (e, dt, tau) for this state, so ``dt`` may change; resets ``time``
        to 0, the guard record and its checkpoint; keeps rain settings (restarted from the seed).
        """
        h = self._field("h", h, 0.0)
        u = self._field("u", u, 0.0)
        v = self._field("v", v, 0.0)
        bed = self._field("bed", bed, 0.0)
        if np.any(h <= 0):
            j, i = np.argwhere(h <= 0)[0]
            raise ValueError(f"set_state: depth h[{j}, {i}] = {h[j, i]:g} m is not positive; "
                             "dry cells are not supported (negative depth is invalid)")
        speed = np.hypot(u, v)
        lat = choose_lattice(self.dx, float(h.max()), float(speed.max()), self.options)
        if h.min() < lat.min_depth:
            j, i = np.unravel_index(np.argmin(h), h.shape)
            raise ValueError(f"set_state: depth h[{j}, {i}] = {h[j, i]:g} m is below min_depth="
                             f"{lat.min_depth:g} m (nearly dry cells are not supported)")
        froude = speed / np.sqrt(lat.gravity * h)
        if froude.max() > lat.max_froude:
            j, i = np.unravel_index(np.argmax(froude), h.shape)
            raise ValueError(f"set_state: Froude number {froude[j, i]:.3g} at [j, i] = ({j}, {i})"
                             f" exceeds max_froude={lat.max_froude:g} (supercritical flow is not"
                             " supported by D2Q9 LABSWE)")
        self.lattice: Lattice = lat
        self._depth_chosen = float(h.max())   # the depth the lattice was chosen for
        self._lattice_note = None
        self._uneven = bool(np.ptp(bed) > 0)
        self._set_params(lat, float(h.mean()))
        q = self.rt.queue
        if self.storage is Storage.FP16S:
            self._store_populations(equilibrium(h, u / lat.e, v / lat.e, lat.g_lat))
            h32 = h.astype(np.float32)
        else:   # the kernel's float32 equilibrium of the stored depth: a lake at rest is exact
            h32 = self._quantized(h).astype(np.float32)
            self._store_populations(equilibrium_f32(h32, u / lat.e, v / lat.e, lat.g_lat),
                                    depth=h32)
        cl.enqueue_copy(q, self._h.current, h32)
        cl.enqueue_copy(q, self._bed, bed.astype(np.float32))
        if self._zforce is not self._bed:
            cl.enqueue_copy(q, self._zforce, self._bed)
        for m in (self._mark.current, self._mark.other):
            cl.enqueue_fill_buffer(q, m, np.uint8(0), 0, self.n_cells)
        self._bed_host = bed.astype(np.float32)
        g = np.zeros(1, GUARD_DTYPE)
        g["tau"] = g["tau_user"] = lat.tau
        cl.enqueue_copy(q, self._guard, g)
        self._reported = g.copy()
        self._bind_steps()
        self.time = 0.0
        self.steps = 0
        self._since_check = 0
        self._since_save = 0
        self._parity = 0
        if self._rain_seed is not None:
            self._start_rain(self._rain.rate, self._rain.radius, self._rain.height,
                             self._rain_seed)
        self._check(SaveRequest.FORCE)   # the first checkpoint, and the first statistics

    def _set_params(self, lat: Lattice, h_ref: float) -> None:
        """The by-value constants; for fp16s storage also the lake at rest of depth ``h_ref``
        whose populations the stored float16 deviations are taken from."""
        rest = np.zeros(3, np.float32)
        if self.storage is Storage.FP16S:
            h32, g32 = np.float32(h_ref), np.float32(lat.g_lat)
            half = np.float32(0.5) * g32 * h32 * h32
            ra, rd = np.float32(1 / 3) * half, np.float32(1 / 12) * half
            rest[:] = (h32 - (np.float32(4) * ra + np.float32(4) * rd), ra, rd)
        self._rest = rest
        self._params = record(
            PARAMS_DTYPE, nx=self.nx, ny=self.ny, n_cells=self.n_cells, dx=self.dx, e=lat.e,
            g_lat=lat.g_lat, drag=lat.drag * lat.dt, h_min=lat.min_depth,
            u2_max=lat.max_speed_ratio**2, fr2_max=lat.max_froude**2, rest0=rest[0],
            rest_axis=rest[1], rest_diag=rest[2], quantum=self._quantum(lat))

    def _quantum(self, lat: Lattice) -> float:
        """float32 storage: the power of two every population is kept a multiple of, 2^-24 of
        the smallest power of two above the depth cap (kernels/lbm.h lbm_quantize: the volume
        is then conserved exactly). 0 for fp16s storage."""
        if self.storage is Storage.FP16S:
            return 0.0
        _, k = math.frexp(GH_LIMIT / float(np.float32(lat.g_lat)))
        return math.ldexp(1.0, k - 24)

    def _rest_planes(self) -> np.ndarray:
        """(9, 1, 1) float32: the rest population of each direction (0 for fp32 storage)."""
        r = np.array([self._rest[0]] + [self._rest[1], self._rest[2]] * 4, np.float32)
        return r.reshape(9, 1, 1)

    def _quantized(self, x) -> np.ndarray:
        """``x`` rounded to multiples of the quantum (float64)."""
        q = float(self._params["quantum"])
        return np.rint(np.asarray(x, np.float64) / q) * q

    def _store_populations(self, f, quantize: bool = True, depth=None) -> None:
        """Write populations (9, ny, nx) into f.current in the storage's format. float32 (unless
        not ``quantize``): the moving ones rounded to multiples of the quantum, as the kernels
        keep them, and the rest population the rounded depth (``depth``, default the sum of
        ``f``) less them, so that the stored depth is the rounded one exactly."""
        if self.storage is Storage.FP16S or not quantize:
            f32 = np.asarray(f, np.float32).reshape(9, self.ny, self.nx)
            if self.storage is Storage.FP16S:
                f32 = (f32 - self._rest_planes()).astype(np.float16)
        else:
            f64 = np.asarray(f, np.float64).reshape(9, self.ny, self.nx)
            fq = self._quantized(f64)
            fq[0] = self._quantized(f64.sum(0) if depth is None else depth) - fq[1:].sum(0)
            f32 = fq.astype(np.float32)
        cl.enqueue_copy(self.rt.queue, self._f.current, np.ascontiguousarray(f32))

    # -- stepping ---------------------------------------------------------------------------
    def _local_size(self):
        if self.options.local_size is not None:
            return tuple(self.options.local_size)
        return (128, 1) if self.rt.is_gpu else None

    def _enqueue_step(self, two: bool = False) -> cl.Event:
        """One lbm_step launch, or with ``two`` one lbm_step2 launch (two time steps)."""
        if two:
            evt = self._k_step2_pair[self._parity].launch(self._step2_size, STEP2_TILE)
        else:
            evt = self._k_step_pair[self._parity].launch(self._step_size, self._local_size())
        self._f.swap()
        self._h.swap()
        self._mark.swap()
        self._parity ^= 1
        return evt

    def enqueue_steps(self, n: int) -> list[cl.Event]:
        """``n`` bare fused steps (in pairs where :attr:`steps_per_launch` is 2), no rain and no
        guard check, returning their events: for benchmarks timing a chain of launches. A frame
        calls :meth:`step`."""
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
            raise ValueError(f"enqueue_steps: n={n!r} must be an integer >= 1")
        events, left = [], int(n)
        while left > 0:
            two = self._k_step2_pair is not None and left >= 2
            events.append(self._enqueue_step(two))
            left -= 1 + two
        self.time += n * self.dt
        self.steps += n
        self._since_check += n
        self._since_save += n
        return events

    def step(self, n: int = 1) -> None:
        """Advance ``n`` time steps (``n * dt`` seconds): n fused collide+stream launches, the
        rain drops due, a guard check every ``guard_interval`` steps and one at the end. Only
        enqueues: no host sync, no host copy."""
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 0:
            raise ValueError(f"step: n={n!r} must be an integer >= 0")
        if n == 0:
            return
        interval = self.options.guard_interval
        left = int(n)
        while left > 0:
            if self._rain is not None:
                self._rain_due(self.time + self.dt)
            two = left >= 2 and self._two_steps_free(interval)
            self._enqueue_step(two)
            for _ in range(1 + two):
                for hook in list(self._step_hooks):
                    hook(self.dt)
                self.time += self.dt
                self.steps += 1
                self._since_check += 1
                self._since_save += 1
            left -= 1 + two
            if self._since_check >= interval:
                self._check_due()
        if self._since_check > 0:
            self._check_due()

    def _two_steps_free(self, interval: int) -> bool:
        """Whether the next two steps may run as one lbm_step2 launch: nothing is due between
        them (no step hook that acts, no guard check, no rain drop: the state of two launches)."""
        if self._k_step2_pair is None or self._since_check + 1 >= interval:
            return False
        if any(quiet is None or quiet() < 1 for quiet in self._step_hooks.values()):
            return False
        return self._rain is None or self._rain.next_time >= (self.time + self.dt) + self.dt

    def _check_due(self) -> None:
        save = SaveRequest.NO
        if self._since_save >= self.options.checkpoint_interval:
            save = SaveRequest.IF_CLEAN
            self._since_save = 0
        self._check(save)

    def _check(self, save: SaveRequest) -> None:
        """Guard check, all on the device: reduce, decide (restore / save / nothing), apply;
        then start a non-blocking read of the 112-byte guard record (read_guard_each_check)."""
        rt, p = self.rt, self._params
        self._k_partial.bind(f=self._f.current, mark=self._mark.current, p=p,
                             partials=self._partials).launch(self._n_partials * 256, 256)
        self._k_final.bind(partials=self._partials, n_partials=self._n_partials, g=self._guard,
                           save=int(save),
                           snapshot=self._guard_scratch if self.guard_snapshot is None
                           else self.guard_snapshot).launch(256, 256)
        if self.guard:
            self._k_apply.bind(f=self._f.current, h_buf=self._h.current, f_ckpt=self._f_ckpt,
                               h_ckpt=self._h_ckpt, mark=self._mark.current, p=p,
                               guard=self._guard).launch(self.n_cells,
                                                         256 if rt.is_gpu else None)
        if self._guard_evt is not None:  # released, it would wait for its read: kept
            rt.keep(self._guard_evt)
        self._guard_evt = None
        if self.read_guard_each_check:
            self._guard_evt = cl.enqueue_copy(rt.queue, self._guard_host, self._guard,
                                              is_blocking=False)
        self._since_check = 0
        self._dirty = False

    # -- sources ----------------------------------------------------------------------------
    def _box(self, x0: float, x1: float, y0: float, y1: float):
        """Cells whose centres may lie in [x0, x1] x [y0, y1]: (i0, j0, w, h), or None."""
        i0 = max(0, math.floor(x0 / self.dx - 0.5))
        i1 = min(self.nx - 1, math.ceil(x1 / self.dx - 0.5))
        j0 = max(0, math.floor(y0 / self.dx - 0.5))
        j1 = min(self.ny - 1, math.ceil(y1 / self.dx - 0.5))
        if i1 < i0 or j1 < j0:
            return None
        return i0, j0, i1 - i0 + 1, j1 - j0 + 1

    def _launch_source(self, kernel, box, volume=0.0, **fields) -> None:
        i0, j0, w, h = box
        src = record(SOURCE_DTYPE, i0=i0, j0=j0, volume=volume, **fields)
        kernel.bind(f=self._f.current, h_buf=self._h.current, mark=self._mark.current,
                    p=self._params, s=src, guard=self._guard).launch((w, h))
        self._dirty = True

    def _check_radius(self, what: str, radius) -> float:
        r = _finite(f"{what}: radius", radius)
        if r < 0.5 * self.dx:
            raise ValueError(f"{what}: radius={radius!r} m is below half a cell "
                             f"(dx/2 = {0.5 * self.dx:g} m) and would touch no cell centre")
        return r

    def _check_point(self, what: str, x, y) -> tuple[float, float]:
        x, y = _finite(f"{what}: x", x), _finite(f"{what}: y", y)
        lx, ly = self.size
        if not (0 <= x <= lx and 0 <= y <= ly):
            raise ValueError(f"{what}: point ({x:g}, {y:g}) m is outside the box "
                             f"[0, {lx:g}] x [0, {ly:g}] m")
        return x, y

    @property
    def max_drop_height(self) -> float:
        """The tallest drop (m) :meth:`add_drop` accepts: the stability cap on the depth,
        0.6 e^2 / g, less the depth the lattice was chosen for."""
        return GH_LIMIT / self.lattice.g_lat - self._depth_chosen

    def add_drop(self, x: float, y: float, radius: float, height: float) -> None:
        """Add a smooth bump of water: height * (1 + cos(pi r/radius)) / 2 within ``radius`` m of
        (x, y) m, at constant velocity (negative height: a dip).

        A drop taller than :attr:`max_drop_height` or a dip deeper than the water the lattice
        was chosen for is refused (ValueError). Where the result still breaks the limits
        (min_depth, the depth cap, f0_eq >= 0) the guard clips it, and ``stats()`` reports the
        volume clipped or created and the cells limited."""
        x, y = self._check_point("add_drop", x, y)
        r = self._check_radius("add_drop", radius)
        amount = _finite("add_drop: height", height)
        if amount > self.max_drop_height:
            raise ValueError(f"add_drop: height={amount:g} m is above the stability limit: "
                             f"water {self._depth_chosen:g} m deep can take drops up to "
                             f"{self.max_drop_height:.4g} m (g h/e^2 <= {GH_LIMIT})")
        if -amount >= self._depth_chosen:
            raise ValueError(f"add_drop: height={amount:g} m would dig deeper than the water "
                             f"({self._depth_chosen:g} m deep); dry cells are not supported")
        box = self._box(x - r, x + r, y - r, y + r)
        if box is not None:
            self._launch_source(self._k_drop, box, x=x, y=y, dx=0.0, dy=0.0,
                                radius=r, amount=amount,
                                volume=self._drop_volume(box, x, y, r, amount))

    def _drop_volume(self, box, x, y, r, amount) -> float:
        """Depth the drop kernel adds over its box before the limiter (sum over cells, m)."""
        i0, j0, w, h = box
        jj, ii = np.mgrid[j0:j0 + h, i0:i0 + w]
        rr = np.hypot((ii + 0.5) * self.dx - x, (jj + 0.5) * self.dx - y)
        dh = np.where(rr < r, amount * 0.5 * (1.0 + np.cos(np.pi * rr / r)), 0.0)
        return float(dh.sum())

    def push(self, x: float, y: float, dx: float, dy: float, strength: float,
             radius: float | None = None) -> None:
        """Momentum along a drag from (x, y) to (x + dx, y + dy) (m): cells within ``radius``
        (m; default 4 cells) of that segment gain ``strength`` m/s along it, weighted
        (1 - (d/radius)^2)^2. A zero-length drag has no direction and does nothing. Velocities
        beyond the limiter's limits (max_speed_ratio, max_froude) are clamped and counted."""
        x, y = self._check_point("push", x, y)
        ddx, ddy = _finite("push: dx", dx), _finite("push: dy", dy)
        s = _finite("push: strength", strength)
        r = self._check_radius("push", 4.0 * self.dx if radius is None else radius)
        if ddx == 0.0 and ddy == 0.0:
            return
        box = self._box(min(x, x + ddx) - r, max(x, x + ddx) + r,
                        min(y, y + ddy) - r, max(y, y + ddy) + r)
        if box is not None:
            self._launch_source(self._k_push, box, x=x, y=y, dx=ddx, dy=ddy,
                                radius=r, amount=s)

    def set_rain(self, rate: float, radius: float, height: float, seed: int = 0) -> None:
        """Rain: drops of ``radius`` m and ``height`` m falling at ``rate`` per second (a Poisson
        process), uniformly over the box, from a NumPy generator seeded with ``seed``: the same
        seed gives the same drops at the same times. ``rate`` 0 stops the rain."""
        rate = _finite("set_rain: rate", rate)
        if rate < 0:
            raise ValueError(f"set_rain: rate={rate:g} must be >= 0 (drops per second)")
        r = self._check_radius("set_rain", radius)
        height = _finite("set_rain: height", height)
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"set_rain: seed={seed!r} must be an integer >= 0")
        if rate == 0:
            self._rain = None
            self._rain_seed = None
            return
        self._start_rain(rate, r, height, int(seed))

    def _start_rain(self, rate, radius, height, seed) -> None:
        rng = np.random.default_rng(seed)
        self._rain = _Rain(rate, radius, height, rng, self.time + rng.exponential(1.0 / rate))
        self._rain_seed = seed

    def _rain_due(self, t_end: float) -> None:
        """Drops whose time falls before ``t_end`` (drawn from the seeded generator)."""
        rain, (lx, ly) = self._rain, self.size
        while rain.next_time < t_end:
            x, y = rain.rng.uniform(0.0, lx), rain.rng.uniform(0.0, ly)
            self.add_drop(x, y, rain.radius, rain.height)
            rain.next_time += rain.rng.exponential(1.0 / rain.rate)

    # -- output -----------------------------------------------------------------------------
    def write_surface(self, vertices_buf: cl.Buffer, normals_buf: cl.Buffer | None = None,
                      origin=(0.0, 0.0, 0.0)) -> cl.Event:
        """Write the surface mesh into the caller's device buffers (nx*ny float4 each): vertex
        (i, j) at index j*nx + i, position (ox + (i+1/2) dx, oy + bed + h, oz + (j+1/2) dx, 0)
        in metres with Y up; unit normals from central differences of bed + h. No host copy.
        Triangles: :func:`lbm.grid_triangles`. Returns the event of the last launch."""
        origin4 = self._check_surface_args(vertices_buf, normals_buf, origin)
        if self._eta is None:
            self._eta = self.rt.buffer(4 * self.n_cells)
        self._k_height.bind(f=self._f.current, bed=self._bed, p=self._params, eta=self._eta)
        self._k_height.launch(self.n_cells, 256 if self.rt.is_gpu else None)
        return self._enqueue_mesh(vertices_buf, normals_buf, origin4)

    @property
    def surface_buffer(self) -> cl.Buffer | None:
        """The surface heights bed + h (nx*ny float32, m, index j*nx + i) as the last
        :meth:`write_surface` computed them: exactly what its mesh launch turned into vertices
        (None before the first call). Read-only for other stages."""
        return self._eta

    def write_surface_heights(self, eta, vertices_buf: cl.Buffer,
                              normals_buf: cl.Buffer | None = None,
                              origin=(0.0, 0.0, 0.0)) -> cl.Event:
        """:meth:`write_surface` from given surface heights ``eta`` (nx*ny float32, m, as
        :attr:`surface_buffer` held them) instead of the populations: the same mesh launch, so
        the same heights give the same vertex and normal bytes. For rendering a recorded
        surface (a snapshot) on another device; the water itself is not touched."""
        origin4 = self._check_surface_args(vertices_buf, normals_buf, origin)
        eta = np.asarray(eta)
        if eta.dtype != np.float32 or eta.size != self.n_cells:
            raise ValueError(f"write_surface_heights: eta must hold nx*ny = {self.n_cells} "
                             f"float32 values, got {eta.size} {eta.dtype}")
        if self._eta is None:
            self._eta = self.rt.buffer(4 * self.n_cells)
        self.rt.keep(cl.enqueue_copy(self.rt.queue, self._eta,
                                     np.ascontiguousarray(eta).ravel(), is_blocking=False))
        return self._enqueue_mesh(vertices_buf, normals_buf, origin4)

    def _check_surface_args(self, vertices_buf, normals_buf, origin) -> np.ndarray:
        need = 16 * self.n_cells
        for name, buf in (("vertices_buf", vertices_buf), ("normals_buf", normals_buf)):
            if buf is None and name == "normals_buf":
                continue
            if not isinstance(buf, cl.Buffer):
                raise ValueError(f"write_surface: {name} must be a pyopencl Buffer, "
                                 f"got {type(buf).__name__}")
            if buf.size < need:
                raise ValueError(f"write_surface: {name} holds {buf.size} bytes; needs "
                                 f"{need} (nx*ny = {self.n_cells} float4)")
        try:
            o = np.array([float(c) for c in origin], dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"write_surface: origin={origin!r} must be three numbers") from None
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise ValueError(f"write_surface: origin={origin!r} must be three finite numbers")
        return np.array([o[0], o[1], o[2], 0.0], np.float32)

    def _enqueue_mesh(self, vertices_buf, normals_buf, origin4) -> cl.Event:
        """Vertices (and normals) from :attr:`surface_buffer`: the mesh launch."""
        self._k_mesh.bind(eta=self._eta, p=self._params, origin=origin4, vertices=vertices_buf,
                          normals=normals_buf if normals_buf is not None else vertices_buf,
                          write_normals=int(normals_buf is not None))
        return self._k_mesh.launch((self.nx, self.ny), (64, 1) if self.rt.is_gpu else None)

    def fields(self) -> dict[str, np.ndarray]:
        """Depth ``h`` (m), velocity ``u``, ``v`` (m/s) and ``bed`` (m) as float32 (ny, nx)
        arrays. A host copy of whole fields: for tests, saving and analysis, not per frame."""
        if self._dirty:
            self._check(SaveRequest.NO)
        if self._field_bufs is None:
            self._field_bufs = [self.rt.buffer(4 * self.n_cells) for _ in range(3)]
        hb, ub, vb = self._field_bufs
        self._k_fields.bind(f=self._f.current, p=self._params, h_out=hb, u_out=ub, v_out=vb)
        self._k_fields.launch(self.n_cells, 256 if self.rt.is_gpu else None)
        shape = (self.ny, self.nx)
        out = {name: self.rt.to_host(b, np.float32, self.n_cells).reshape(shape)
               for name, b in (("h", hb), ("u", ub), ("v", vb))}
        out["bed"] = self._bed_host.copy()
        bad = [k for k, a in out.items() if not np.all(np.isfinite(a))]
        if bad and self.guard:  # the guard restores before any read; this is a solver bug
            raise RuntimeError(f"internal error: non-finite {bad} after the guard check")
        return out

    def _load_populations(self, f: np.ndarray) -> None:
        """Overwrite the stored populations (9, ny, nx) and the depth buffer (their sum) as they
        are, NaN included: for kernel tests. The next check sees whatever was loaded."""
        f = np.ascontiguousarray(f, np.float32).reshape(9, self.ny, self.nx)
        self._store_populations(f, quantize=False)
        cl.enqueue_copy(self.rt.queue, self._h.current,
                        f.astype(np.float64).sum(0).astype(np.float32))
        self._dirty = True

    def populations(self) -> np.ndarray:
        """The stored post-collision populations (9, ny, nx) float32 (tests and debugging)."""
        if self.storage is Storage.FP16S:
            raw = self.rt.to_host(self._f.current, np.float16, 9 * self.n_cells)
            return raw.reshape(9, self.ny, self.nx).astype(np.float32) + self._rest_planes()
        return self.rt.to_host(self._f.current, np.float32, 9 * self.n_cells).reshape(
            9, self.ny, self.nx)

    def damped_cells(self) -> np.ndarray:
        """Bool (ny, nx): cells the guard damps locally in the next step (their mark > 0).
        A host copy, for tests."""
        return self.rt.to_host(self._mark.current, np.uint8, self.n_cells).reshape(
            self.ny, self.nx) > 0

    # -- the guard --------------------------------------------------------------------------
    def copy_guard_to_snapshot(self) -> None:
        """Copy the guard record as it stands into :attr:`guard_snapshot` now (device to
        device): for a frame that ran no check."""
        if self.guard_snapshot is not None:
            cl.enqueue_copy(self.rt.queue, self.guard_snapshot, self._guard)

    def guard_record(self) -> np.void:
        """The device guard record as of the last check (waits for that check only; without
        :attr:`read_guard_each_check`, for everything enqueued)."""
        if self._dirty:
            self._check(SaveRequest.NO)
        if self._guard_evt is None:
            self._guard_evt = cl.enqueue_copy(self.rt.queue, self._guard_host, self._guard,
                                              is_blocking=True)
        self._guard_evt.wait()
        return self._guard_host[0].copy()

    def stats(self) -> dict:
        """Statistics of the current state, the volume budget and what the guard did since the
        last call.

        State: ``mass`` (= ``volume``, m^3 of water), ``max_speed_ratio`` (max |u|/e),
        ``min_depth`` (m), ``max_froude`` (the largest of the state's and of what the limiter saw
        before clipping since the last call). Budget (m^3, cumulative since set_state):
        ``volume_initial``, ``volume_sources`` (asked for by drops and rain; pushes ask for 0),
        ``volume_clipped`` and ``volume_created`` (by the limiter and by restores), so that
        ``volume_initial + volume_sources - volume_clipped + volume_created == volume`` to
        float32 round-off. Since the last call: ``cells_limited`` (= ``clamped``, cell updates the
        limiter clipped), ``restored`` (checkpoint restores), ``damped`` (checks with locally
        damped cells), ``saved`` (checkpoints), ``nan`` (a non-finite value was found; with the
        guard it was replaced by the checkpoint), ``acted`` (the guard limited or restored
        anything); ``cells_damped`` (cells damped now), ``tau`` (unchanged by the guard),
        ``lattice`` (a line when the lattice was re-chosen, else None), ``time``, ``steps``,
        and ``report``, one line saying what happened ("ok" when nothing did).
        """
        g = self.guard_record()
        prev, self._reported = self._reported, np.array([g], GUARD_DTYPE)
        out = self.guard_summary(g, prev[0])
        note = self._maybe_rechoose(out)
        if note:
            out["lattice"] = note
            parts = [p for p in out["report"].split("; ")
                     if p != "ok" and not p.startswith("the water deepened")]
            out["report"] = "; ".join(parts + [note])
        return out

    @property
    def guard_buffer(self) -> cl.Buffer:
        """The device guard record (``GUARD_DTYPE``), current as of the last check: a frame
        loop copies it without blocking and reads it with :meth:`guard_summary`."""
        if self._dirty:
            self._check(SaveRequest.NO)
        return self._guard

    def guard_summary(self, g: np.void, prev: np.void) -> dict:
        """:meth:`stats`'s dict for guard record ``g``, counts taken since record ``prev``
        (``lattice`` is always None here: only :meth:`stats` re-chooses the lattice)."""
        delta = {k: int(g[k]) - int(prev[k]) for k in ("clamped", "restored", "damped",
                                                        "saved")}
        a = self.dx**2
        # the Froude number the limiter saw before clipping, in the run of acting intervals
        # that ended with the last check (lbm_reduce_final)
        peak = float(g["peak_fr2"]) if delta["clamped"] else 0.0
        fr2 = max(float(g["max_fr2"]), peak, 0.0)
        nan = delta["restored"] > 0 if self.guard else int(g["nan_cells"]) > 0
        out = {
            "time": self.time,
            "steps": self.steps,
            "mass": float(g["mass"]) * a,
            "volume": float(g["mass"]) * a,
            "max_speed_ratio": math.sqrt(max(float(g["max_u2"]), 0.0)),
            "max_froude": math.sqrt(fr2) if math.isfinite(fr2) else math.inf,
            "min_depth": float(g["min_h"]),
            "nan": nan,
            "tau": float(g["tau"]),
            **delta,
            "cells_limited": delta["clamped"],
            "cells_damped": int(g["damped_cells"]),
            "volume_initial": float(g["mass0"]) * a,
            "volume_sources": float(g["sources"]) * a,
            "volume_clipped": float(g["clipped"]) * a,
            "volume_created": float(g["created"]) * a,
            "acted": delta["clamped"] > 0 or delta["restored"] > 0,
            "lattice": None,
        }
        parts = []
        if nan:
            parts.append(f"non-finite values: restored the checkpoint {delta['restored']}x"
                         if self.guard else f"non-finite values in {int(g['nan_cells'])} cells "
                         "(guard off: not restored)")
        if delta["clamped"]:
            parts.append(f"limited {delta['clamped']} cell updates (|u|/e <= "
                         f"{self.lattice.max_speed_ratio:g}, Fr <= {self.lattice.max_froude:g},"
                         f" h >= {self.lattice.min_depth:g} m, f0_eq >= 0; max Fr seen "
                         f"{out['max_froude']:.3g}), damped them locally; volume clipped "
                         f"{out['volume_clipped']:.3g} m^3, created {out['volume_created']:.3g}"
                         " m^3 so far")
        mean = out["volume"] / (self.n_cells * self.dx**2)
        if self.guard and mean > self._deepening_limit():
            parts.append(f"the water deepened to {mean:.4g} m on average, past the depth the "
                         "lattice was chosen for (stats() re-chooses it)")
        out["report"] = "; ".join(parts) if parts else "ok"
        return out

    def _deepening_limit(self) -> float:
        """Mean depth (m) past which the lattice is chosen again: midway between the depth it
        was chosen for and its design depth."""
        return 0.5 * (self._depth_chosen + self.lattice.design_depth)

    def _maybe_rechoose(self, s: dict) -> str | None:
        """When rain or drops have deepened the water past the depth the lattice was chosen for
        (mean depth above the midpoint of that depth and the design depth), choose e, dt and tau
        again for the water as it is now and restart the populations at their equilibrium
        (depth and velocity kept; the budget and time go on). Returns a line saying so."""
        if not self.guard or s["nan"]:
            return None
        lat = self.lattice
        mean = s["volume"] / (self.n_cells * self.dx**2)
        if mean <= self._deepening_limit():
            return None
        f = self.fields()
        h = f["h"].astype(np.float64)
        speed = np.hypot(f["u"], f["v"]).astype(np.float64)
        new = choose_lattice(self.dx, float(h.max()), float(speed.max()), self.options)
        old_e, old_dt = lat.e, lat.dt
        self.lattice = new
        self._depth_chosen = float(h.max())
        self._set_params(new, float(h.mean()))
        self._store_populations(equilibrium(h, f["u"] / new.e, f["v"] / new.e, new.g_lat))
        g = self.guard_record()
        g["tau"] = g["tau_user"] = new.tau
        rec = np.array([g], GUARD_DTYPE)
        cl.enqueue_copy(self.rt.queue, self._guard, rec)
        self._reported = rec.copy()
        self._bind_steps()
        self._check(SaveRequest.FORCE)
        return (f"the water deepened to {mean:.4g} m on average (the lattice was chosen for "
                f"{lat.design_depth / self.options.depth_headroom:.4g} m): re-chose e "
                f"{old_e:.4g} -> {new.e:.4g} m/s, dt {old_dt:.4g} -> {new.dt:.4g} s, tau "
                f"{new.tau:.4g}")
