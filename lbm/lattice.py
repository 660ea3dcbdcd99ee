"""Solver options and the choice of the lattice: SI units outside, lattice units inside.

The lattice speed e = dx/dt is the one free choice. It is taken as small as the conditions of
LABSWE allow with margin, because a larger e means a smaller dt (more steps per second of water)
and, at a fixed viscosity, tau = 1/2 + 3 nu / (e dx) closer to the unstable 1/2:

* stability:   g H_d / e^2 <= GH_DESIGN (0.5). Measured: BGK D2Q9 LABSWE goes unstable in moving
               water above g h / e^2 ~ 0.6 (docs/lbm.md); the limiter caps g h / e^2 at 0.6.
* f0_eq >= 0:  5 g H_d / (6 e^2) + 2 u_d^2 / (3 e^2) <= F0_DESIGN (0.8, the bound is 1)
* slow flow:   u_d / e <= SPEED_DESIGN (0.3; u^2/e^2 < 1 and Zhou's |u| < 0.3 e/sqrt(3) spirit)

with the design depth H_d = depth_headroom x the deepest water (drops and waves pile up) and
u_d the expected speed. gh/e^2 < 1 follows from the first. Fr < 1 is a property of the flow,
checked on set_state and held by the limiter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

GH_DESIGN = 0.5
F0_DESIGN = 0.8
SPEED_DESIGN = 0.3
#: kernels/lbm.h LBM_GH_LIMIT: the limiter's bound on g h / e^2.
GH_LIMIT = 0.6
#: kernels/lbm.h LBM_F0_LIMIT: the limiter's bound on 5Gh/6 + 2U^2/3.
F0_LIMIT = 0.98
DEFAULT_TAU = 0.6


def _num(name: str, value, lo: float, hi: float, *, lo_open: bool = False,
         allow_none: bool = False, integer: bool = False):
    """``value`` checked as a finite number in [lo, hi] (or (lo, hi]); one-line ValueError."""
    if value is None and allow_none:
        return None
    kind = "an integer" if integer else "a number"
    ok_type = isinstance(value, int | np.integer) if integer else isinstance(
        value, int | float | np.integer | np.floating)
    if isinstance(value, bool) or not ok_type:
        raise ValueError(f"option {name}={value!r} must be {kind}"
                         + (" or None" if allow_none else ""))
    x = int(value) if integer else float(value)
    left = "(" if lo_open else "["
    if not math.isfinite(x) or x < lo or x > hi or (lo_open and x == lo):
        raise ValueError(f"option {name}={value!r} is out of range; allowed {left}{lo:g}, {hi:g}]")
    return x


@dataclass(frozen=True)
class Options:
    """Solver options in SI units (the ``**options`` of :class:`lbm.ShallowWater`)."""

    gravity: float = 9.81            # m/s^2
    viscosity: float | None = None   # kinematic, m^2/s; None: tau = 0.6 (nu = e dx / 30)
    expected_speed: float | None = None  # m/s; None: 0.3 sqrt(g H) for the deepest water H
    depth: float = 1.0               # m, still depth of the lake the solver starts with
    depth_headroom: float = 1.5      # design depth = headroom x deepest water (room for drops)
    lattice_speed: float | None = None  # m/s, fixes e = dx/dt instead of choosing it
    drag: float = 0.0                # 1/s, linear drag: larger makes motion fade faster
    min_depth: float | None = None   # m, limiter floor; None: 1% of the deepest water
    max_froude: float = 1.0          # limiter: Froude number above this is clamped
    max_speed_ratio: float = 0.5     # limiter: |u|/e above this is clamped
    guard_interval: int = 100        # steps between guard checks inside one step(n) call
    checkpoint_interval: int = 500   # steps between checkpoint saves (only of clean states)
    local_size: tuple[int, int] | None = None  # work-group of the step kernel; None: device's
    steps_per_launch: int | None = None  # 2: lbm_step2 (two steps a launch); None: the device's

    @classmethod
    def from_kwargs(cls, **kw) -> Options:
        valid = [f.name for f in fields(cls)]
        for k in kw:
            if k not in valid:
                raise ValueError(f"unknown option {k!r}; valid options: {', '.join(valid)}")
        o = cls(**kw)
        _num("gravity", o.gravity, 0.0, 1e3, lo_open=True)
        _num("viscosity", o.viscosity, 0.0, 1e6, lo_open=True, allow_none=True)
        _num("expected_speed", o.expected_speed, 0.0, 1e5, lo_open=True, allow_none=True)
        _num("depth", o.depth, 0.0, 1e5, lo_open=True)
        _num("depth_headroom", o.depth_headroom, 1.0, 100.0)
        _num("lattice_speed", o.lattice_speed, 0.0, 1e6, lo_open=True, allow_none=True)
        _num("drag", o.drag, 0.0, 1e6)
        _num("min_depth", o.min_depth, 0.0, 1e5, lo_open=True, allow_none=True)
        _num("max_froude", o.max_froude, 0.0, 1.0, lo_open=True)
        _num("max_speed_ratio", o.max_speed_ratio, 0.0, 0.7, lo_open=True)
        _num("guard_interval", o.guard_interval, 1, 10**9, integer=True)
        _num("checkpoint_interval", o.checkpoint_interval, 1, 10**9, integer=True)
        _num("steps_per_launch", o.steps_per_launch, 1, 2, integer=True, allow_none=True)
        if o.local_size is not None:
            ls = o.local_size
            if (not isinstance(ls, tuple | list) or len(ls) != 2
                    or not all(isinstance(v, int) and 1 <= v <= 1024 for v in ls)):
                raise ValueError(f"option local_size={ls!r} must be None or two integers "
                                 "in [1, 1024]")
        return o


@dataclass(frozen=True)
class Lattice:
    """The lattice chosen for a grid and a state: every derived constant, SI and lattice."""

    dx: float        # m
    e: float         # lattice speed dx/dt, m/s
    dt: float        # s
    tau: float       # BGK relaxation time
    viscosity: float  # kinematic viscosity nu = e dx (2 tau - 1) / 6, m^2/s
    gravity: float   # m/s^2
    design_depth: float   # m, H_d
    design_speed: float   # m/s, u_d
    min_depth: float      # m, limiter floor
    max_froude: float
    max_speed_ratio: float
    drag: float           # 1/s

    @property
    def g_lat(self) -> float:
        """G = g / e^2 (1/m): gravity in the lattice equilibrium."""
        return self.gravity / self.e**2

    def f0_margin(self, depth: float, speed: float) -> float:
        """5 g h / (6 e^2) + 2 u^2 / (3 e^2): f0_eq >= 0 while this is <= 1."""
        return (5.0 * self.gravity * depth / 6.0 + 2.0 * speed**2 / 3.0) / self.e**2


def choose_lattice(dx: float, max_depth: float, max_speed: float, opts: Options) -> Lattice:
    """The lattice for cells of ``dx`` metres holding water up to ``max_depth`` m moving at up to
    ``max_speed`` m/s (the larger of that and ``opts.expected_speed`` is the design speed)."""
    g = opts.gravity
    h_d = opts.depth_headroom * max_depth
    u_d = opts.expected_speed if opts.expected_speed is not None else 0.3 * math.sqrt(g * max_depth)
    u_d = max(u_d, max_speed)
    if opts.lattice_speed is None:
        e = max(math.sqrt(g * h_d / GH_DESIGN),
                math.sqrt((5.0 * g * h_d / 6.0 + 2.0 * u_d**2 / 3.0) / F0_DESIGN),
                u_d / SPEED_DESIGN)
    else:
        e = float(opts.lattice_speed)
        need = max(math.sqrt(g * max_depth / GH_LIMIT),
                   math.sqrt((5.0 * g * max_depth / 6.0 + 2.0 * u_d**2 / 3.0) / F0_LIMIT),
                   u_d / opts.max_speed_ratio)
        if e < need:
            raise ValueError(
                f"option lattice_speed={e:g} m/s is too small for water {max_depth:g} m deep "
                f"moving at {u_d:g} m/s; needs >= {need:.4g} (g h/e^2 <= {GH_LIMIT}, "
                "f0_eq >= 0, |u|/e <= max_speed_ratio)")
    if opts.viscosity is None:
        tau = DEFAULT_TAU
    else:
        tau = 0.5 + 3.0 * opts.viscosity / (e * dx)
    nu = e * dx * (2.0 * tau - 1.0) / 6.0
    dt = dx / e
    if opts.drag * dt > 0.5:
        raise ValueError(f"option drag={opts.drag:g} 1/s is too large for dt={dt:.3g} s "
                         f"(drag*dt must be <= 0.5; allowed drag <= {0.5 / dt:.4g})")
    h_min = opts.min_depth if opts.min_depth is not None else 0.01 * max_depth
    if h_min >= max_depth:
        raise ValueError(f"option min_depth={h_min:g} m must be below the water depth "
                         f"{max_depth:g} m")
    return Lattice(dx=dx, e=e, dt=dt, tau=tau, viscosity=nu, gravity=g, design_depth=h_d,
                   design_speed=u_d, min_depth=h_min, max_froude=opts.max_froude,
                   max_speed_ratio=opts.max_speed_ratio, drag=opts.drag)


#: D2Q9 velocities in Zhou's order (0 rest, odd axes, even diagonals) and equilibrium weights.
CX = np.array([0, 1, 1, 0, -1, -1, -1, 0, 1])
CY = np.array([0, 0, 1, 1, 1, 0, -1, -1, -1])
W = np.array([0.0, 1 / 3, 1 / 12, 1 / 3, 1 / 12, 1 / 3, 1 / 12, 1 / 3, 1 / 12])


def equilibrium(h: np.ndarray, ux: np.ndarray, uy: np.ndarray, g_lat: float) -> np.ndarray:
    """Zhou's equilibrium (9, ...) in float64 from depth h (m) and lattice velocity u/e."""
    h = np.asarray(h, np.float64)
    u2 = ux * ux + uy * uy
    feq = np.empty((9,) + h.shape)
    feq[0] = h - 5.0 * g_lat * h * h / 6.0 - 2.0 * h * u2 / 3.0
    for a in range(1, 9):
        cu = CX[a] * ux + CY[a] * uy
        feq[a] = W[a] * (0.5 * g_lat * h * h + h * cu + 1.5 * h * cu * cu - 0.5 * h * u2)
    return feq


def equilibrium_f32(h, ux, uy, g_lat: float) -> np.ndarray:
    """Zhou's equilibrium (9, ...) in float32 with the operations of kernels/lbm.h
    ``lbm_equilibrium`` in their order: at rest (ux = uy = 0) its bits are the kernel's."""
    f = np.float32
    h, ux, uy, g = (np.asarray(v, f) for v in (h, ux, uy, g_lat))
    u2 = ux * ux + uy * uy
    base = f(0.5) * g * h * h - f(0.5) * h * u2
    a, b = ux + uy, uy - ux
    out = np.empty((9,) + h.shape, f)
    for k, w, c in ((1, 1 / 3, ux), (3, 1 / 3, uy), (2, 1 / 12, a), (4, 1 / 12, b)):
        out[k] = f(w) * (base + h * c + f(1.5) * h * c * c)
        out[k + 4] = f(w) * (base - h * c + f(1.5) * h * c * c)
    out[0] = h - (((out[1] + out[5]) + (out[3] + out[7])) + ((out[2] + out[6]) + (out[4] + out[8])))
    return out
