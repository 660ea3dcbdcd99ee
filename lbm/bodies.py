"""Floating rigid bodies (boats) coupled both ways with the shallow water, stepped on the device.

Host side of ``kernels/lbm_bodies.cl``. The host precomputes, once per hull, a compact
description from the closed mesh (:class:`Hull`): volume, centre of mass and principal moments of
a uniform solid, and a footprint height map (where the hull crosses vertical lines on a small grid
in body coordinates, ringed by empty columns that measure the water level around the hull).
:meth:`Boats.enqueue_step` only enqueues one launch for all boats (several work-groups per
boat, every substep in the launch: buoyancy and drag from the water under every column, a local
reduction to force and torque, then semi-implicit Euler with added mass, walls, and the pose
written into the caller's transform buffer as world_from_mesh; then each of the boat's groups
presses its tile of the hull's box only: the hulls' pressure head added to the bed the water's
force sees, so the hull pushes water away, a moving boat makes a wake and a heaving one makes
waves; water volume is conserved exactly). Every group of a boat computes the same update (the
same inputs and code: the same bits); boats whose cells can meet within an update (known from
the start: a horizontal speed limit, :data:`MAX_SPEED`) are updated together by each of their
groups, so the launch needs no global synchronisation and is deterministic. Coupled to
``sim.step``, the boats are updated every :attr:`Boats.every` water steps, at most
``max_substep`` seconds apart (the coupling lag is bounded in time, not in steps). See
docs/lbm.md, "Floating bodies".

    boats = Boats(sim, [BoatSpec(V, F, mass=100.0, position=(1, 0.55, 1))],
                  transform_buffer, rows=[3], origin=(0, 0, 0))
    sim.step(k)                                     # coupled: boats follow, no host sync
    positions, quaternions = boats.poses()          # a host read, for tests and saving
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from lbm.structs import BODY_DTYPE, BODY_STEP_DTYPE, record

#: Most boats one :class:`Boats` holds (the device array is allocated once at this size;
#: kernels/lbm_bodies.h LBM_MAX_BODIES).
MAX_BOATS = 16
#: kernels/lbm_bodies.h LBM_BODY_WG.
BODY_WG = 512
#: kernels/lbm_bodies.h LBM_PRESS_BATCH.
PRESS_BATCH = 4
#: Horizontal speed limit of a boat, m/s (kernels/lbm_bodies.h LBM_BODY_MAX_SPEED): faster is
#: clamped. It bounds where a boat can be after an update, so the update knows from the start
#: which boats' cells can meet.
MAX_SPEED = 5.0
RHO_WATER = 1000.0
#: Target cells of the pressure pass per work-item (sets the work-groups per boat of an update;
#: each group also recomputes the boat's reduction, so more groups cost more redundant work).
PRESS_CELLS = 4.0
#: Most work-groups per boat in an update.
MAX_GROUPS = 64


class HullError(ValueError):
    """A hull mesh that cannot float: not closed, no volume, or too heavy."""


# -- geometry of a closed triangle mesh -------------------------------------------------------
def check_closed(F: np.ndarray) -> None:
    """Every edge is shared by exactly two triangles, once in each direction (a closed,
    consistently oriented surface); raises HullError naming the first bad edge."""
    F = np.asarray(F, np.int64)
    if F.ndim != 2 or F.shape[1] != 3 or len(F) < 4:
        raise HullError(f"a hull needs at least 4 triangles, got faces of shape {F.shape}")
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = e[:, 0] * (int(F.max()) + 1) + e[:, 1]
    rev = e[:, 1] * (int(F.max()) + 1) + e[:, 0]
    uniq, counts = np.unique(key, return_counts=True)
    if np.any(counts > 1):
        a, b = divmod(int(uniq[np.argmax(counts > 1)]), int(F.max()) + 1)
        raise HullError(f"the mesh is not closed: edge ({a}, {b}) is used twice in the same "
                        "direction (inconsistent orientation or a non-manifold edge)")
    missing = ~np.isin(rev, uniq)
    if np.any(missing):
        a, b = e[np.argmax(missing)]
        raise HullError(f"the mesh is not closed: edge ({a}, {b}) has no neighbour across it "
                        f"({int(missing.sum())} open edges)")


def solid_properties(V: np.ndarray, F: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume (m^3), centroid (3,) and inertia tensor about the centroid per unit density
    (3, 3) of the solid a closed mesh bounds, in float64 (signed tetrahedra from the origin)."""
    V = np.asarray(V, np.float64)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    det = np.einsum("ij,ij->i", a, np.cross(b, c))       # 6 x signed volumes
    vol = det.sum() / 6.0
    if abs(vol) < 1e-12:
        raise HullError("the mesh encloses no volume")
    if vol < 0:   # inward-facing triangles: flip
        det, vol = -det, -vol
    centroid = (det[:, None] * (a + b + c)).sum(0) / (24.0 * vol)
    # second moments int x_i x_j dV of each tetrahedron (0, a, b, c), summed
    s = a + b + c
    P = (det[:, None, None] / 120.0) * (np.einsum("ni,nj->nij", a, a) + np.einsum(
        "ni,nj->nij", b, b) + np.einsum("ni,nj->nij", c, c) + np.einsum("ni,nj->nij", s, s))
    P = P.sum(0) - vol * np.outer(centroid, centroid)
    inertia = np.trace(P) * np.eye(3) - P
    return float(vol), centroid, inertia


def vertical_hits(V: np.ndarray, F: np.ndarray, xs: np.ndarray, zs: np.ndarray):
    """Lowest and highest y where vertical lines through (xs[k], zs[k]) cross the mesh
    (NaN where a line misses it), float64, by barycentric tests in the xz plane."""
    V = np.asarray(V, np.float64)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    lo = np.full(len(xs), np.inf)
    hi = np.full(len(xs), -np.inf)
    d = (b[:, 2] - c[:, 2]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 2] - c[:, 2])
    ok = np.abs(d) > 1e-18
    a, b, c, d = a[ok], b[ok], c[ok], d[ok]
    bx0 = np.minimum(np.minimum(a[:, 0], b[:, 0]), c[:, 0])
    bx1 = np.maximum(np.maximum(a[:, 0], b[:, 0]), c[:, 0])
    bz0 = np.minimum(np.minimum(a[:, 2], b[:, 2]), c[:, 2])
    bz1 = np.maximum(np.maximum(a[:, 2], b[:, 2]), c[:, 2])
    chunk = max(1, 2_000_000 // max(len(xs), 1))
    for t0 in range(0, len(a), chunk):
        sl = slice(t0, t0 + chunk)
        px, pz = xs[None, :], zs[None, :]
        inside_box = ((px >= bx0[sl, None]) & (px <= bx1[sl, None]) & (pz >= bz0[sl, None])
                      & (pz <= bz1[sl, None]))
        ti, si = np.nonzero(inside_box)
        if len(ti) == 0:
            continue
        ti = ti + t0
        x, z = xs[si] - c[ti, 0], zs[si] - c[ti, 2]
        l1 = ((b[ti, 2] - c[ti, 2]) * x + (c[ti, 0] - b[ti, 0]) * z) / d[ti]
        l2 = ((c[ti, 2] - a[ti, 2]) * x + (a[ti, 0] - c[ti, 0]) * z) / d[ti]
        l3 = 1.0 - l1 - l2
        eps = -1e-9
        hit = (l1 >= eps) & (l2 >= eps) & (l3 >= eps)
        y = l1 * a[ti, 1] + l2 * b[ti, 1] + l3 * c[ti, 1]
        np.minimum.at(lo, si[hit], y[hit])
        np.maximum.at(hi, si[hit], y[hit])
    miss = ~np.isfinite(lo)
    lo[miss] = np.nan
    hi[miss] = np.nan
    return lo, hi


@dataclass(frozen=True)
class Hull:
    """A hull's compact description in body coordinates (origin at the centre of mass of the
    uniform solid, axes of the placed mesh).

    ``footprint`` (nfz, nfx, 2) float32: (bottom, top) of the hull on the vertical line through
    sample (x0 + ix dfx, z0 + iz dfz), (1, 0) where there is no hull (a ring of such columns
    measures the water level around it). ``volume`` (m^3), ``centroid`` (3,) in the placed
    mesh's frame, ``inertia_unit`` (3, 3) per unit density about the centroid, ``radius`` the
    largest horizontal distance of a hull column from the centre (m)."""

    footprint: np.ndarray
    x0: float
    z0: float
    dfx: float
    dfz: float
    volume: float
    centroid: np.ndarray
    inertia_unit: np.ndarray
    radius: float
    footprint_volume: float

    @classmethod
    def from_mesh(cls, V, F, *, spacing: float | None = None, max_samples: int = 40,
                  ring: int = 2) -> Hull:
        """From a closed mesh in its placed frame (metres, Y up). ``spacing``: footprint sample
        spacing (m; default: the longer horizontal extent / (max_samples - 2 ring))."""
        V = np.asarray(V, np.float64)
        F = np.asarray(F, np.int64)
        if V.ndim != 2 or V.shape[1] != 3 or not np.all(np.isfinite(V)):
            raise HullError("hull vertices must be finite (n, 3) coordinates")
        check_closed(F)
        vol, c, inertia = solid_properties(V, F)
        Vb = V - c
        lo, hi = Vb.min(0), Vb.max(0)
        ext = hi - lo
        if spacing is None:
            spacing = max(ext[0], ext[2]) / (max_samples - 2 * ring)
        nfx = min(max_samples, int(math.ceil(ext[0] / spacing)) + 2 * ring)
        nfz = min(max_samples, int(math.ceil(ext[2] / spacing)) + 2 * ring)
        dfx = (ext[0] / max(nfx - 2 * ring, 1)) if ext[0] > 0 else spacing
        dfz = (ext[2] / max(nfz - 2 * ring, 1)) if ext[2] > 0 else spacing
        x0 = lo[0] + 0.5 * dfx - ring * dfx
        z0 = lo[2] + 0.5 * dfz - ring * dfz
        zz, xx = np.mgrid[0:nfz, 0:nfx]
        xs, zs = (x0 + xx * dfx).ravel(), (z0 + zz * dfz).ravel()
        bottom, top = vertical_hits(Vb, F, xs, zs)
        empty = ~np.isfinite(bottom) | (top - bottom <= 1e-9)
        fp = np.stack([np.where(empty, 1.0, bottom), np.where(empty, 0.0, top)], -1)
        fp = fp.reshape(nfz, nfx, 2).astype(np.float32)
        if empty.all():
            raise HullError("the hull has no footprint (no vertical line crosses it)")
        full = ~empty
        radius = float(np.hypot(xs[full], zs[full]).max() + 0.5 * math.hypot(dfx, dfz))
        fvol = float(((top - bottom)[full]).sum() * dfx * dfz)
        return cls(fp, float(x0), float(z0), float(dfx), float(dfz), vol, c, inertia, radius,
                   fvol)

    def displaced(self, level: float) -> float:
        """Volume (m^3) below body height ``level`` with the hull upright (footprint model)."""
        b, t = self.footprint[..., 0].astype(np.float64), self.footprint[..., 1]
        full = t >= b
        return float(np.clip(level - b, 0.0, t - b)[full].sum() * self.dfx * self.dfz)

    def rest_level(self, mass: float, rho: float = RHO_WATER) -> float:
        """Body height of the water line where the upright hull floats with ``mass`` kg."""
        b = self.footprint[..., 0][self.footprint[..., 1] >= self.footprint[..., 0]]
        t = self.footprint[..., 1][self.footprint[..., 1] >= self.footprint[..., 0]]
        lo, hi = float(b.min()), float(t.max())
        want = mass / rho
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.displaced(mid) < want else (lo, mid)
        return 0.5 * (lo + hi)

    @property
    def sample_radius(self) -> float:
        """Largest distance (m) from the centre of mass of a point where a column samples the
        water: a hull column's bottom, a ring column's centre (kernels/lbm_bodies.cl)."""
        fp = self.footprint.astype(np.float64)
        zz, xx = np.mgrid[0:fp.shape[0], 0:fp.shape[1]]
        xs, zs = self.x0 + xx * self.dfx, self.z0 + zz * self.dfz
        y = np.where(fp[..., 1] >= fp[..., 0], fp[..., 0], 0.0)
        return float(np.sqrt(xs * xs + y * y + zs * zs).max()) * (1 + 1e-6)

    @property
    def bottom(self) -> float:
        """Lowest point of the hull in body coordinates (m)."""
        fp = self.footprint
        return float(fp[..., 0][fp[..., 1] >= fp[..., 0]].min())


def _shift(hull: Hull, d: np.ndarray) -> Hull:
    """The same hull in body coordinates whose origin moved by ``d`` (placed frame, m)."""
    fp = hull.footprint.copy()
    full = fp[..., 1] >= fp[..., 0]
    fp[..., 0][full] -= d[1]
    fp[..., 1][full] -= d[1]
    zz, xx = np.mgrid[0:fp.shape[0], 0:fp.shape[1]]
    xs, zs = hull.x0 - d[0] + xx * hull.dfx, hull.z0 - d[2] + zz * hull.dfz
    radius = float(np.hypot(xs[full], zs[full]).max() + 0.5 * math.hypot(hull.dfx, hull.dfz))
    return Hull(fp, hull.x0 - float(d[0]), hull.z0 - float(d[2]), hull.dfx, hull.dfz,
                hull.volume, hull.centroid + d, hull.inertia_unit, radius,
                hull.footprint_volume)


def quat_from_matrix(R) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (float64)."""
    R = np.asarray(R, np.float64)
    t = np.trace(R)
    if t > 0:
        s = 2.0 * math.sqrt(t + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + R[i, i] - R[j, j] - R[k, k], 1e-300))
        q = [0.0] * 4
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q = np.asarray(q)
    return q / np.linalg.norm(q) * (1 if q[0] >= 0 else -1)


def matrix_from_quat(q) -> np.ndarray:
    w, x, y, z = np.asarray(q, np.float64)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@dataclass
class BoatSpec:
    """One boat. ``vertices`` (n, 3) and ``faces`` (m, 3) of a closed mesh; ``base`` (3, 4) or
    (4, 4): the mesh's own placement (placed_from_mesh: size, centring); the initial pose is
    world_from_placed = [``rotation`` (3x3) | ``position`` (m)], so the transform row written
    is world_from_mesh = world_from_placed . base, as for a static mesh. ``mass`` (kg) or
    ``density`` (kg/m^3 of the hull's volume); ``damping`` (heave, drift, rotation) in 1/s:
    heave and drift relax the hull's velocity towards the water's (per kg of displaced water),
    rotation damps its spin. ``mass_height``: height (m) of the centre of mass above the hull's
    lowest point, above the solid's centroid (ballast; the inertia is the uniform solid's moved
    there by the parallel-axis rule); None: the centroid of the uniform solid, which floats
    upright only if the hull's metacentre is above it."""

    vertices: np.ndarray
    faces: np.ndarray
    mass: float | None = None
    density: float | None = None
    position: tuple = (0.0, 0.0, 0.0)
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    base: np.ndarray = field(default_factory=lambda: np.eye(4)[:3])
    damping: tuple = (2.0, 1.0, 2.0)
    added_mass: float = 0.5
    mass_height: float | None = None
    name: str = ""


def _finite3(name, v) -> np.ndarray:
    try:
        a = np.asarray(v, np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={v!r} must be three numbers") from None
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}={v!r} must be finite")
    return a


class Boats:
    """Rigid floating bodies on ``sim`` (a :class:`lbm.ShallowWater`), stepped on the device.

    ``transform_buffer``: the scene's device transform buffer (rows of ``Transform`` in
    kernels/transform.h, 48 bytes); boat k writes row ``rows[k]`` (world_from_mesh) every update,
    with no host copy. ``origin``: world position of the water grid's corner (as
    ``sim.write_surface``'s origin), so the water surface is at ``origin.y + bed + h``.
    ``rho``: water density (kg/m^3). ``coupled``: True (default) steps the boats inside
    ``sim.step(n)`` (a hook) every :attr:`every` water steps, ``every * dt <= max_substep``
    (every step where ``dt > max_substep``): the hulls' pressure is held at most
    ``max_substep`` seconds of water time (holding it longer lags the water's reaction and
    undamps a bobbing hull: measured, docs/lbm.md); False: the caller calls
    :meth:`enqueue_step`. Poses are those of the last update.
    Building one reads the water's depth once (a host copy) to refuse boats that would touch
    the bed.
    """

    def __init__(self, sim, specs, transform_buffer: cl.Buffer, rows, *,
                 origin=(0.0, 0.0, 0.0), rho: float = RHO_WATER, max_substep: float = 1 / 120,
                 coupled: bool = True, work_group: int = BODY_WG,
                 press_batch: int = PRESS_BATCH):
        self.sim, self.rt = sim, sim.rt
        self.origin = _finite3("origin", origin)
        self.rho = float(rho)
        if not (self.rho > 0 and math.isfinite(self.rho)):
            raise ValueError(f"rho={rho!r} must be a positive density (kg/m^3)")
        self.max_substep = float(max_substep)
        if not (self.max_substep > 0 and math.isfinite(self.max_substep)):
            raise ValueError(f"max_substep={max_substep!r} must be a positive time (s)")
        if not isinstance(transform_buffer, cl.Buffer):
            raise ValueError("transform_buffer must be a pyopencl Buffer of Transform rows")
        self.transforms = transform_buffer
        self._zforce = sim.pressure_head_buffer()
        # the records: an update reads one buffer and writes the other (swapped after it)
        self._bodies = self.rt.buffer(MAX_BOATS * BODY_DTYPE.itemsize)
        self._bodies_out = self.rt.buffer(MAX_BOATS * BODY_DTYPE.itemsize)
        self._host = np.zeros(MAX_BOATS, BODY_DTYPE)
        self._hulls: list[Hull | None] = [None] * MAX_BOATS
        self.names: list[str] = []
        self._slots: list[int] = []
        self._foot = None
        if work_group not in (128, 256, 512, 1024):
            raise ValueError(f"work_group={work_group}; allowed 128, 256, 512, 1024")
        self.work_group = int(work_group)   #: LBM_BODY_WG of the update kernel
        if press_batch not in (1, 2, 4, 8):
            raise ValueError(f"press_batch={press_batch}; allowed 1, 2, 4, 8")
        self.press_batch = int(press_batch)   #: LBM_PRESS_BATCH of the update kernel
        defines = dict(sim.defines)
        if work_group != BODY_WG:
            defines["LBM_BODY_WG"] = self.work_group
        if press_batch != PRESS_BATCH:
            defines["LBM_PRESS_BATCH"] = self.press_batch
        self._k_update = self.rt.kernel_launcher("lbm_bodies.cl", "lbm_bodies_update",
                                                 stage="lbm.bodies", defines=defines)
        self._k_press_all = self.rt.kernel_launcher("lbm_bodies.cl", "lbm_bodies_press_all",
                                                    stage="lbm.bodies", defines=defines)
        self._held_s, self._held_steps = 0.0, 0   # water time since the last coupled update
        self._recs: dict = {}   # BodyStep records by their inputs
        #: Target press cells per work-item (sets :meth:`groups_per_boat`); ``press_groups``:
        #: a fixed number of work-groups per boat instead (tests, benchmarks).
        self.press_cells: float = PRESS_CELLS
        self.press_groups: int | None = None
        self._groups_key, self._groups = None, 1
        self._depth = None
        self._floor = 0.0
        specs, rows = list(specs), list(rows)
        if len(specs) != len(rows):
            raise ValueError(f"{len(specs)} boats but {len(rows)} transform rows")
        for spec, row in zip(specs, rows, strict=True):
            self._add(spec, row)
        self._upload()
        self.coupled = bool(coupled)
        if self.coupled:
            sim.add_step_hook(self._water_step, self._quiet_steps)

    def close(self) -> None:
        """Stop following the water (removes the step hook)."""
        self.sim.remove_step_hook(self._water_step)

    # -- building -----------------------------------------------------------------------------
    def _water(self) -> dict:
        """The water's fields, read once (a host copy at construction, not per frame)."""
        if self._depth is None:
            self._depth = self.sim.fields()
        return self._depth

    def _add(self, spec: BoatSpec, row: int) -> int:
        name = spec.name or f"boat {len(self.names)}"
        free = [k for k in range(MAX_BOATS) if self._hulls[k] is None]
        if not free:
            raise ValueError(f"{name}: at most {MAX_BOATS} boats")
        if isinstance(row, bool) or not isinstance(row, int | np.integer) or row < 0:
            raise ValueError(f"{name}: transform row {row!r} must be an integer >= 0")
        if (int(row) + 1) * 48 > self.transforms.size:
            raise ValueError(f"{name}: transform row {row} is beyond the transform buffer "
                             f"({self.transforms.size // 48} rows)")
        base = np.asarray(spec.base, np.float64)
        if base.shape == (4, 4):
            base = base[:3]
        if base.shape != (3, 4) or not np.all(np.isfinite(base)):
            raise ValueError(f"{name}: base must be a finite 3x4 or 4x4 matrix")
        R = np.asarray(spec.rotation, np.float64)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(
                R) < 0:
            raise ValueError(f"{name}: rotation must be a 3x3 rotation matrix")
        pos = _finite3(f"{name}: position", spec.position)
        V = np.asarray(spec.vertices, np.float64)
        placed = V @ base[:, :3].T + base[:, 3]
        try:
            hull = Hull.from_mesh(placed, spec.faces)
        except HullError as exc:
            raise HullError(f"{name}: {exc}") from None
        if (spec.mass is None) == (spec.density is None):
            raise ValueError(f"{name}: give exactly one of mass (kg) or density (kg/m^3)")
        mass = spec.mass if spec.mass is not None else spec.density * hull.volume
        if not (isinstance(mass, int | float | np.floating) and math.isfinite(mass) and mass > 0):
            raise ValueError(f"{name}: mass={mass!r} must be a positive number of kg")
        floats = self.rho * min(hull.volume, hull.footprint_volume)
        if mass >= 0.98 * floats:
            raise HullError(f"{name}: mass {mass:.4g} kg sinks it: the hull displaces at most "
                            f"{floats:.4g} kg of water (volume {hull.volume:.4g} m^3)")
        damping = np.asarray(spec.damping, np.float64).reshape(3)
        if not np.all(np.isfinite(damping)) or np.any(damping < 0):
            raise ValueError(f"{name}: damping={tuple(spec.damping)} must be three rates >= 0 "
                             "(1/s)")
        # a boat must float free of the bed: its rest draft below 90% of the water's depth
        draft = hull.rest_level(mass, self.rho) - hull.bottom
        water = self._water()
        depth = float(water["h"].min())
        if draft >= 0.9 * depth:
            raise HullError(f"{name}: its rest draft {draft:.3g} m needs water deeper than "
                            f"{draft / 0.9:.3g} m (the water is {depth:.3g} m deep)")
        k = free[0]
        c = hull.centroid
        inertia = hull.inertia_unit * (mass / hull.volume)
        if spec.mass_height is not None:
            mh = float(spec.mass_height)
            top = float(hull.footprint[..., 1][hull.footprint[..., 1] >= hull.footprint[
                ..., 0]].max())
            if not (math.isfinite(mh) and 0 <= mh <= top - hull.bottom):
                raise ValueError(f"{name}: mass_height={spec.mass_height!r} m must lie within "
                                 f"the hull's height [0, {top - hull.bottom:.4g}] m")
            cm = c + np.array([0.0, hull.bottom + mh, 0.0])
            d = cm - c
            inertia = inertia + mass * (d @ d * np.eye(3) - np.outer(d, d))
            hull = _shift(hull, d)
            c = cm
        com = pos + R @ c
        moments = np.diag(inertia)
        body_from_mesh = np.hstack([base[:, :3], (base[:, 3] - c)[:, None]])
        level = self.origin[1] + float(np.mean(water["h"].astype(np.float64) + water["bed"]))
        self._floor = float(water["bed"].min())
        self._level0 = level
        rec = np.zeros(1, BODY_DTYPE)[0]
        rec["pos"] = (*com, mass)
        rec["quat"] = quat_from_matrix(R)
        rec["vel"] = (0.0, 0.0, 0.0, -hull.bottom)
        rec["omega"] = (0.0, 0.0, 0.0, hull.sample_radius)
        rec["inertia"] = (*moments, spec.added_mass)
        rec["damping"] = (*damping, hull.radius)
        rec["torque"] = (0.0, 0.0, 0.0, level)
        rec["base_r0"], rec["base_r1"], rec["base_r2"] = body_from_mesh
        rec["foot"] = (hull.x0, hull.z0, hull.dfx, hull.dfz)
        rec["foot_n"] = (hull.footprint.shape[1], hull.footprint.shape[0], 0, int(row))
        full = hull.footprint[..., 1] >= hull.footprint[..., 0]
        cols, rows = np.nonzero(full.any(0))[0], np.nonzero(full.any(1))[0]
        rec["flags"] = (1, 0, min(cols[0], full.shape[1] - 1 - cols[-1]),
                        min(rows[0], full.shape[0] - 1 - rows[-1]))
        self._host[k] = rec
        self._hulls[k] = hull
        self._slots.append(k)
        self.names.append(name)
        return k

    def _upload(self) -> None:
        """Footprints (concatenated) and body records to the device; bodies keep their state."""
        parts, off = [], 0
        for k in range(MAX_BOATS):
            hull = self._hulls[k]
            if hull is None:
                self._host[k]["flags"] = (0, 0, 0, 0)
                continue
            self._host[k]["foot_n"][2] = off
            parts.append(hull.footprint.reshape(-1, 2))
            off += hull.footprint.shape[0] * hull.footprint.shape[1]
        foot = np.concatenate(parts) if parts else np.zeros((1, 2), np.float32)
        self._foot = self.rt.to_device(np.ascontiguousarray(foot, np.float32))
        # the still-water level every hull presses against: the level without boats raised by
        # the water they displace at rest (their mass / rho over the pool's area)
        lx, ly = self.sim.size
        if self._slots:
            level = self._level0 + float(self._host["pos"][self._slots, 3].sum()) / (
                self.rho * lx * ly)
            for k in self._slots:
                self._host[k]["torque"][3] = level
        # the whole-grid pass below leaves each hull's head within its bounding circle's box:
        # the box the next update restores (a cell wider than the kernel's own)
        for k in self._slots:
            r = self._host[k]
            r["box"] = r["box_old"] = self._circle_cells(r["pos"][0], r["pos"][2],
                                                         r["damping"][3])
        cl.enqueue_copy(self.rt.queue, self._bodies, self._host)
        self._n = (max(self._slots) + 1) if self._slots else 0
        self.enqueue_press()

    def _circle_cells(self, x: float, z: float, r: float) -> tuple:
        """Cells (i0, j0, i1, j1) whose centres may lie within r of world (x, z), two cells of
        margin, clamped to the grid (kernels/lbm_bodies.cl lbm_body_box has one)."""
        dx, (ox, _, oz) = self.sim.dx, self.origin
        g = [(float(x) - r - ox) / dx - 0.5, (float(z) - r - oz) / dx - 0.5,
             (float(x) + r - ox) / dx - 0.5, (float(z) + r - oz) / dx - 0.5]
        b = [math.floor(g[0]) - 2, math.floor(g[1]) - 2, math.ceil(g[2]) + 2, math.ceil(g[3]) + 2]
        hi = [self.sim.nx - 1, self.sim.ny - 1] * 2
        return tuple(int(min(max(v, 0), h)) for v, h in zip(b, hi, strict=True))

    def add(self, spec: BoatSpec, row: int) -> int:
        """Add a boat writing transform row ``row``; returns its index in :attr:`names`. Reads
        and rewrites the body records (a host round trip: not per frame)."""
        self._sync_host()
        self._add(spec, row)
        self._upload()
        return len(self.names) - 1

    def drop(self, index: int) -> None:
        """Remove boat ``index`` (its transform row is left as it was)."""
        if not 0 <= index < len(self.names):
            raise ValueError(f"drop: boat index {index} out of range [0, {len(self.names)})")
        self._sync_host()
        k = self._slots.pop(index)
        self.names.pop(index)
        self._hulls[k] = None
        self._upload()

    def _sync_host(self) -> None:
        cl.enqueue_copy(self.rt.queue, self._host, self._bodies).wait()

    # -- per frame ------------------------------------------------------------------------------
    def _step_record(self, dt: float, n_sub: int = 1) -> np.void:
        gravity = self.sim.lattice.gravity
        key = (dt, n_sub, self._n, self._floor, gravity)
        rec = self._recs.get(key)
        if rec is None:
            if len(self._recs) >= 8:
                self._recs.clear()
            lx, ly = self.sim.size
            rec = self._recs[key] = record(
                BODY_STEP_DTYPE, origin=(*self.origin, 0.0), dt=dt, gravity=gravity,
                rho=self.rho, n_bodies=self._n, size_x=lx, size_z=ly, floor=self._floor,
                n_sub=n_sub)
        return rec

    def groups_per_boat(self, dt: float) -> int:
        """Work-groups per boat slot in an update of ``dt`` seconds: :attr:`press_groups` if
        set, else enough for :attr:`press_cells` cells per work-item over a bound of the
        cells a boat presses (the rectangle of its bounding circle's box, widened by how far
        it can move at :data:`MAX_SPEED`; after :meth:`place` its old box can lie farther: its
        groups then stride over more cells), at most one wave: the device's compute units
        over the boats (each group of 512 redoes the boat's reduction, so a second wave would
        cost a second reduction's time)."""
        if self.press_groups is not None:
            return int(self.press_groups)
        key = (dt, tuple(self._slots))
        if key != self._groups_key:
            reach = MAX_SPEED * dt * 1.001
            r = max((float(self._host[k]["damping"][3]) for k in self._slots), default=0.0)
            side = math.floor(2.0 * (r + reach) / self.sim.dx) + 8
            area = min(side, self.sim.nx) * min(side, self.sim.ny)
            wg = self.work_group
            cells = wg * max(float(self.press_cells), 1.0 / wg)
            wave = self.rt.device.max_compute_units // max(len(self._slots), 1)
            self._groups = max(1, min(MAX_GROUPS, wave, math.ceil(area / cells)))
            self._groups_key = key
        return self._groups

    @property
    def every(self) -> int:
        """Water steps per coupled update: the most whose time fits in ``max_substep``, >= 1."""
        return max(1, int(self.max_substep / self.sim.dt * (1 + 1e-9)))

    def _quiet_steps(self) -> int:
        """How many of the coming steps' hook calls only count (the call that completes
        :attr:`every` steps updates the boats)."""
        return max(0, self.every - self._held_steps - 1)

    def _water_step(self, dt: float) -> None:
        """The step hook: the boats are updated once :attr:`every` water steps have passed."""
        self._held_s += dt
        self._held_steps += 1
        if self._held_steps >= self.every:
            held, self._held_s, self._held_steps = self._held_s, 0.0, 0
            self.enqueue_step(held)

    def enqueue_step(self, dt: float) -> cl.Event | None:
        """Advance the boats by ``dt`` seconds against the water as it is now (substeps of at
        most ``max_substep``), write their transform rows, then their pressure head for the
        next water steps. Only enqueues: one launch for all boats."""
        if not (isinstance(dt, int | float | np.floating) and math.isfinite(dt) and dt >= 0):
            raise ValueError(f"enqueue_step: dt={dt!r} must be a finite number >= 0 (s)")
        if self._n == 0 or dt == 0:
            return None
        n_sub = max(1, math.ceil(dt / self.max_substep * (1 - 1e-9)))
        groups = self.groups_per_boat(dt)
        sim = self.sim
        self._k_update.bind(f=sim.populations_buffer, zforce=self._zforce, bed=sim.bed_buffer,
                            p=sim.params, foot=self._foot, bodies=self._bodies,
                            out=self._bodies_out, transforms=self.transforms,
                            s=self._step_record(dt / n_sub, n_sub))
        wg = self.work_group
        event = self._k_update.launch(self._n * groups * wg, wg)
        self._bodies, self._bodies_out = self._bodies_out, self._bodies
        return event

    def enqueue_press(self) -> cl.Event | None:
        """Write the hulls' pressure head into the bed the water's force sees over every cell
        (the updates write it over the hulls' boxes only)."""
        sim = self.sim
        self._k_press_all.bind(bed=sim.bed_buffer, zforce=self._zforce, p=sim.params,
                               foot=self._foot, bodies=self._bodies, s=self._step_record(0.0))
        return self._k_press_all.launch((sim.nx, sim.ny), (64, 1) if self.rt.is_gpu else None)

    # -- host reads (tests, saving) -------------------------------------------------------------
    def state(self) -> np.ndarray:
        """The body records (``BODY_DTYPE``) of the boats, in :attr:`names` order (host copy)."""
        self._sync_host()
        return self._host[self._slots].copy()

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre-of-mass positions (n, 3) m and rotations (n, 4) as quaternions (w, x, y, z)."""
        s = self.state()
        return (s["pos"][:, :3].astype(np.float64).copy(),
                s["quat"].astype(np.float64).copy())

    def mesh_transforms(self) -> np.ndarray:
        """world_from_mesh (n, 3, 4) of the boats now, float64 from their records (host copy):
        the rows the bodies kernel writes into the transform buffer."""
        s = self.state()
        out = np.empty((len(s), 3, 4))
        for i, r in enumerate(s):
            R = matrix_from_quat(r["quat"])
            base = np.stack([r["base_r0"], r["base_r1"], r["base_r2"]]).astype(np.float64)
            out[i] = R @ base
            out[i][:, 3] += r["pos"][:3]
        return out

    def velocities(self) -> tuple[np.ndarray, np.ndarray]:
        """Linear (n, 3) m/s and angular (n, 3) rad/s velocities."""
        s = self.state()
        return s["vel"][:, :3].astype(np.float64), s["omega"][:, :3].astype(np.float64)

    def hull(self, index: int) -> Hull:
        return self._hulls[self._slots[index]]

    def pressure_head(self) -> np.ndarray:
        """The hulls' pressure head (ny, nx) m on the water (zforce - bed; a host copy)."""
        n = self.sim.n_cells
        z = self.rt.to_host(self._zforce, np.float32, n)
        b = self.rt.to_host(self.sim.bed_buffer, np.float32, n)
        return (z - b).reshape(self.sim.ny, self.sim.nx)

    def _index(self, what: str, index: int) -> int:
        if isinstance(index, bool) or not isinstance(index, int | np.integer) or not (
                0 <= index < len(self.names)):
            raise ValueError(f"{what}: boat index {index!r} out of range [0, {len(self.names)})")
        return self._slots[int(index)]

    def place(self, index: int, position, *, heading: float | None = 0.0, velocity=None,
              hold: bool = False) -> None:
        """Move boat ``index``'s centre of mass to ``position`` (world m), upright, turned
        ``heading`` rad about +y from its placed frame (None: keeps its heading now), at rest
        or moving at ``velocity`` (m/s): a boat dropped from above (the window's B key).
        ``hold``: it stays there, at rest, its hull pressing on the water, until
        :meth:`release`. A host round trip (it waits for the queue): not per frame."""
        k = self._index("place", index)
        pos = _finite3("position", position)
        vel = np.zeros(3) if velocity is None else _finite3("velocity", velocity)
        self._sync_host()
        if heading is None:   # the body's x axis projected on the horizontal plane
            R = matrix_from_quat(self._host[k]["quat"])
            heading = math.atan2(-R[2, 0], R[0, 0]) if math.hypot(R[0, 0], R[2, 0]) > 1e-6 \
                else 0.0
        if not math.isfinite(heading):
            raise ValueError(f"place: heading={heading!r} must be finite (rad)")
        self._host[k]["pos"][:3] = pos
        self._host[k]["quat"] = (math.cos(heading / 2), 0.0, math.sin(heading / 2), 0.0)
        self._host[k]["vel"][:3] = 0.0 if hold else vel
        self._host[k]["omega"][:3] = 0.0
        self._host[k]["flags"][1] = int(bool(hold))
        cl.enqueue_copy(self.rt.queue, self._bodies, self._host)

    def release(self, index: int, velocity=None) -> None:
        """Let a held boat go (see :meth:`place`), at rest or moving at ``velocity`` (m/s)."""
        k = self._index("release", index)
        vel = None if velocity is None else _finite3("velocity", velocity)
        self._sync_host()
        self._host[k]["flags"][1] = 0
        if vel is not None:
            self._host[k]["vel"][:3] = vel
        cl.enqueue_copy(self.rt.queue, self._bodies, self._host)

    def held(self, index: int) -> bool:
        """Whether boat ``index`` is held (host record, no device read)."""
        return bool(self._host[self._index("held", index)]["flags"][1])

    def rest_position(self, index: int, x: float, z: float, keel: float | None = None):
        """World position of boat ``index``'s centre of mass upright over world (x, z) with its
        keel ``keel`` m above the still water (None: at its rest draft, afloat). No device read."""
        k = self._index("rest_position", index)
        hull = self._hulls[k]
        level = float(self._host[k]["torque"][3])      # the still water with the boats in it
        if keel is None:
            y = level - hull.rest_level(float(self._host[k]["pos"][3]), self.rho)
        else:
            y = level + float(keel) - hull.bottom
        return np.array([float(x), y, float(z)])

    def set_velocity(self, index: int, velocity) -> None:
        """Set boat ``index``'s velocity (m/s): a push or a tow (a host round trip)."""
        k = self._index("set_velocity", index)
        vel = _finite3("velocity", velocity)
        self._sync_host()
        self._host[k]["vel"][:3] = vel   # w: the keel depth
        cl.enqueue_copy(self.rt.queue, self._bodies, self._host)


def hull_proxy(V, F, deck: float, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed stand-in for a hull that is not a closed mesh (a game asset with open parts): the
    solid between the mesh's lowest surface and the height ``deck``, as one closed box per
    column of a ``spacing`` grid (coincident faces of neighbouring boxes cancel in every
    integral; each box is closed, so :func:`check_closed` accepts the union). Returns (V, F)."""
    V = np.asarray(V, np.float64)
    lo, hi = V.min(0), V.max(0)
    nx = max(1, int(math.ceil((hi[0] - lo[0]) / spacing)))
    nz = max(1, int(math.ceil((hi[2] - lo[2]) / spacing)))
    zz, xx = np.mgrid[0:nz, 0:nx]
    xs = lo[0] + (xx.ravel() + 0.5) * spacing
    zs = lo[2] + (zz.ravel() + 0.5) * spacing
    bottom, _ = vertical_hits(V, np.asarray(F, np.int64), xs, zs)
    keep = np.isfinite(bottom) & (bottom < deck)
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (0, 1) for z in (-0.5, 0.5)])
    box_f = np.array([(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
                      (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)])
    verts, faces = [], []
    for k, (x, z, b) in enumerate(zip(xs[keep], zs[keep], bottom[keep], strict=True)):
        c = corners.copy()
        c[:, 0] = x + c[:, 0] * spacing
        c[:, 2] = z + c[:, 2] * spacing
        c[:, 1] = np.where(c[:, 1] > 0, deck, b)
        verts.append(c)
        faces.append(box_f + 8 * k)
    if not verts:
        raise HullError(f"no part of the mesh lies below the deck height {deck:g}")
    return np.concatenate(verts), np.concatenate(faces)
