"""The wide BLAS layout for CPU devices: 8-wide nodes, 4-triangle blocks (kernels/bvh_wide.cl).

A CPU OpenCL device (PoCL) runs one ray per work-item as scalar code, so a binary tree wastes its
SIMD units: each node tests two boxes. The wide layout, made on the device from the binary LBVH
after each build, tests eight child boxes with float8 slabs and four triangles with float4
arithmetic (Embree's single-ray layout). The binary tree stays the builder's product: the collapse
records where each child box comes from, so a refit is the binary refit plus one copy launch.

Layouts are named ``"binary"`` (the GPU's, ``kernels/traverse.h`` with ``TRACE_WIDE=0``) and
``"wide"`` (``TRACE_WIDE=1``); the runtime's ``bvh_layout`` picks by device type.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime

WIDTH = 8          #: children per wide node (WIDE_WIDTH in kernels/bvh.h)
BLOCK = 4          #: triangles per block (WIDE_BLOCK)
MAX_LEVELS = 64    #: wide tree levels the collapse launches at most (WIDE_MAX_LEVELS)
#: Leaf size of the binary tree a wide tree is collapsed from, unless the caller sets one:
#: leaves of up to one block (measured best on PoCL, BENCHMARKS.md).
DEFAULT_WIDE_LEAF_SIZE = 4
_WG = 64

WIDE_NODE_DTYPE = np.dtype([("plane", np.float32, (6, WIDTH)), ("ref", np.int32, WIDTH),
                            ("cnt", np.int32, WIDTH)])
TRI_BLOCK_DTYPE = np.dtype([("v", np.float32, (3, 3, BLOCK)), ("prim", np.int32, BLOCK)])
WIDE_INFO_DTYPE = np.dtype([("level_count", np.int32, MAX_LEVELS), ("n_nodes", np.int32),
                            ("n_blocks", np.int32), ("truncated", np.int32), ("pad", np.int32)])


def wide_node_bound(n_tris: int) -> int:
    """Most wide nodes a tree over ``n_tris`` triangles can have.

    Every node has at least two children, and one with fewer than eight holds only leaves (the
    collapse opens inner children while it can). With L leaves, A such nodes (A <= L/2, plus the
    root) and F full ones, 8F <= (F + A - 1) + L - 2A, so F + A <= (4L - 1)/7 + 1, and L <= n.
    """
    return (4 * max(int(n_tris), 1)) // 7 + 2


def block_bound(n_tris: int) -> int:
    """Most blocks: a leaf of c >= 1 triangles takes ceil(c / 4) <= c blocks."""
    return max(int(n_tris), 1)


@dataclasses.dataclass(frozen=True)
class WideStorage:
    """Where a BLAS's wide tree lives: a scene's shared arrays and this BLAS's offsets in them."""

    nodes: cl.Buffer       #: WideNode array
    node_base: int
    blocks: cl.Buffer      #: TriBlock array
    block_base: int
    infos: cl.Buffer       #: WideInfo per BLAS (indexed like the binary BvhInfo)
    info_index: int
    bin: cl.Buffer         #: int per wide node: the binary node it was made from
    src: cl.Buffer         #: 8 ints per wide node: each slot's binary node * 2 + side, or -1
    block_src: cl.Buffer   #: int2 per block: first leaf-ordered triangle, count

    @classmethod
    def allocate(cls, rt: Runtime, n_tris: int) -> WideStorage:
        """Own buffers for one BLAS of ``n_tris`` triangles (offsets 0)."""
        return cls.for_scene(rt, [n_tris])[0]

    @classmethod
    def for_scene(cls, rt: Runtime, tri_counts: list[int]) -> list[WideStorage]:
        """Shared buffers for several BLASes; one storage record per mesh, in order."""
        nodes = [wide_node_bound(n) for n in tri_counts]
        blocks = [block_bound(n) for n in tri_counts]
        n_nodes, n_blocks = max(sum(nodes), 1), max(sum(blocks), 1)
        bufs = dict(nodes=rt.buffer(WIDE_NODE_DTYPE.itemsize * n_nodes),
                    blocks=rt.buffer(TRI_BLOCK_DTYPE.itemsize * n_blocks),
                    infos=rt.buffer(WIDE_INFO_DTYPE.itemsize * max(len(tri_counts), 1)),
                    bin=rt.buffer(4 * n_nodes), src=rt.buffer(4 * WIDTH * n_nodes),
                    block_src=rt.buffer(8 * n_blocks))
        out, nb, bb = [], 0, 0
        for i, (nn, nbk) in enumerate(zip(nodes, blocks, strict=True)):
            out.append(cls(node_base=nb, block_base=bb, info_index=i, **bufs))
            nb += nn
            bb += nbk
        return out


class WideBvh:
    """The wide tree of one :class:`raytrace.bvh.Blas`, made and refreshed on the device.

    ``collapse()`` after every binary build, ``refit()`` after every binary refit (the Blas calls
    them). Its root is node ``storage.node_base`` (level 0 comes first).
    """

    def __init__(self, rt: Runtime, blas, storage: WideStorage, depth_bound: int,
                 stage: str = "bvh"):
        """``blas``: the binary :class:`raytrace.bvh.Blas`; ``depth_bound``: most levels of its
        tree (:func:`raytrace.bvh.expected_depth_bound`), the number of collapse launches."""
        if depth_bound > MAX_LEVELS:
            raise ValueError(f"wide BVH: the binary tree may be {depth_bound} levels deep, more "
                             f"than the {MAX_LEVELS} the wide tree holds")
        self.rt, self.storage = rt, storage
        s, b = storage, blas.storage
        common = {"winfos": s.infos, "wide_base": s.node_base,
                  "block_base": s.block_base, "wide_src": s.src, "wnodes": s.nodes,
                  "block_src": s.block_src}
        self._levels = []
        # level L has at most 8^L nodes: a grid-stride launch of up to `cap` work-items each
        cap = max(4 * rt.device.max_compute_units * _WG, _WG)
        for level in range(depth_bound):
            k = rt.kernel_launcher("bvh_wide.cl", "bvh_wide_collapse",
                                   stage=f"{stage}.wide.collapse")
            k.bind(level=level, nodes=b.nodes, infos=b.infos, info_index=b.info_index,
                   wide_bin=s.bin, **common)
            size = 1 if level == 0 else min(WIDTH ** min(level, 10), cap)
            self._levels.append(k.set_size(size, 1 if level == 0 else _WG))
        self._refit = rt.kernel_launcher("bvh_wide.cl", "bvh_wide_refit",
                                         stage=f"{stage}.wide.refit")
        self._refit.bind(nodes=b.nodes, tris=b.tris, info_index=s.info_index,
                         blocks=s.blocks, **common)
        n_work = max(wide_node_bound(blas.n_triangles), block_bound(blas.n_triangles))
        self._refit.set_size(min(n_work, cap), _WG)

    @property
    def root(self) -> int:
        return self.storage.node_base

    def collapse(self) -> None:
        """Make the wide tree from the binary one just built (enqueued; no host sync)."""
        for launch in self._levels:
            launch()
        self._refit()

    def refit(self) -> None:
        """New boxes and triangles after a binary refit (enqueued; no host sync)."""
        self._refit()

    # -- host inspection (synchronises) -------------------------------------------------------
    def info(self) -> np.void:
        return self.rt.to_host(self.storage.infos, WIDE_INFO_DTYPE, 1, self.storage.info_index)[0]

    def host_arrays(self) -> dict:
        """The wide nodes and blocks in use (absolute refs), and the header."""
        info = self.info()
        s = self.storage
        nodes = self.rt.to_host(s.nodes, WIDE_NODE_DTYPE, int(info["n_nodes"]), s.node_base)
        blocks = self.rt.to_host(s.blocks, TRI_BLOCK_DTYPE, int(info["n_blocks"]), s.block_base)
        return {"nodes": nodes, "blocks": blocks, "info": info, "node_base": s.node_base,
                "block_base": s.block_base}

    def check(self) -> None:
        if int(self.info()["truncated"]):
            raise ValueError(f"wide BVH deeper than {MAX_LEVELS} levels: subtrees were dropped")
