"""The light buffer's host side (kernels/light_buffer.h, light_buffer.cl): which lights get a
map, where each map lies, the triangles it lists, and the per-frame build.

A shadow ray toward a directional light can only be blocked by the opaque triangles whose
shadow falls where its origin does. The map lists them per cell; the shadow kernels test those
few (the traversal's own triangle test, so the answer is the BVH's, bit for bit) instead of
walking the TLAS and BLASes, and fall back to the walk where a cell, and its fine cell (below),
list more than ``LB_SLOTS``. What it covers: the instances the shadow rays' any-hit query sees
(the opaque ones when the scene has a dielectric, else all), when each is a mesh the host holds;
none otherwise (a height field, a mesh given as device buffers), and no spot light (their rays
walk the BVH as before).
A cell that lists more (a boat's rigging, whose tiny triangles stack along the light) gets a
fine grid of ``LB_FINE`` x ``LB_FINE`` cells of its own while the map's grids last
(:func:`fine_grids_for`); only a full fine cell leaves its rays to the walk.

Per build (:meth:`LightBuffer.enqueue`, when the transform rows were written since the last):
``light_buffer_clear`` over every map's cells, then per map ``light_buffer_raster`` (a work-item
per triangle, moved by its instance's live transform row: a boat that a device stage moves is
followed with no host copy) and ``light_buffer_raster_big`` (the triangles over more than 32
cells: a work-group each, or the whole launch for those over 4096), both listing the (triangle,
cell) pairs past a cell's slots, then ``light_buffer_fine`` (the full cells' grids handed out,
their slots' triangles added to the pairs) and ``light_buffer_fine_raster`` (each pair's triangle
in its cell's fine cells, a work-item per pair and fine row).
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime
from raytrace.render_types import MAX_LIGHTS, LightKind

_F4 = (np.float32, 4)
#: Mirror of ``LightBuffer`` (kernels/light_buffer.h), 96 bytes.
LIGHT_BUFFER = np.dtype([("u", _F4), ("v", _F4), ("toward", _F4), ("n_u", np.int32),
                         ("n_v", np.int32), ("cell_base", np.int32), ("outside_cell", np.int32),
                         ("big_cell", np.int32), ("margin", np.float32),
                         ("depth_slack", np.float32), ("fine_base", np.int32),
                         ("fine_grids", np.int32), ("fine_cell", np.int32),
                         ("fine_pairs", np.int32), ("pad", np.int32)])
LB_SLOTS = 16           #: kernels/light_buffer.h
LB_FINE = 8             #: kernels/light_buffer.h: a fine grid's cells along each side
LB_FINE_SLOTS = 32      #: kernels/light_buffer.h: triangles a fine cell lists
_FINE_STRIDE = LB_FINE_SLOTS // LB_SLOTS   # cells' room a fine cell takes (LB_FINE_STRIDE)
#: Most cells along a map's side.
MAX_CELLS = 8192
#: Most triangles listed: past it the per-frame raster would cost more than the walks it saves.
MAX_TRIANGLES = 1 << 20
#: How far a map reaches past its triangles' footprint when it was planned, as a fraction of
#: that footprint's extent on each side (a floating boat drifts; past the map, rays walk the BVH).
DOMAIN_PAD = 0.1
#: Most work-items light_buffer_raster starts (they stride over the triangles).
_MAX_ITEMS = 1 << 20


#: (triangle, full cell) pairs a map's list has room for, per fine grid: the grid's LB_SLOTS and
#: twice as many again past them on average (the baseline scene's 1,431 full cells at 1024
#: cells: 48,138 pairs, against room for 129,984).
PAIRS_PER_GRID = 3 * LB_SLOTS
#: Most work-items light_buffer_fine_raster starts (they stride over the pairs' rows).
_MAX_FINE_ITEMS = 1 << 18


def fine_grids_for(map_cells: int) -> int:
    """Fine grids a map of ``map_cells`` cells has room for: one per 256 cells (2,708 for the
    baseline scene's map of 1024 x 677, which fills 1,431; 9 KiB a grid), at least 16."""
    return max(16, map_cells // 256)


class LightBuffer:
    """The maps of one renderer: ``cells`` along a map's longer side (0: none)."""

    def __init__(self, rt: Runtime, cells: int, stage: str = "render.light_buffer",
                 fine_grids: int | None = None, pairs_per_grid: int = PAIRS_PER_GRID):
        # checked with the settings (RenderSettings.resolved: [0, MAX_CELLS])
        self.rt, self.cells, self.stage = rt, int(cells), stage
        #: fine grids per map (None: :func:`fine_grids_for` its cells) and room for the pairs
        #: that fill them per grid (tests and studies)
        self.fine_grids, self.pairs_per_grid = fine_grids, int(pairs_per_grid)
        self.maps = np.zeros(MAX_LIGHTS, LIGHT_BUFFER)
        self.n_tris = 0
        self.n_cells = 0               #: cells of every map, then three counters per map
        self.n_map_cells = 0           #: cells of every map
        self.n_fine_cells = 0          #: the maps' fine grids' cells, after n_cells
        self.reason = "not planned"    #: why no light has a map ("" when one has)
        self._key = None
        self._generation = 0           # plans made (each replaces the buffers)
        self._built = None             # (rows_version, generation) of the last build
        self.builds = 0                #: builds enqueued
        self._alloc(np.zeros((1, 4), np.float32), 1)
        self._kernels = None           # built with the first map (none: no program to build)
        # the big triangles' launch: a few work-groups per compute unit share each one's cells
        self._big_items = 4 * 256 * rt.device.max_compute_units

    def _launchers(self) -> tuple:
        if self._kernels is None:
            self._kernels = tuple(
                self.rt.kernel_launcher("light_buffer.cl", f"light_buffer_{name}",
                                        stage=f"{self.stage}.{stage}")
                for name, stage in (("clear", "clear"), ("raster", "raster"),
                                    ("raster_big", "big"), ("fine", "fine"),
                                    ("fine_raster", "fine")))
        return self._kernels

    def _alloc(self, tris: np.ndarray, n_cells: int) -> None:
        """The buffers for ``n_cells`` cells, counters and fine cells."""
        rt = self.rt
        self.maps_buf = rt.to_device(self.maps)
        self.tris_buf = rt.to_device(tris)
        self.cells_buf = rt.buffer(8 * max(n_cells, 1))
        self.slots_buf = rt.buffer(4 * LB_SLOTS * max(n_cells, 1))
        self.pairs_buf = rt.buffer(8 * max(int(self.maps["fine_pairs"].max()), 1))
        self.big_buf = rt.buffer(4 * max(len(tris) // 3, 1))   # light_buffer_raster_big's list

    @property
    def active(self) -> bool:
        """Whether any light has a map."""
        return bool((self.maps["n_u"] > 0).any())

    def bindings(self) -> dict:
        """``LIGHT_BUFFER_PARAMS`` (kernels/light_buffer.h) by name."""
        return {"lb_maps": self.maps_buf, "lb_cells": self.cells_buf,
                "lb_slots": self.slots_buf, "lb_tris": self.tris_buf}

    # -- planning --------------------------------------------------------------------------
    def plan(self, render_scene, any_hit_mask: int) -> bool:
        """Decide the maps for ``render_scene`` (after its update: masks and lights set) whose
        shadow rays' any-hit query sees the instances of ``any_hit_mask``; redone only when the
        meshes, instances, masks or lights changed. True when the buffers were replaced (the
        kernels must be bound again)."""
        sc = render_scene.scene
        masks = tuple(sc.instance_mask(i) for i in range(sc.n_instances))
        key = (self.cells, len(render_scene.meshes), masks, render_scene.lights.tobytes(),
               int(any_hit_mask))
        if key == self._key:
            return False
        self._key = key
        self._generation += 1
        self.maps = np.zeros(MAX_LIGHTS, LIGHT_BUFFER)
        tris, self.reason = self._triangles(render_scene, masks, int(any_hit_mask))
        lights = render_scene.lights
        directional = [i for i in range(len(lights))
                       if int(lights[i]["kind"]) == int(LightKind.DIRECTIONAL)]
        if not directional and not self.reason:
            self.reason = "no directional light"
        n_cells = 0
        if not self.reason:
            world = self._world_vertices(render_scene.scene, tris)
            for i in directional:
                n_cells = self._plan_map(i, -lights[i]["direction"][:3], world, n_cells)
            self.n_map_cells = n_cells
            for k, i in enumerate(directional):   # their counters after every map's cells
                self.maps[i]["outside_cell"] = n_cells + 3 * k
                self.maps[i]["big_cell"] = n_cells + 3 * k + 1
                self.maps[i]["fine_cell"] = n_cells + 3 * k + 2
            n_cells += 3 * len(directional)
        self.n_tris = 0 if self.reason else len(tris) // 3
        self.n_cells, n_fine = n_cells, 0
        for i in directional if not self.reason else ():   # their fine grids after the counters
            m = self.maps[i]
            grids = (fine_grids_for(int(m["n_u"] * m["n_v"])) if self.fine_grids is None
                     else int(self.fine_grids))
            m["fine_base"], m["fine_grids"] = n_cells + n_fine, grids
            m["fine_pairs"] = grids * self.pairs_per_grid
            n_fine += grids * LB_FINE * LB_FINE * _FINE_STRIDE
        self.n_fine_cells = n_fine
        self._alloc(tris if self.n_tris else np.zeros((1, 4), np.float32), n_cells + n_fine)
        return True

    def _triangles(self, render_scene, masks, mask: int) -> tuple[np.ndarray, str]:
        """lb_tris: three float4 per triangle of the instances ``mask`` sees, object space,
        p0.w = the instance id's bits; or an empty array and why there is none."""
        if self.cells == 0:
            return np.zeros((0, 4), np.float32), "off"
        out, n = [], 0
        for inst, m in enumerate(masks):
            if not m & mask:
                continue
            mesh = render_scene.meshes[int(render_scene.instances[inst]["mesh"])]
            if mesh["vertices"] is None or mesh["dynamic"]:
                return np.zeros((0, 4), np.float32), (
                    f"instance {inst} is a mesh the device writes (a height field or dynamic)")
            v = np.asarray(mesh["vertices"], np.float32)
            t = np.asarray(mesh["triangles"], np.int64)
            q = np.zeros((len(t), 3, 4), np.float32)
            q[:, :, :3] = v[t]
            q[:, 0, 3] = np.array([inst], np.int32).view(np.float32)[0]
            out.append(q.reshape(-1, 4))
            n += len(t)
            if n > MAX_TRIANGLES:
                return np.zeros((0, 4), np.float32), f"more than {MAX_TRIANGLES} triangles"
        if not out:
            return np.zeros((0, 4), np.float32), ""
        return np.concatenate(out), ""

    @staticmethod
    def _world_vertices(scene, tris: np.ndarray) -> np.ndarray:
        """The listed triangles' vertices in world space by the transforms the host wrote."""
        q = tris.reshape(-1, 3, 4)
        rows = scene.read_host_transforms().astype(np.float64)[q[:, 0, 3].view(np.int32)]
        p = q[:, :, :3].astype(np.float64)
        return (np.einsum("nij,nkj->nki", rows[:, :, :3], p) + rows[:, None, :, 3]).reshape(-1, 3)

    def _plan_map(self, light: int, toward, world: np.ndarray, n_cells: int) -> int:
        """Map ``light`` across the unit direction ``toward`` over the footprint of ``world``
        (padded by DOMAIN_PAD), its cells from ``n_cells``; returns the cells used so far."""
        m = self.maps[light]
        t32 = np.asarray(toward, np.float32)
        t = t32.astype(np.float64)
        a = np.array([1.0, 0.0, 0.0]) if abs(t[1]) < 0.9 else np.array([0.0, 0.0, 1.0])
        eu = np.cross(a, t)
        eu /= np.linalg.norm(eu)
        ev = np.cross(t, eu)
        if len(world):
            pu, pv = world @ eu, world @ ev
            lo = np.array([pu.min(), pv.min()])
            hi = np.array([pu.max(), pv.max()])
            reach = float(np.abs(world).max())
        else:
            lo, hi, reach = np.zeros(2), np.ones(2), 1.0
        ext = np.maximum(hi - lo, 1e-6)
        lo, hi = lo - DOMAIN_PAD * ext, hi + DOMAIN_PAD * ext
        size = float((hi - lo).max()) / self.cells
        n_u, n_v = (int(np.ceil((hi[k] - lo[k]) / size)) for k in (0, 1))
        n_u, n_v = max(1, min(n_u, self.cells)), max(1, min(n_v, self.cells))
        m["u"] = (*(eu / size), -lo[0] / size)
        m["v"] = (*(ev / size), -lo[1] / size)
        m["toward"][:3] = t32
        m["n_u"], m["n_v"], m["cell_base"] = n_u, n_v, n_cells
        # float32 rounding of the projections and depths: ~1e-6 of the coordinates, grown 10x
        scale = reach + float((hi - lo).max())
        m["margin"] = 1.0 / 64 + 1e-5 * scale / size
        m["depth_slack"] = 1e-5 * scale
        return n_cells + n_u * n_v

    # -- per frame -------------------------------------------------------------------------
    def enqueue(self, transform_buffer: cl.Buffer, rows_version: int | None = None) -> bool:
        """Clear and fill every map from the instances' live transform rows (enqueued), unless
        they are the rows of the last build (``rows_version``: raytrace.scene.Scene's count of
        writes; None: build). Returns whether it built."""
        if not self.active:
            return False
        key = (rows_version, self._generation)
        if rows_version is not None and key == self._built:
            return False
        self._built = key
        self.builds += 1
        clear, raster, raster_big, fine, fine_raster = self._launchers()
        clear.bind(lb_cells=self.cells_buf, n_cells=self.n_cells, n_map_cells=self.n_map_cells)
        clear.launch(self.n_cells, 256)
        if self.n_tris == 0:
            return True
        cells = {"lb_maps": self.maps_buf, "lb_cells": self.cells_buf, "lb_slots": self.slots_buf,
                 "lb_pairs": self.pairs_buf}
        tris = {"lb_tris": self.tris_buf, "xforms": transform_buffer}
        raster.bind(**cells, **tris, lb_big=self.big_buf, n_tris=self.n_tris)
        raster_big.bind(**cells, **tris, lb_big=self.big_buf, n_tris=self.n_tris)
        fine.bind(**cells)
        fine_raster.bind(**cells, **tris)
        items = min(self.n_tris, _MAX_ITEMS)
        for light in np.flatnonzero(self.maps["n_u"] > 0):
            m = self.maps[light]
            for k in (raster, raster_big, fine, fine_raster):
                k.bind(light=int(light))
            raster.launch(-(-items // 64) * 64, 64)
            raster_big.launch(self._big_items, 256)
            fine.launch(-(-int(m["n_u"] * m["n_v"]) // 256) * 256, 256)
            rows = min(int(m["fine_pairs"]) * LB_FINE, _MAX_FINE_ITEMS)
            fine_raster.launch(-(-rows // 256) * 256, 256)
        return True

    def read(self, light: int) -> dict:
        """Light ``light``'s map as host arrays (synchronises; tests and studies): ``count``
        and ``depth`` (n_v, n_u), ``slots`` (n_v, n_u, LB_SLOTS), ``outside`` (triangles that
        reached off the map), ``big`` (those left to light_buffer_raster_big), ``grid`` (n_v,
        n_u: each full cell's fine grid, -1 none or not full), ``fine_grids`` (grids the full
        cells asked for, handed out or not), ``fine_pairs`` (the pairs listed for them: past the
        map's ``fine_pairs`` no grid is read), and the grids' ``fine_count`` (grids, LB_FINE,
        LB_FINE) and ``fine_slots`` (grids, LB_FINE, LB_FINE, LB_FINE_SLOTS)."""
        m = self.maps[light]
        if m["n_u"] == 0:
            raise ValueError(f"light {light} has no map ({self.reason or 'not directional'})")
        n = int(m["n_u"] * m["n_v"])
        base = int(m["cell_base"])
        cells = self.rt.to_host(self.cells_buf, np.int32, 2 * n, 2 * base).reshape(-1, 2)
        counters = self.rt.to_host(self.cells_buf, np.int32, 6, 2 * int(m["outside_cell"]))
        slots = self.rt.to_host(self.slots_buf, np.int32, LB_SLOTS * n, LB_SLOTS * base)
        shape = (int(m["n_v"]), int(m["n_u"]))
        count = cells[:n, 0].reshape(shape)
        slots = slots.reshape(*shape, LB_SLOTS)
        asked = int(counters[4])
        g, fb = min(asked, int(m["fine_grids"])), int(m["fine_base"])
        per = LB_FINE * LB_FINE * _FINE_STRIDE   # cells' entries a grid takes
        fine = self.rt.to_host(self.cells_buf, np.int32, 2 * max(g * per, 1), 2 * fb)
        fslots = self.rt.to_host(self.slots_buf, np.int32, LB_SLOTS * max(g * per, 1),
                                 LB_SLOTS * fb)
        return {"count": count, "depth": ordered_to_float(cells[:n, 1]).reshape(shape),
                "slots": slots, "outside": int(counters[0]),
                "big": int(counters[2] + counters[3]),
                "grid": np.where(count > LB_SLOTS, slots[..., 0], -1), "fine_grids": asked,
                "fine_pairs": int(counters[5]),
                "fine_count": fine[0:2 * g * per:2 * _FINE_STRIDE].reshape(g, LB_FINE, LB_FINE),
                "fine_slots": fslots[:LB_SLOTS * g * per].reshape(g, LB_FINE, LB_FINE,
                                                                   LB_FINE_SLOTS)}


def ordered_to_float(i: np.ndarray) -> np.ndarray:
    """kernels/bvh.h's ordered_to_float over an int32 array."""
    i = np.asarray(i, np.int32)
    return np.where(i >= 0, i, i ^ np.int32(0x7FFFFFFF)).astype(np.int32).view(np.float32)
