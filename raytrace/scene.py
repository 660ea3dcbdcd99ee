"""Two-level scene: one BLAS per mesh, instances with 4x4 transforms, a TLAS rebuilt on the device.

Every mesh's nodes and leaf-ordered triangles live in one shared node array and one triangle
array (each BLAS writes at its own offsets), so any kernel sees the whole scene through the fixed
parameter list ``SCENE_PARAMS`` of ``kernels/scene.h``; :meth:`Scene.trace_args` returns the
buffers in that order. Hits name the instance id and the triangle's index in its mesh's own input
order; ``mesh_record(mesh_id).prim_base`` (also in the device ``Instance``) maps that to a
scene-wide triangle number if the renderer concatenates per-triangle attributes.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime, check_bvh_layout
from raytrace.bvh import (
    DEFAULT_LEAF_SIZE,
    INFO_DTYPE,
    INSTANCE_DTYPE,
    NODE_DTYPE,
    TRI_DTYPE,
    Blas,
    BlasStorage,
    check_mesh_arrays,
    node_count,
    vertices_to_float4,
)
from raytrace.bvh_wide import DEFAULT_WIDE_LEAF_SIZE, WideStorage
from raytrace.heightfield import HeightField, check_grid_triangles
from raytrace.sort import make_sorter

#: One row of the scene's transform buffer (kernels/transform.h, 48 bytes): an instance's
#: world_from_object as three float4 rows (xyz: the 3x3 part, w: the translation).
TRANSFORM_DTYPE = np.dtype([("r0", np.float32, 4), ("r1", np.float32, 4),
                            ("r2", np.float32, 4)])
TLAS_LEAF_SIZE = 1
#: Most instances whose TLAS is built in one launch by one work-group (kernels/bvh_tlas.cl
#: tlas_build_one_group; the five-launch build above it).
TLAS_ONE_LAUNCH = 256
#: An instance's default visibility mask (kernels/bvh.h Instance.mask): every ray sees it.
MASK_ALL = 0xFFFFFFFF
TRACE_STAT_OVERFLOW = 0
#: Rays of the cooperative walk redone serially, its stack full (kernels/traverse_coop.h).
TRACE_STAT_COOP_REDO = 1
#: TRACE_COUNT builds: height-field walks culled whole and spans skipped by the slopes.
TRACE_STAT_HF_CULLED = 2
TRACE_STAT_HF_SKIPPED = 3
#: TRACE_COUNT builds: the light buffer's answers by kind, then the triangles it tested
#: (kernels/light_buffer.h).
TRACE_STAT_LB = 4
LIGHT_BUFFER_COUNT_FIELDS = ("empty", "nearer", "tested_clear", "blocked", "full", "off_map",
                             "triangles", "fine")
#: The traversal work counters of TRACE_COUNT builds (kernels/scene.h): ray kinds and fields.
TRACE_KINDS = ("query", "primary", "secondary", "shadow", "photon", "crossing")
TRACE_COUNT_FIELDS = ("rays", "traversals", "tlas_nodes", "blas_entries", "blas_nodes",
                      "tri_tests", "hits", "spare")
TRACE_COUNT_INST = 8
TRACE_STAT_COUNT = TRACE_STAT_LB + len(LIGHT_BUFFER_COUNT_FIELDS)
TRACE_STAT_INST = TRACE_STAT_COUNT + len(TRACE_KINDS) * len(TRACE_COUNT_FIELDS)
TRACE_STATS_LEN = TRACE_STAT_INST + len(TRACE_KINDS) * TRACE_COUNT_INST
BOUNDS_WG = 256


@dataclasses.dataclass
class MeshRecord:
    """A mesh of the scene: its device buffers and where its BVH lives in the shared arrays."""

    vertices_buf: cl.Buffer
    triangles_buf: cl.Buffer
    n_vertices: int
    n_triangles: int
    dynamic: bool
    prim_base: int      #: first triangle in scene-wide numbering (sum of earlier meshes)
    grid: tuple[int, int] | None = None  #: (nx, ny) of a grid mesh traced as a height field
    node_base: int = 0  #: first node slot in the shared node array
    tri_base: int = 0   #: first slot in the shared leaf-ordered triangle array
    blas: Blas | None = None


def _affine_rows(m, what: str) -> np.ndarray:
    """3x4 float32 rows of an affine 4x4 (or 3x4) world_from_object, validated."""
    a = np.asarray(m, dtype=np.float64)
    if a.shape not in ((4, 4), (3, 4)):
        raise ValueError(f"{what}: world_from_object must be 4x4 (or 3x4), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{what}: world_from_object has a non-finite entry")
    if a.shape == (4, 4) and not np.allclose(a[3], [0, 0, 0, 1], atol=1e-9):
        raise ValueError(f"{what}: world_from_object must be affine (last row 0 0 0 1), "
                         f"got {a[3].tolist()}")
    det = float(np.linalg.det(a[:3, :3]))
    scale = float(np.abs(a[:3, :3]).max()) ** 3
    if not abs(det) > 1e-12 * max(scale, 1e-300):
        raise ValueError(f"{what}: world_from_object is singular (det {det:.3g})")
    return a[:3].astype(np.float32)


class Scene:
    """Meshes, instances and the two-level BVH over them, on one device.

    ``layout``: how the BLASes are stored for traversal, ``"binary"`` (GPU) or ``"wide"`` (8-wide
    nodes, CPU; ``raytrace.bvh_wide``); default: the runtime's ``bvh_layout``. Kernels that trace
    must be built with :attr:`trace_defines` (the runtime adds its own layout to every build).
    ``leaf_size``: most triangles per BLAS leaf (default 1 binary, 4 wide). Typical use::

        scene = Scene(rt)
        water = scene.add_mesh(vbuf, tbuf, dynamic=True, n_vertices=nv, n_triangles=nt)
        boat = scene.add_mesh(boat_vertices, boat_triangles)
        scene.add_instance(water)
        b = scene.add_instance(boat, world_from_boat)
        scene.update()                 # first call builds everything
        ...                            # each frame:
        scene.set_transform(b, M); scene.update()   # refit water, rebuild the TLAS
        kernel.bind(**scene.trace_bindings(), ...)

    Instance transforms live once, on the device, in :attr:`transform_buffer` (one
    ``Transform`` row per instance, :meth:`transform_row`): the host writes a row when
    :meth:`set_transform` changes it; a device stage may write rows itself (floating bodies),
    with no host copy, and says so with :meth:`rows_written`. Every :meth:`update` derives the
    Instance records, the world boxes and the normal transforms (:attr:`normal_buffer`) from
    the rows on the device.
    """

    def __init__(self, rt: Runtime, *, leaf_size: int | None = None, layout: str | None = None,
                 stage: str = "bvh"):
        self.layout = check_bvh_layout(rt.bvh_layout if layout is None else layout)
        if leaf_size is None:
            leaf_size = DEFAULT_WIDE_LEAF_SIZE if self.wide else DEFAULT_LEAF_SIZE
        self.rt, self.leaf_size, self.stage = rt, int(leaf_size), stage
        self.meshes: list[MeshRecord] = []
        self._inst_mesh: list[int] = []
        self._inst_masks: list[int] = []   #: visibility bits per instance (set_instance_mask)
        self._masks_dirty = False
        self._xforms = np.zeros((0, 3, 4), np.float32)  # the rows the host last wrote
        self.transform_buffer = rt.buffer(TRANSFORM_DTYPE.itemsize)
        self._xform_capacity = 0
        self.rows_version = 0          # bumped by every write of the rows (rows_written)
        self._storage_tris = -1        # triangle count the shared storage was made for
        self._tlas_n = -1              # instance count the TLAS scratch was made for
        self.trace_stats = rt.buffer(4 * TRACE_STATS_LEN)
        cl.enqueue_fill_buffer(rt.queue, self.trace_stats, np.int32(0), 0, 4 * TRACE_STATS_LEN)
        self.tlas_info = rt.buffer(INFO_DTYPE.itemsize)
        self._reset = rt.kernel_launcher("bvh_build.cl", "bvh_reset_info",
                                         stage=f"{stage}.tlas.reset")
        self._reset.bind(infos=self.tlas_info, info_index=0, n_prims=0).set_size(1)
        #: TLASes of at most this many instances are built in one launch (TLAS_ONE_LAUNCH)
        self.tlas_one_launch = TLAS_ONE_LAUNCH
        #: the grid mesh traced as a height field, if any (raytrace.heightfield)
        self.heightfield = HeightField(rt, stage)
        self._init_empty_tlas()

    # -- content ---------------------------------------------------------------------------
    def add_mesh(self, vertices, triangles, *, dynamic: bool = False,
                 n_vertices: int | None = None, n_triangles: int | None = None,
                 grid: tuple[int, int] | None = None) -> int:
        """Add a mesh; returns its mesh id.

        ``vertices``/``triangles``: NumPy (n,3) floats / (m,3) ints (copied to the device), or
        device buffers (float4 per vertex, 3 x uint32 per triangle; pass ``n_vertices`` and
        ``n_triangles``; the scene keeps a reference and reads them at every build).
        ``dynamic``: refitted (or rebuilt) by every :meth:`update`; static meshes are built once.
        ``grid=(nx, ny)``: the mesh is an ``nx x ny`` vertex grid with ``lbm.grid_triangles``'s
        triangles (checked here), traced as a height field (:mod:`raytrace.heightfield`): no
        BVH, a bounds pass per :meth:`update` instead of a refit, the same hits. One per scene.
        """
        name = f"mesh {len(self.meshes)}"
        if isinstance(vertices, cl.Buffer) != isinstance(triangles, cl.Buffer):
            raise ValueError(f"{name}: give vertices and triangles both as NumPy arrays or both "
                             "as device buffers")
        if isinstance(vertices, cl.Buffer):
            if n_vertices is None or n_triangles is None:
                raise ValueError(f"{name}: device buffers need n_vertices= and n_triangles=")
            vbuf, tbuf, nv, nt = vertices, triangles, int(n_vertices), int(n_triangles)
            if nt < 1:
                raise ValueError(f"{name}: n_triangles must be >= 1, got {nt}")
        else:
            v, t = check_mesh_arrays(vertices, triangles, name)
            vbuf = self.rt.to_device(vertices_to_float4(v))
            tbuf = self.rt.to_device(t)
            nv, nt = len(v), len(t)
        if grid is not None:
            self._check_grid(grid, triangles, tbuf, nv, nt, name)
        prim_base = sum(m.n_triangles for m in self.meshes)
        self.meshes.append(MeshRecord(vbuf, tbuf, nv, nt, bool(dynamic), prim_base,
                                      None if grid is None else (int(grid[0]), int(grid[1]))))
        if grid is not None:
            self.heightfield.attach(len(self.meshes) - 1, int(grid[0]), int(grid[1]))
        return len(self.meshes) - 1

    def _check_grid(self, grid, triangles, tbuf, nv: int, nt: int, name: str) -> None:
        """A grid mesh's shape and triangles (read back once when given as a buffer)."""
        if self.heightfield.mesh is not None:
            raise ValueError(f"{name}: the scene already has a grid mesh (mesh "
                             f"{self.heightfield.mesh}); one height field per scene")
        if not isinstance(grid, tuple | list) or len(grid) != 2:
            raise ValueError(f"{name}: grid must be (nx, ny), got {grid!r}")
        nx, ny = grid
        tris = (self.rt.to_host(tbuf, np.uint32, 3 * nt) if isinstance(triangles, cl.Buffer)
                else np.asarray(triangles))
        check_grid_triangles(tris, nx, ny, name)
        if nx * ny != nv:
            raise ValueError(f"{name}: a {nx}x{ny} grid has {nx * ny} vertices, got {nv}")

    def replace_vertex_buffer(self, mesh_id: int, vertices_buf: cl.Buffer) -> None:
        """Point a mesh given as device buffers at another vertex buffer of the same size (its
        writer moved); the BLASes are rebound and rebuilt at the next :meth:`update`."""
        rec = self.mesh_record(mesh_id)
        if vertices_buf.size < 16 * rec.n_vertices:
            raise ValueError(f"mesh {mesh_id}: vertex buffer holds {vertices_buf.size} bytes, "
                             f"{rec.n_vertices} float4 vertices need {16 * rec.n_vertices}")
        if vertices_buf is not rec.vertices_buf:
            rec.vertices_buf = vertices_buf
            self._storage_tris = -1  # new Blas objects bound to the new buffer

    def add_instance(self, mesh_id: int, world_from_object=None) -> int:
        """Place mesh ``mesh_id`` with an affine 4x4 ``world_from_object`` (identity if None).

        Its row of :attr:`transform_buffer` is written now. Adding instances beyond the
        buffer's capacity moves it to a larger buffer (rows copied on the device): a device
        writer takes :attr:`transform_buffer` again after adding instances."""
        self._check_mesh_id(mesh_id)
        rows = _affine_rows(np.eye(4) if world_from_object is None else world_from_object,
                            f"instance {len(self._inst_mesh)}")
        inst = len(self._inst_mesh)
        self._inst_mesh.append(int(mesh_id))
        self._inst_masks.append(MASK_ALL)
        self._xforms = np.concatenate([self._xforms, rows[None]])
        if inst >= self._xform_capacity:
            self._grow_transforms(max(4, 2 * self._xform_capacity))
        self._write_row(inst, rows)
        return inst

    def set_transform(self, instance_id: int, world_from_object) -> None:
        """Move an instance: validates ``world_from_object`` (affine, finite, not singular) and
        writes its row of :attr:`transform_buffer` (48 bytes, no wait) when it differs from
        the last one the host wrote; takes effect at the next :meth:`update`. (A row a device
        stage wrote since is overwritten only when the host's new value differs from its own
        last one.)"""
        i = int(instance_id)
        if not 0 <= i < len(self._inst_mesh):
            raise ValueError(f"instance id {instance_id} out of range [0, {len(self._inst_mesh)})")
        rows = _affine_rows(world_from_object, f"instance {instance_id}")
        if np.array_equal(rows, self._xforms[i]):
            return
        self._xforms[i] = rows
        self._write_row(i, rows)

    def set_instance_mask(self, instance_id: int, mask: int) -> None:
        """Visibility bits of an instance (default :data:`MASK_ALL`): a ray traced with a mask
        (kernels/traverse.h, ``scene_*_masked``) sees it only when the two share a bit; the
        unmasked queries see every instance. Takes effect at the next :meth:`update`."""
        i = int(instance_id)
        if not 0 <= i < len(self._inst_mesh):
            raise ValueError(f"instance id {instance_id} out of range [0, {len(self._inst_mesh)})")
        if not 0 <= int(mask) <= MASK_ALL:
            raise ValueError(f"instance mask must lie in [0, 2^32), got {mask}")
        if self._inst_masks[i] != int(mask):
            self._inst_masks[i] = int(mask)
            self._masks_dirty = True

    def instance_mask(self, instance_id: int) -> int:
        return self._inst_masks[int(instance_id)]

    def transform_row(self, instance_id: int) -> int:
        """The row of :attr:`transform_buffer` holding instance ``instance_id``'s
        world_from_object (a device stage writes ``Transform`` records there)."""
        i = int(instance_id)
        if not 0 <= i < len(self._inst_mesh):
            raise ValueError(f"instance id {instance_id} out of range [0, {len(self._inst_mesh)})")
        return i

    def _grow_transforms(self, capacity: int) -> None:
        rt = self.rt
        new = rt.buffer(TRANSFORM_DTYPE.itemsize * capacity)
        if self._xform_capacity:  # keep rows a device stage may have written
            rt.record(f"{self.stage}.transform", cl.enqueue_copy(
                rt.queue, new, self.transform_buffer,
                byte_count=TRANSFORM_DTYPE.itemsize * self._xform_capacity))
        self.transform_buffer, self._xform_capacity = new, capacity
        self.rows_version += 1
        self._tlas_n = -1  # tlas_prep reads the new buffer

    def rows_written(self) -> None:
        """Say that rows of :attr:`transform_buffer` were (or are queued to be) written other
        than by :meth:`set_transform` (a device stage moving bodies, a restored snapshot):
        what is derived from them on demand (a renderer's light buffer) is made again.
        :attr:`rows_version` counts these and the host's own writes."""
        self.rows_version += 1

    def _write_row(self, i: int, rows: np.ndarray) -> None:
        self.rows_version += 1
        # non-blocking: pyopencl keeps the host array alive until the copy is done
        rt = self.rt
        rt.record(f"{self.stage}.transform", cl.enqueue_copy(
            rt.queue, self.transform_buffer, np.ascontiguousarray(rows, np.float32),
            dst_offset=TRANSFORM_DTYPE.itemsize * i, is_blocking=False))

    def read_host_transforms(self) -> np.ndarray:
        """(n_instances, 3, 4) float32 world_from_object rows as the host last wrote them (a
        device stage may have moved one since: :meth:`read_transforms`); no device work."""
        return self._xforms.copy()

    def read_transforms(self) -> np.ndarray:
        """(n_instances, 3, 4) float32 world_from_object rows as on the device (synchronises;
        tests and references)."""
        n = self.n_instances
        return self.rt.to_host(self.transform_buffer, np.float32, 12 * n).reshape(n, 3, 4)

    @property
    def wide(self) -> bool:
        return self.layout == "wide"

    @property
    def trace_defines(self) -> dict:
        """Build defines of a kernel that traces this scene (``kernels/scene.h``)."""
        return {"TRACE_WIDE": int(self.wide)}

    @property
    def n_instances(self) -> int:
        return len(self._inst_mesh)

    def mesh_record(self, mesh_id: int) -> MeshRecord:
        self._check_mesh_id(mesh_id)
        return self.meshes[mesh_id]

    def blas(self, mesh_id: int) -> Blas:
        """The BLAS of a mesh (exists after the first :meth:`update`)."""
        rec = self.mesh_record(mesh_id)
        if rec.grid is not None:
            raise ValueError(f"mesh {mesh_id} is a height field (grid {rec.grid}): it has no BVH")
        if rec.blas is None:
            raise ValueError(f"mesh {mesh_id} has no BVH yet: call Scene.update() first")
        return rec.blas

    def _check_mesh_id(self, mesh_id) -> None:
        if not 0 <= int(mesh_id) < len(self.meshes):
            raise ValueError(f"mesh id {mesh_id} out of range [0, {len(self.meshes)})")

    # -- device work -------------------------------------------------------------------------
    def update(self, rebuild: bool = False) -> None:
        """Bring the BVHs up to date (enqueued; no host sync).

        New meshes are built; dynamic meshes are refitted, or rebuilt when ``rebuild``; the TLAS
        is rebuilt over the instances' current transforms every call.
        """
        total = sum(m.n_triangles for m in self.meshes)
        fresh = total != self._storage_tris
        if fresh:
            self._allocate_storage()
        for rec in self.meshes:
            if rec.grid is not None:
                if fresh or rec.dynamic or not self._hf_done:
                    self.heightfield.enqueue_bounds(rec.vertices_buf, self.blas_infos)
                    self._hf_done = True
                continue
            if fresh or not rec.blas.built:
                rec.blas.rebuild()
            elif rec.dynamic:
                if rebuild:
                    rec.blas.rebuild()
                else:
                    rec.blas.refit()
        self._build_tlas()

    def _bvh_triangles(self, rec: MeshRecord) -> int:
        """Triangles of a mesh's BVH (none for the height field)."""
        return 0 if rec.grid is not None else rec.n_triangles

    def _allocate_storage(self) -> None:
        rt = self.rt
        n_nodes = sum(node_count(self._bvh_triangles(m)) for m in self.meshes)
        n_tris = sum(self._bvh_triangles(m) for m in self.meshes)
        self.blas_nodes = rt.buffer(NODE_DTYPE.itemsize * max(n_nodes, 1))
        self.blas_tris = rt.buffer(TRI_DTYPE.itemsize * max(n_tris, 1))
        self.blas_infos = rt.buffer(INFO_DTYPE.itemsize * max(len(self.meshes), 1))
        self.mesh_prim_base = rt.to_device(
            np.array([m.prim_base for m in self.meshes] or [0], np.int32))
        counts = [self._bvh_triangles(m) for m in self.meshes]
        wide = WideStorage.for_scene(rt, counts) if self.wide else [None] * len(counts)
        # the instance records' BLAS roots: the binary root (in the header) or the wide root
        roots = [w.node_base for w in wide] if self.wide else [-1] * len(counts)
        self.mesh_wide_root = rt.to_device(np.array(roots or [0], np.int32))
        # the BLAS arrays the tracing kernels read (SCENE_PARAMS)
        self._trace_blas = ((wide[0].nodes, wide[0].blocks) if self.wide and wide
                            else (self.blas_nodes, self.blas_tris))
        node_base = tri_base = 0
        self._hf_done = False
        for i, rec in enumerate(self.meshes):
            rec.node_base, rec.tri_base = node_base, tri_base
            if rec.grid is not None:
                continue
            storage = BlasStorage(self.blas_nodes, node_base, self.blas_tris, tri_base,
                                  self.blas_infos, i)
            rec.blas = Blas(rt, rec.vertices_buf, rec.triangles_buf, rec.n_vertices,
                            rec.n_triangles, leaf_size=self.leaf_size, storage=storage,
                            wide=wide[i], stage=f"{self.stage}.blas")
            node_base += node_count(rec.n_triangles)
            tri_base += rec.n_triangles
        self._storage_tris = sum(m.n_triangles for m in self.meshes)
        self._tlas_n = -1  # the TLAS kernels bind the BLAS headers: rebind them

    def _init_empty_tlas(self) -> None:
        rt = self.rt
        self.tlas_nodes = rt.buffer(NODE_DTYPE.itemsize)
        self.tlas_prims = rt.buffer(4)
        self.instances = rt.buffer(INSTANCE_DTYPE.itemsize)
        self.normal_buffer = rt.buffer(TRANSFORM_DTYPE.itemsize)
        if not hasattr(self, "blas_nodes"):
            self.blas_nodes = rt.buffer(NODE_DTYPE.itemsize)
            self.blas_tris = rt.buffer(TRI_DTYPE.itemsize)
            self._trace_blas = (self.blas_nodes, self.blas_tris)

    def _allocate_tlas(self, n: int) -> None:
        rt = self.rt
        self.tlas_nodes = rt.buffer(NODE_DTYPE.itemsize * node_count(n))
        self.tlas_prims = rt.buffer(4 * n)      # sorted instance ids (the sort's values)
        self._tlas_keys = rt.buffer(4 * n)
        self._tlas_flags = rt.buffer(4 * node_count(n))
        cl.enqueue_fill_buffer(rt.queue, self._tlas_flags, np.int32(-1), 0, 4 * node_count(n))
        self.instances = rt.buffer(INSTANCE_DTYPE.itemsize * n)
        self.normal_buffer = rt.buffer(TRANSFORM_DTYPE.itemsize * n)
        self._tlas_boxes = rt.buffer(32 * n)
        self._inst_mesh_dev = rt.to_device(np.array(self._inst_mesh, np.int32))
        self._inst_mask_dev = rt.to_device(np.array(self._inst_masks, np.uint32))
        self._masks_dirty = False
        st = f"{self.stage}.tlas"

        def kernel(name, stage):
            return rt.kernel_launcher("bvh_tlas.cl", name, stage=f"{st}.{stage}")

        self._prep = kernel("tlas_prep", "prep").bind(
            n_inst=n, xforms=self.transform_buffer, inst_mesh=self._inst_mesh_dev,
            mesh_prim_base=self.mesh_prim_base, blas_infos=self.blas_infos,
            mesh_wide_root=self.mesh_wide_root, wide=int(self.wide),
            inst_mask=self._inst_mask_dev, instances=self.instances,
            normals=self.normal_buffer, boxes=self._tlas_boxes, tlas_info=self.tlas_info)
        self._prep.set_size(n, BOUNDS_WG)
        self._morton = kernel("bvh_box_morton", "morton").bind(
            n=n, boxes=self._tlas_boxes, info=self.tlas_info, key_bits=32,
            keys=self._tlas_keys, vals=self.tlas_prims).set_size(n, 64)
        self._hier = kernel("bvh_hierarchy_boxes", "hierarchy").bind(
            n=n, leaf_size=TLAS_LEAF_SIZE, keys=self._tlas_keys, order=self.tlas_prims,
            boxes=self._tlas_boxes, nodes=self.tlas_nodes, flags=self._tlas_flags,
            info=self.tlas_info).set_size(n, 64)
        self._tlas_sorter = make_sorter(rt, self._tlas_keys, self.tlas_prims, n,
                                        stage=f"{st}.sort")
        self._tlas_one = kernel("tlas_build_one_group", "build").bind(
            n_inst=n, xforms=self.transform_buffer, inst_mesh=self._inst_mesh_dev,
            mesh_prim_base=self.mesh_prim_base, blas_infos=self.blas_infos,
            mesh_wide_root=self.mesh_wide_root, wide=int(self.wide),
            inst_mask=self._inst_mask_dev, instances=self.instances,
            normals=self.normal_buffer, boxes=self._tlas_boxes, keys=self._tlas_keys,
            order=self.tlas_prims, nodes=self.tlas_nodes, flags=self._tlas_flags,
            info=self.tlas_info).set_size(BOUNDS_WG, BOUNDS_WG)
        self._tlas_n = n

    def _build_tlas(self) -> None:
        n = self.n_instances
        if n == 0:
            self._reset.bind(n_prims=0)
            self._reset()  # root = -1: an empty scene misses
            return
        if n != self._tlas_n:
            self._allocate_tlas(n)
        if self._masks_dirty:
            self.rt.keep(cl.enqueue_copy(self.rt.queue, self._inst_mask_dev,
                                         np.array(self._inst_masks, np.uint32),
                                         is_blocking=False))
            self._masks_dirty = False
        if n <= self.tlas_one_launch:
            self._tlas_one()
            return
        self._reset.bind(n_prims=n)
        self._reset()
        self._prep()
        self._morton()
        self._tlas_sorter.enqueue()
        self._hier()

    # -- traversal work (TRACE_COUNT builds) ------------------------------------------------
    def reset_trace_counts(self) -> None:
        """Zero the work counters (the overflow and redo guards stay)."""
        n = TRACE_STATS_LEN - TRACE_STAT_HF_CULLED
        cl.enqueue_fill_buffer(self.rt.queue, self.trace_stats, np.uint32(0),
                               4 * TRACE_STAT_HF_CULLED, 4 * n)

    def trace_counts(self) -> dict:
        """The work counters since the last reset, per ray kind: ``{kind: {field: n}}`` with
        the fields of :data:`TRACE_COUNT_FIELDS` and ``blas_nodes_by_instance`` (a list; ids
        past the last slot share it), and ``heightfield``: its walks culled whole and spans
        skipped by the slopes (kernels/traverse_heightfield.h), and ``light_buffer``: its
        answers by kind and the triangles it tested (:data:`LIGHT_BUFFER_COUNT_FIELDS`,
        kernels/light_buffer.h). All zero unless the kernels were built with ``TRACE_COUNT=1``
        (``Runtime(defines={"TRACE_COUNT": 1})``).
        Synchronises."""
        st = self.rt.to_host(self.trace_stats, np.uint32, TRACE_STATS_LEN)
        nf = len(TRACE_COUNT_FIELDS)
        out = {}
        for k, kind in enumerate(TRACE_KINDS):
            base = TRACE_STAT_COUNT + k * nf
            rec = {f: int(st[base + i]) for i, f in enumerate(TRACE_COUNT_FIELDS)}
            ib = TRACE_STAT_INST + k * TRACE_COUNT_INST
            rec["blas_nodes_by_instance"] = [int(x) for x in st[ib:ib + TRACE_COUNT_INST]]
            out[kind] = rec
        out["heightfield"] = {"culled": int(st[TRACE_STAT_HF_CULLED]),
                              "skipped_spans": int(st[TRACE_STAT_HF_SKIPPED])}
        out["light_buffer"] = {f: int(st[TRACE_STAT_LB + i])
                               for i, f in enumerate(LIGHT_BUFFER_COUNT_FIELDS)}
        return out

    # -- kernels' view ----------------------------------------------------------------------
    def trace_args(self) -> list:
        """Buffers for ``SCENE_PARAMS`` (kernels/scene.h), in order; valid after update()."""
        return list(self.trace_bindings().values())

    def trace_bindings(self) -> dict:
        """``SCENE_PARAMS`` by name, for ``Kernel.bind(**scene.trace_bindings())``."""
        return {"tlas_info": self.tlas_info, "tlas_nodes": self.tlas_nodes,
                "tlas_prims": self.tlas_prims, "instances": self.instances,
                "blas_nodes": self._trace_blas[0], "blas_tris": self._trace_blas[1],
                **self.heightfield.bindings(), "trace_stats": self.trace_stats}

    def coop_redos(self) -> int:
        """Cooperative walks (kernels/traverse_coop.h) traced again serially because their local
        stack was full, since the scene was made: correct hits, only slower. Synchronises."""
        return int(self.rt.to_host(self.trace_stats, np.int32, 1, TRACE_STAT_COOP_REDO)[0])

    def check(self) -> dict:
        """Read the device's guards (synchronises): raise ValueError on non-finite vertices or a
        traversal-stack overflow; else return ``{"overflows": 0, "bad_triangles": 0}``."""
        stats = self.rt.to_host(self.trace_stats, np.int32, TRACE_STATS_LEN)
        bad = 0
        for i, rec in enumerate(self.meshes):
            if rec.blas is not None:
                if rec.blas.wide is not None:
                    rec.blas.wide.check()
                n_bad = int(rec.blas.info()["n_bad"])
                if n_bad:
                    raise ValueError(f"mesh {i}: {n_bad} triangles have a NaN or infinite vertex "
                                     "coordinate")
                bad += n_bad
        if self.heightfield.mesh is not None and self._storage_tris >= 0:
            n_bad = int(self.heightfield.read()["n_bad"])
            if n_bad:
                raise ValueError(f"mesh {self.heightfield.mesh}: {n_bad} grid vertices are NaN, "
                                 "infinite or off the regular grid")
        if stats[TRACE_STAT_OVERFLOW]:
            raise ValueError(f"traversal stack overflowed {int(stats[TRACE_STAT_OVERFLOW])} "
                             "times: hits may be missing")
        return {"overflows": 0, "bad_triangles": bad}
