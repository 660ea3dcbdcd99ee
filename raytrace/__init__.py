"""GPU BVH (LBVH build, refit, two-level instances), ray queries and the wavefront renderer.

Public entry points: :func:`intersect` (NumPy in, NumPy out, the renderer's own traversal code),
:class:`Blas` (one mesh's device BVH: rebuild/refit/stats), :class:`Scene` (meshes + instances +
TLAS; ``trace_args()`` for kernels using ``kernels/traverse.h``), :class:`RayQuery`.
"""

from raytrace.bvh import HIT_DTYPE, Blas
from raytrace.query import RayQuery, intersect
from raytrace.scene import Scene

__all__ = ["HIT_DTYPE", "Blas", "RayQuery", "Scene", "intersect"]
