"""``raytrace.intersect``: NumPy rays against a NumPy mesh, traced by the renderer's own device
code (``kernels/traverse.h`` through ``kernels/trace_query.cl``).

Also :class:`RayQuery`, which binds the query kernels to a :class:`~raytrace.scene.Scene` once
and traces device ray buffers (float4 origin with tmin in w, float4 direction with tmax in w)
into a device buffer of ``Hit`` records: what the benchmark and tests use without host copies.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime, get_runtime
from raytrace.bvh import HIT_DTYPE
from raytrace.scene import MASK_ALL, Scene

#: Work-items per ray of the cooperative walk (kernels/traverse_coop.h TRACE_COOP_WIDTH) and the
#: most work-groups a cooperative launch uses (a grid stride covers the rest).
COOP_WIDTH = 32
COOP_MAX_GROUPS = 8192
#: The renderer's cooperative kernels take a work-group per ray only for a level of at most so
#: many rays, else a work-item per ray (kernels/traverse_coop.h TRACE_COOP_MAX_RAYS). 16384, not
#: the 4096 before: on the H200 the pool's tail levels (4k-12k rays, counts that vary between
#: frames) took 4.04 instead of 4.14 kernel ms a frame; 36k rays a group each were 2x slower.
COOP_MAX_RAYS = 16384


def pack_rays(origins, directions, tmin=0.0, tmax=np.inf) -> tuple[np.ndarray, np.ndarray]:
    """(n,4) float32 origin|tmin and direction|tmax arrays, validated; one-line ValueErrors."""
    for name, a in (("origins", origins), ("directions", directions)):
        if np.iscomplexobj(a):
            raise TypeError(f"{name} must be real numbers, got {np.asarray(a).dtype}")
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    if o.ndim != 2 or o.shape[1] != 3:
        raise ValueError(f"origins must have shape (n, 3), got {o.shape}")
    if d.shape != o.shape:
        raise ValueError(f"directions must have the shape of origins {o.shape}, got {d.shape}")
    n = len(o)
    lo = np.broadcast_to(np.asarray(tmin, dtype=np.float64), (n,))
    hi = np.broadcast_to(np.asarray(tmax, dtype=np.float64), (n,))
    if not (np.isfinite(o).all() and np.isfinite(d).all()):
        raise ValueError("origins and directions must be finite")
    if np.isnan(lo).any() or np.isnan(hi).any():
        raise ValueError("tmin and tmax must not be NaN")
    if (~(d != 0).any(axis=1)).any():
        raise ValueError(f"direction {int(np.flatnonzero(~(d != 0).any(axis=1))[0])} is zero")
    ro = np.empty((n, 4), np.float32)
    rd = np.empty((n, 4), np.float32)
    with np.errstate(over="ignore", under="ignore"):
        ro[:, :3], ro[:, 3] = o, lo
        rd[:, :3], rd[:, 3] = d, hi
    if not (np.isfinite(ro[:, :3]).all() and np.isfinite(rd[:, :3]).all()):
        raise ValueError("origins and directions must be finite in float32 (|x| < 3.4e38)")
    if (~(rd[:, :3] != 0).any(axis=1)).any():   # a tiny direction that float32 rounds to 0
        raise ValueError(f"direction {int(np.flatnonzero(~(rd[:, :3] != 0).any(axis=1))[0])} "
                         "is zero in float32")
    return ro, rd


class RayQuery:
    """Closest-hit or any-hit queries of device rays against a scene (kernels bound once)."""

    def __init__(self, scene: Scene, org: cl.Buffer, dirs: cl.Buffer, hits: cl.Buffer, n: int,
                 *, any_hit: bool = False, stage: str = "trace", defines: dict | None = None,
                 mask: int = MASK_ALL, coop: bool = False, only: int = -1):
        """``defines``: extra build defines of ``trace_query.cl`` (e.g. ``{"TRACE_CPU": 0}``
        to time the GPU flavour of the traversal on a CPU; see kernels/traverse.h). ``mask``:
        the rays see the instances whose visibility mask shares a bit with it
        (Scene.set_instance_mask). ``coop``: one ray per work-group of 32 tracing it together
        (kernels/traverse_coop.h; binary layout, else each work-item alone). ``only`` >= 0:
        that instance alone, with no TLAS walk (its BLAS, or its height-field walk; the caller
        knows it is the one ``mask`` can match)."""
        self.rt, self.n, self.stage, self.coop = scene.rt, int(n), stage, bool(coop)
        name = ("trace_any" if any_hit else "trace_closest") + ("_coop" if coop else "")
        defines = {**scene.trace_defines, **({"TRACE_COOP": 1} if coop else {}),
                   **(defines or {})}
        self._k = scene.rt.kernel_launcher("trace_query.cl", name, stage=stage, defines=defines)
        if not -1 <= int(only) < scene.n_instances:
            raise ValueError(f"only must be -1 or an instance id below {scene.n_instances}, "
                             f"got {only}")
        self._k.bind(**scene.trace_bindings(), n=self.n, org=org, dir=dirs, hits=hits,
                     mask=int(mask), only=int(only))
        # kernel arguments hold no references: keep the buffers alive as long as the query
        self._scene, self.org, self.dirs, self.hits = scene, org, dirs, hits

    def rebind_scene(self) -> None:
        """Call after the scene reallocated its buffers (a mesh or instance was added)."""
        self._k.bind(**self._scene.trace_bindings())

    def enqueue(self, local_size: int | None = 64) -> cl.Event:
        if self.coop:   # a work-group of COOP_WIDTH per ray, at most COOP_MAX_GROUPS
            return self._k.launch(COOP_WIDTH * max(1, min(self.n, COOP_MAX_GROUPS)), COOP_WIDTH)
        return self._k.launch(self.n, local_size)


def intersect(vertices, triangles, origins, directions, *, tmin=0.0, tmax=np.inf,
              any_hit: bool = False, device: str | Runtime | None = None) -> dict:
    """Trace rays against one triangle mesh on the device.

    ``vertices`` (n,3), ``triangles`` (m,3) integer indices, ``origins``/``directions`` (k,3)
    (directions need not be unit; ``t`` is in units of them); ``tmin``/``tmax`` scalars or (k,).
    Returns NumPy arrays: ``t`` (inf on a miss), ``prim`` (-1 on a miss), ``u``, ``v``
    (Embree's barycentrics: P = (1-u-v) p0 + u p1 + v p2) and ``hit`` (bool). With ``any_hit``
    the hit reported is the first found, not necessarily the closest.
    """
    rt = get_runtime(device)
    ro, rd = pack_rays(origins, directions, tmin, tmax)
    scene = Scene(rt, stage="intersect.bvh")
    scene.add_instance(scene.add_mesh(vertices, triangles))
    scene.update()
    n = len(ro)
    out = {"t": np.full(n, np.inf, np.float32), "prim": np.full(n, -1, np.int32),
           "u": np.zeros(n, np.float32), "v": np.zeros(n, np.float32),
           "hit": np.zeros(n, bool)}
    if n == 0:
        return out
    hits = rt.buffer(HIT_DTYPE.itemsize * n)
    q = RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits, n, any_hit=any_hit,
                 stage="intersect.trace")
    q.enqueue()
    h = rt.to_host(hits, HIT_DTYPE, n)
    scene.check()
    miss = h["prim"] < 0
    out["t"] = np.where(miss, np.inf, h["t"]).astype(np.float32)
    out["prim"] = h["prim"]
    out["u"] = np.where(miss, 0, h["u"]).astype(np.float32)
    out["v"] = np.where(miss, 0, h["v"]).astype(np.float32)
    out["hit"] = ~miss
    return out


def intersect_reference(vertices, triangles, origins, directions, tmin=0.0, tmax=np.inf,
                chunk: int = 256) -> dict:
    """Float64 NumPy reference of :func:`intersect` (closest hit, brute force over all triangles).

    Closed, two-sided triangles (Moller-Trumbore in float64); O(rays x triangles): tests and the
    benchmark's correctness check only.

    Returns t (inf on a miss), prim (-1), u, v in Embree's convention.
    """
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles, np.int64)
    o = np.asarray(origins, np.float64)
    d = np.asarray(directions, np.float64)
    p0, p1, p2 = v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    n = len(o)
    lo = np.broadcast_to(np.asarray(tmin, np.float64), (n,))
    hi = np.broadcast_to(np.asarray(tmax, np.float64), (n,))
    out = {"t": np.full(n, np.inf), "prim": np.full(n, -1, np.int64), "u": np.zeros(n),
           "v": np.zeros(n)}
    for s in range(0, n, chunk):
        oo, dd = o[s:s + chunk, None, :], d[s:s + chunk, None, :]
        pv = np.cross(dd, e2[None])
        det = (e1[None] * pv).sum(-1)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inv = 1.0 / det
            tv = oo - p0[None]
            u = (tv * pv).sum(-1) * inv
            q = np.cross(tv, e1[None])
            w = (dd * q).sum(-1) * inv
            t = (e2[None] * q).sum(-1) * inv
            ok = ((det != 0) & (u >= 0) & (w >= 0) & (u + w <= 1)
                  & (t >= lo[s:s + chunk, None]) & (t < hi[s:s + chunk, None]))
        t = np.where(ok, t, np.inf)
        j = np.argmin(t, axis=1)
        rows = np.arange(len(j))
        best = t[rows, j]
        hit = np.isfinite(best)
        out["t"][s:s + chunk] = best
        out["prim"][s:s + chunk] = np.where(hit, j, -1)
        out["u"][s:s + chunk] = np.where(hit, u[rows, j], 0)
        out["v"][s:s + chunk] = np.where(hit, w[rows, j], 0)
    return out
