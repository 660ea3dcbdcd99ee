"""A grid mesh traced as a height field: the cells walked along the ray, no BVH (water surfaces).

A mesh added with ``Scene.add_mesh(..., grid=(nx, ny))`` is an ``nx x ny`` vertex grid, vertex
``(i, j)`` at index ``j*nx + i`` lying at ``x0 + i dx, z0 + j dz`` in object space (``y`` free),
with the triangles of ``lbm.grid_triangles`` (quad ``q = j*(nx-1) + i``: triangles ``2q`` and
``2q+1``). Its per-frame pass, ``heightfield_bounds`` (``kernels/heightfield.cl``), writes the
y range and a slope bound of every 8 x 8 block of cells and the grid's box and slope bound: one
launch reading the vertices once, in place of a BVH refit (several launches, about 100 B of
nodes and leaf triangles per triangle). Rays walk its cells (``kernels/traverse_heightfield.h``)
and get the BVH's hit bit for bit; a ray that departs from the surface faster than the slopes
skips what it cannot meet. The kernels read the vertex buffer the writer fills: no copy.
"""

from __future__ import annotations

import math

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime

#: ``HeightField`` of kernels/heightfield.h (128 bytes).
HEIGHTFIELD_DTYPE = np.dtype([
    ("lo", np.float32, 4), ("hi", np.float32, 4), ("x0", np.float32), ("z0", np.float32),
    ("cells_per_x", np.float32), ("cells_per_z", np.float32), ("nx", np.int32), ("ny", np.int32),
    ("nbx", np.int32), ("nby", np.int32), ("mesh", np.int32), ("n_bad", np.int32),
    ("ticket", np.int32), ("acc_bad", np.int32), ("acc_lo", np.int32, 4),
    ("acc_hi", np.int32, 4), ("slope", np.float32), ("acc_rise_x", np.int32),
    ("acc_rise_z", np.int32), ("pad0", np.int32)])
#: kernels/heightfield.h: cells per side of a y-range block, the bounds pass's work-group, and
#: the mesh id of no height field.
HF_BLOCK = 8
HF_WG = 64
HF_NONE = -1
#: kernels/heightfield.h: HeightField.slope's factor over the grid's largest edge steps.
HF_SLOPE_MARGIN = 1.05
_INT_MAX, _INT_MIN = 2**31 - 1, -(2**31)


def grid_blocks(nx: int, ny: int) -> tuple[int, int]:
    """Blocks of ``HF_BLOCK x HF_BLOCK`` cells along x and z of an ``nx x ny`` vertex grid."""
    return math.ceil((nx - 1) / HF_BLOCK), math.ceil((ny - 1) / HF_BLOCK)


def check_grid_triangles(triangles: np.ndarray, nx: int, ny: int, what: str) -> None:
    """Raise ValueError unless ``triangles`` are the grid's (quad q: (a, c, b), (b, c, d))."""
    for name, v in (("nx", nx), ("ny", ny)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 2:
            raise ValueError(f"{what}: grid {name}={v!r} must be an integer >= 2")
    t = np.asarray(triangles).reshape(-1, 3)
    n_quads = (nx - 1) * (ny - 1)
    if len(t) != 2 * n_quads:
        raise ValueError(f"{what}: a {nx}x{ny} grid has {2 * n_quads} triangles, got {len(t)}")
    j, i = np.divmod(np.arange(n_quads, dtype=np.int64), nx - 1)
    a = j * nx + i
    quads = t.astype(np.int64).reshape(n_quads, 6)
    want = np.stack([a, a + nx, a + 1, a + 1, a + nx, a + nx + 1], axis=1)
    bad = np.flatnonzero((quads != want).any(axis=1))
    if len(bad):
        q = int(bad[0])
        raise ValueError(f"{what}: triangles {2 * q} and {2 * q + 1} are "
                         f"{quads[q].tolist()}, not the grid's {want[q].tolist()} "
                         "(vertex (i, j) = j*nx + i; quad q: (a, c, b), (b, c, d))")


class HeightField:
    """The scene's height field: its device record, block ranges and bounds pass.

    Without a grid mesh (``mesh`` is None) the record says ``HF_NONE`` and the buffers are
    placeholders, so the tracing kernels' parameters are always bound.
    """

    def __init__(self, rt: Runtime, stage: str):
        self.rt, self.stage = rt, stage
        self.mesh: int | None = None
        self.nx = self.ny = 0
        self.record = rt.to_device(self._record(HF_NONE, 2, 2))
        self.blocks = rt.buffer(16)
        self._vertices = rt.buffer(16)
        self._bounds = None

    def _record(self, mesh: int, nx: int, ny: int) -> np.ndarray:
        rec = np.zeros(1, HEIGHTFIELD_DTYPE)
        nbx, nby = grid_blocks(nx, ny)
        rec["mesh"], rec["nx"], rec["ny"], rec["nbx"], rec["nby"] = mesh, nx, ny, nbx, nby
        rec["acc_lo"], rec["acc_hi"] = _INT_MAX, _INT_MIN
        rec["acc_rise_x"] = rec["acc_rise_z"] = _INT_MIN
        rec["slope"] = np.inf   # no pass yet: no ray is known to climb over it
        return rec

    def attach(self, mesh: int, nx: int, ny: int) -> None:
        """Make mesh ``mesh`` (an ``nx x ny`` vertex grid) the height field."""
        if self.mesh is not None:
            raise ValueError(f"mesh {mesh}: the scene already has a grid mesh (mesh "
                             f"{self.mesh}); one height field per scene")
        self.mesh, self.nx, self.ny = int(mesh), int(nx), int(ny)
        self.record = self.rt.to_device(self._record(self.mesh, self.nx, self.ny))
        nbx, nby = grid_blocks(nx, ny)
        self.blocks = self.rt.buffer(16 * nbx * nby)
        self._bounds = self.rt.kernel_launcher("heightfield.cl", "heightfield_bounds",
                                               stage=f"{self.stage}.heightfield")
        wg = HF_WG
        self._bounds.set_size(-(-nbx * nby // wg) * wg, wg)

    def enqueue_bounds(self, vertices: cl.Buffer, blas_infos: cl.Buffer) -> None:
        """Queue the per-frame pass over ``vertices`` (the grid mesh's current buffer): block
        ranges, box, bad-vertex count, and the mesh's BLAS header for the TLAS build."""
        self._vertices = vertices
        self._bounds.bind(verts=vertices, blocks=self.blocks, hf=self.record,
                          blas_infos=blas_infos)
        self._bounds()

    def bindings(self) -> dict:
        """The height-field part of ``SCENE_PARAMS`` (kernels/scene.h) by name."""
        return {"hf_info": self.record, "hf_vertices": self._vertices, "hf_blocks": self.blocks}

    def read(self) -> np.void:
        """The device record (synchronises; tests and checks)."""
        return self.rt.to_host(self.record, HEIGHTFIELD_DTYPE, 1)[0]

    def read_blocks(self) -> np.ndarray:
        """(nby, nbx, 4) float32 (min y, max y, slope bound, 0) per block (synchronises)."""
        nbx, nby = grid_blocks(self.nx, self.ny)
        return self.rt.to_host(self.blocks, np.float32, 4 * nbx * nby).reshape(nby, nbx, 4)
