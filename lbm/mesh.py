"""Topology of the water surface mesh written by :meth:`lbm.ShallowWater.write_surface`."""

from __future__ import annotations

import numpy as np


def grid_triangles(nx: int, ny: int) -> np.ndarray:
    """Triangle indices (m, 3) uint32 of an nx x ny vertex grid, vertex (i, j) = j*nx + i.

    Two triangles per quad, (a, c, b) and (b, c, d) with a=(i,j), b=(i+1,j), c=(i,j+1),
    d=(i+1,j+1): counter-clockwise seen from above with Y up (grid i along world x, j along
    world z), so geometric normals face +Y. m = 2 (nx-1) (ny-1).
    """
    for name, v in (("nx", nx), ("ny", ny)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 2:
            raise ValueError(f"grid_triangles: {name}={v!r} must be an integer >= 2")
    if nx * ny > 2**32:
        raise ValueError(f"grid_triangles: {nx}x{ny} vertices do not fit uint32 indices")
    idx = np.arange(nx * ny, dtype=np.uint32).reshape(ny, nx)
    a, b = idx[:-1, :-1], idx[:-1, 1:]
    c, d = idx[1:, :-1], idx[1:, 1:]
    tri = np.stack([np.stack([a, c, b], -1), np.stack([b, c, d], -1)], -2)
    return np.ascontiguousarray(tri.reshape(-1, 3))
