"""What the renderer draws: a :class:`raytrace.scene.Scene` (the BVHs) plus everything shading
needs, in device tables bound to ``RENDER_GEOM_PARAMS`` (kernels/render_surface.h).

Mesh and instance ids are those of the underlying Scene. Static meshes are copied to the device
once into concatenated shading arrays. A dynamic mesh made by :meth:`RenderScene.add_dynamic_mesh`
(the water surface the LBM solver writes) lives in arrays of its own, ``dyn_positions`` and
``dyn_normals``, which the BVH and the shader read directly: its writer fills the buffers
``add_dynamic_mesh`` returns (sub-buffers at offsets aligned to the device's
``MEM_BASE_ADDR_ALIGN`` when there are several dynamic meshes) and nothing is copied per frame.
A dynamic mesh given to :meth:`RenderScene.add_mesh` as foreign device buffers is still copied
device-to-device into the shading arrays by every :meth:`RenderScene.update`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime
from raytrace.render_types import (
    INSTANCEINFO,
    LIGHT,
    MASK_OPAQUE,
    MASK_TRANSMISSIVE,
    MATERIAL,
    MAX_LIGHTS,
    MESH_DYNAMIC,
    MESH_HAS_NORMALS,
    MESH_HAS_UVS,
    MESH_TRI_MATERIALS,
    MESHINFO,
    TEXINFO,
    LightKind,
    SkyKind,
)
from raytrace.scene import Scene


@dataclasses.dataclass(frozen=True)
class Material:
    """Whitted material. ``ior`` 0 means opaque; > 0 a dielectric (refracts, Fresnel)."""

    diffuse: tuple = (0.8, 0.8, 0.8)     #: linear albedo
    specular: tuple = (0.0, 0.0, 0.0)    #: Phong specular colour
    shininess: float = 32.0              #: Phong exponent
    reflectivity: float = 0.0            #: opaque: mirror fraction 0..1
    ior: float = 0.0                     #: index of refraction (0: opaque)
    absorption: tuple = (0.0, 0.0, 0.0)  #: Beer-Lambert coefficient inside (1/m)
    texture: int = -1                    #: texture id multiplying diffuse, -1 for none
    uv_scale: tuple = (1.0, 1.0)         #: texture repeats per unit of uv

    def record(self) -> np.ndarray:
        for name in ("diffuse", "specular", "absorption"):
            v = getattr(self, name)
            if len(v) != 3 or not all(math.isfinite(x) and x >= 0 for x in v):
                raise ValueError(f"material {name} must be 3 finite numbers >= 0, got {v}")
        if not 0.0 <= self.reflectivity <= 1.0:
            raise ValueError(f"material reflectivity must lie in [0, 1], got {self.reflectivity}")
        if self.ior != 0.0 and not 1.0 <= self.ior <= 4.0:
            raise ValueError(f"material ior must be 0 (opaque) or in [1, 4], got {self.ior}")
        if not 0.0 <= self.shininess <= 1e4:
            raise ValueError(f"material shininess must lie in [0, 1e4], got {self.shininess}")
        r = np.zeros(1, MATERIAL)[0]
        r["diffuse"][:3] = self.diffuse
        r["specular"][:3] = self.specular
        r["specular"][3] = self.shininess
        r["absorption"][:3] = self.absorption
        r["absorption"][3] = self.ior
        r["reflectivity"] = self.reflectivity
        r["texture"] = self.texture
        r["uv_scale_u"], r["uv_scale_v"] = self.uv_scale
        return r


@dataclasses.dataclass(frozen=True)
class Sky:
    """Procedural sky (gradient, sun disk and glow) or a six-face cubemap."""

    kind: SkyKind = SkyKind.PROCEDURAL
    zenith: tuple = (0.25, 0.45, 0.85)
    horizon: tuple = (0.75, 0.85, 0.95)
    ground: tuple = (0.35, 0.33, 0.3)
    sun_direction: tuple = (0.4, 0.8, 0.45)  #: towards the sun
    sun_color: tuple = (30.0, 28.0, 24.0)    #: sun disk radiance
    sun_radius: float = 0.6                  #: angular radius (deg)
    sun_glow: float = 0.02                   #: glow strength relative to the disk
    cubemap: int = -1                        #: first of six texture ids (+x -x +y -y +z -z)


def _vec3(v, what: str) -> np.ndarray:
    a = np.asarray(v, np.float64).reshape(-1)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise ValueError(f"{what} must be 3 finite numbers, got {v}")
    return a


def _per_vertex(values, nv: int, width: int, what: str) -> np.ndarray:
    """``values`` as float32 (nv, width), or a one-line ValueError."""
    a = np.asarray(values, np.float32).reshape(-1, width)
    if len(a) != nv or not np.isfinite(a).all():
        raise ValueError(f"{what} must be {nv} finite {width}-vectors")
    return a


def _unit(v, what: str) -> np.ndarray:
    a = _vec3(v, what)
    n = np.linalg.norm(a)
    if n == 0:
        raise ValueError(f"{what} must not be zero")
    return a / n


class RenderScene:
    """Meshes with shading attributes, instances, materials, textures, lights and sky."""

    def __init__(self, rt: Runtime, **scene_kw):
        self.rt = rt
        self.scene = Scene(rt, **scene_kw)
        self.materials: list[Material] = []
        self.textures: list[np.ndarray] = []
        self.lights = np.zeros(0, LIGHT)
        self.sky = Sky()
        self.ambient = (0.05, 0.05, 0.05)
        self.meshes: list[dict] = []
        self.instances = np.zeros(0, INSTANCEINFO)
        #: the one instance whose materials include a dielectric, else -1 (none, or several):
        #: a shadow ray's crossings are its own walk alone (render_shadow.h); set by update()
        self.crossing_instance = -1
        self._layout_meshes = -1
        self._dirty = {"materials", "textures", "lights", "instances"}
        self.dyn_positions = rt.buffer(16)  # the dynamic meshes' own arrays (MESH_DYNAMIC)
        self.dyn_normals = rt.buffer(16)
        self._dyn_vertices = 0

    # -- content ---------------------------------------------------------------------------
    def add_material(self, material: Material) -> int:
        material.record()  # validates
        if material.texture >= len(self.textures):
            raise ValueError(f"material texture {material.texture} does not exist "
                             f"({len(self.textures)} textures)")
        self.materials.append(material)
        self._dirty.add("materials")
        return len(self.materials) - 1

    def add_texture(self, image) -> int:
        """A linear-colour image (h, w, 3|4) floats; row 0 is v = 0 (bottom). Returns its id."""
        a = np.asarray(image, np.float32)
        if a.ndim != 3 or a.shape[2] not in (3, 4) or a.shape[0] < 1 or a.shape[1] < 1:
            raise ValueError(f"texture must have shape (h, w, 3 or 4), got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError("texture has non-finite texels")
        t = np.ones(a.shape[:2] + (4,), np.float32)
        t[..., : a.shape[2]] = a
        self.textures.append(t)
        self._dirty.add("textures")
        return len(self.textures) - 1

    def add_mesh(self, vertices, triangles, *, normals=None, uvs=None, material: int = 0,
                 tri_materials=None, dynamic: bool = False, n_vertices: int | None = None,
                 n_triangles: int | None = None) -> int:
        """Add a mesh (see :meth:`Scene.add_mesh`); returns its mesh id.

        ``normals``: (n,3) per-vertex normals, or a device buffer of float4 for a dynamic mesh
        given as device buffers; ``uvs``: (n,2); ``material``: its material id;
        ``tri_materials``: (m,) per-triangle material ids overriding ``material``.
        """
        if not self.materials:  # material 0 is a default grey until one is added
            self.add_material(Material())
        on_device = isinstance(vertices, cl.Buffer)
        tris_host = None
        if on_device:
            if n_vertices is None:
                raise ValueError("a mesh given as device buffers needs n_vertices=")
            if not isinstance(triangles, cl.Buffer):
                tris_host = np.ascontiguousarray(triangles, np.uint32).reshape(-1, 3)
                n_triangles = len(tris_host)
                triangles = self.rt.to_device(tris_host)
            if n_triangles is None:
                raise ValueError("device triangles need n_triangles=")
            nv, nt = int(n_vertices), int(n_triangles)
            mesh_id = self.scene.add_mesh(vertices, triangles, dynamic=dynamic,
                                          n_vertices=nv, n_triangles=nt)
            v_host = None
        else:
            mesh_id = self.scene.add_mesh(vertices, triangles, dynamic=dynamic)
            rec = self.scene.mesh_record(mesh_id)
            nv, nt = rec.n_vertices, rec.n_triangles
            v_host = np.asarray(vertices, np.float32).reshape(-1, 3)
            tris_host = np.ascontiguousarray(triangles, np.uint32).reshape(-1, 3)
        flags = 0
        n_host = None
        if normals is not None:
            flags |= MESH_HAS_NORMALS
            if not isinstance(normals, cl.Buffer):
                n_host = _per_vertex(normals, nv, 3, "normals")
        uv_host = None
        if uvs is not None:
            flags |= MESH_HAS_UVS
            uv_host = _per_vertex(uvs, nv, 2, "uvs")
        tm = None
        if tri_materials is not None:
            flags |= MESH_TRI_MATERIALS
            tm = np.asarray(tri_materials).reshape(-1)
            if len(tm) != nt:
                raise ValueError(f"tri_materials must have {nt} entries, got {len(tm)}")
            if len(tm) and (tm.min() < 0 or tm.max() >= len(self.materials)):
                raise ValueError(f"tri_materials must lie in [0, {len(self.materials) - 1}]")
            tm = tm.astype(np.uint16)
        if not 0 <= material < len(self.materials):
            raise ValueError(f"material {material} does not exist ({len(self.materials)} made)")
        self.meshes.append({
            "vertices": v_host, "triangles": tris_host, "normals": n_host, "uvs": uv_host,
            "tri_materials": tm, "material": int(material), "flags": flags,
            "n_vertices": nv, "n_triangles": nt, "dynamic": bool(dynamic),
            "vbuf": vertices if on_device else None, "tbuf": triangles if on_device else None,
            "nbuf": normals if isinstance(normals, cl.Buffer) else None})
        return mesh_id

    def add_dynamic_mesh(self, n_vertices: int, triangles, *, material: int = 0,
                         tri_materials=None, normals: bool = True,
                         grid: tuple[int, int] | None = None
                         ) -> tuple[int, cl.Buffer, cl.Buffer | None]:
        """A mesh whose vertices a device stage writes every frame, stored once.

        Returns ``(mesh_id, vertices_buf, normals_buf)``: ``n_vertices`` float4 positions (and
        float4 normals when ``normals``; else None) that the writer fills (e.g.
        ``sim.write_surface(vertices_buf, normals_buf, origin)``) and that the BVH refit and the
        shader read in place: no per-frame copy. ``triangles``: (m, 3) vertex indices (the
        topology is fixed). The buffers stay valid until another dynamic mesh is added (which
        moves every dynamic mesh to larger arrays, contents copied on the device); take them
        again then with :meth:`dynamic_buffers`. Refitted by every :meth:`update`;
        ``grid=(nx, ny)``: an ``nx x ny`` vertex grid traced as a height field instead
        (``raytrace.scene.Scene.add_mesh``).
        """
        nv = int(n_vertices)
        if nv < 3:
            raise ValueError(f"a dynamic mesh needs n_vertices >= 3, got {n_vertices}")
        tris = np.asarray(triangles)
        if tris.ndim != 2 or tris.shape[1] != 3 or len(tris) < 1:
            raise ValueError(f"triangles must have shape (m, 3) with m >= 1, got {tris.shape}")
        if tris.min() < 0 or tris.max() >= nv:
            raise ValueError(f"triangle indices must lie in [0, {nv - 1}]")
        if not self.materials:
            self.add_material(Material())
        if not 0 <= material < len(self.materials):
            raise ValueError(f"material {material} does not exist ({len(self.materials)} made)")
        tris = np.ascontiguousarray(tris, np.uint32)
        nt = len(tris)
        tm = None
        flags = MESH_DYNAMIC | (MESH_HAS_NORMALS if normals else 0)
        if tri_materials is not None:
            tm = np.asarray(tri_materials).reshape(-1)
            if len(tm) != nt or (tm.min() < 0 or tm.max() >= len(self.materials)):
                raise ValueError(f"tri_materials must be {nt} ids in [0, "
                                 f"{len(self.materials) - 1}]")
            tm = tm.astype(np.uint16)
            flags |= MESH_TRI_MATERIALS
        old = [m for m in self.meshes if m.get("owned")]
        rec = {"vertices": None, "triangles": tris, "normals": None, "uvs": None,
               "tri_materials": tm, "material": int(material), "flags": flags,
               "n_vertices": nv, "n_triangles": nt, "dynamic": True, "owned": True,
               "has_normals": bool(normals), "vbuf": None, "tbuf": None, "nbuf": None}
        self._layout_dynamic(old + [rec])
        mesh_id = self.scene.add_mesh(rec["vbuf"], self.rt.to_device(tris), dynamic=True,
                                      n_vertices=nv, n_triangles=nt, grid=grid)
        rec["tbuf"] = self.scene.mesh_record(mesh_id).triangles_buf
        self.meshes.append(rec)
        return mesh_id, rec["vbuf"], rec["nbuf"]

    def dynamic_buffers(self, mesh_id: int) -> tuple[cl.Buffer, cl.Buffer | None]:
        """The current (vertices, normals) buffers of a mesh made by :meth:`add_dynamic_mesh`."""
        if not 0 <= int(mesh_id) < len(self.meshes) or not self.meshes[mesh_id].get("owned"):
            raise ValueError(f"mesh {mesh_id} was not made by add_dynamic_mesh")
        m = self.meshes[mesh_id]
        return m["vbuf"], m["nbuf"]

    def _layout_dynamic(self, dyn: list[dict]) -> None:
        """Place the dynamic meshes in (new) arrays of their own, each at an offset aligned to
        the device's MEM_BASE_ADDR_ALIGN so it can be handed out as a sub-buffer; contents of
        meshes already placed are copied over on the device."""
        rt = self.rt
        align_v = max(1, rt.device.mem_base_addr_align // 8 // 16)  # in float4 vertices
        offsets, total = [], 0
        for m in dyn:
            total = -(-total // align_v) * align_v
            offsets.append(total)
            total += m["n_vertices"]
        pos, nrm = rt.buffer(16 * total), rt.buffer(16 * total)
        for m, off in zip(dyn, offsets, strict=True):
            n = 16 * m["n_vertices"]
            if m["vbuf"] is not None:  # already placed: keep what its writer wrote
                for dst, src in ((pos, self.dyn_positions), (nrm, self.dyn_normals)):
                    cl.enqueue_copy(rt.queue, dst, src, src_offset=16 * m["dyn_offset"],
                                    dst_offset=16 * off, byte_count=n)
            m["dyn_offset"] = off
            whole = len(dyn) == 1
            m["vbuf"] = pos if whole else pos.get_sub_region(16 * off, n)
            m["nbuf"] = None if not m["has_normals"] else (
                nrm if whole else nrm.get_sub_region(16 * off, n))
        for i, m in enumerate(self.meshes):
            if m.get("owned"):
                self.scene.replace_vertex_buffer(i, m["vbuf"])
        self.dyn_positions, self.dyn_normals, self._dyn_vertices = pos, nrm, total
        self._layout_meshes = -1  # MeshInfo offsets change

    def add_instance(self, mesh_id: int, world_from_object=None, material: int = -1) -> int:
        """Place a mesh; ``material`` >= 0 overrides its materials."""
        if not -1 <= material < len(self.materials):
            raise ValueError(f"material {material} does not exist ({len(self.materials)} made)")
        inst = self.scene.add_instance(mesh_id, world_from_object)
        rec = np.zeros(1, INSTANCEINFO)
        rec["mesh"], rec["material"] = mesh_id, material
        self.instances = np.concatenate([self.instances, rec])
        self._dirty.add("instances")
        return inst

    def set_transform(self, instance_id: int, world_from_object) -> None:
        """Move an instance (:meth:`raytrace.scene.Scene.set_transform`: one row of the scene's
        transform buffer, which the shader reads too; normals follow on the device)."""
        self.scene.set_transform(instance_id, world_from_object)

    @property
    def transform_buffer(self) -> cl.Buffer:
        """The scene's device transform rows (``raytrace.scene.TRANSFORM_DTYPE``, one per
        instance at ``scene.transform_row(i)``), read by the TLAS build and the shader."""
        return self.scene.transform_buffer

    def add_light(self, kind: LightKind | str, *, direction=(0, -1, 0), color=(1, 1, 1),
                  position=(0, 0, 0), inner_angle: float = 20.0, outer_angle: float = 30.0
                  ) -> int:
        """A directional light (``direction`` it travels, irradiance ``color``) or a spot
        (``position``, axis ``direction``, intensity ``color`` in W/sr-like units falling off as
        1/d^2, cone half-angles in degrees). Returns its index."""
        kind = LightKind.from_str(kind)
        if len(self.lights) >= MAX_LIGHTS:
            raise ValueError(f"at most {MAX_LIGHTS} lights")
        if not 0 <= inner_angle <= outer_angle <= 180:
            raise ValueError(f"spot angles need 0 <= inner {inner_angle} <= outer {outer_angle}"
                             " <= 180 degrees")
        rec = np.zeros(1, LIGHT)
        rec["kind"] = int(kind)
        rec["direction"][0, :3] = _unit(direction, "light direction")
        rec["position"][0, :3] = _vec3(position, "light position")
        c = _vec3(color, "light color")
        if (c < 0).any():
            raise ValueError(f"light color must be >= 0, got {color}")
        rec["color"][0, :3] = c
        rec["cos_inner"] = math.cos(math.radians(inner_angle))
        rec["cos_outer"] = math.cos(math.radians(outer_angle))
        self.lights = np.concatenate([self.lights, rec])
        self._dirty.add("lights")
        return len(self.lights) - 1

    def set_sky(self, sky: Sky) -> None:
        _unit(sky.sun_direction, "sun direction")
        if sky.kind == SkyKind.CUBEMAP and not 0 <= sky.cubemap <= len(self.textures) - 6:
            raise ValueError("a cubemap sky needs six textures starting at sky.cubemap")
        self.sky = sky

    @property
    def has_dielectric(self) -> bool:
        return any(m.ior > 0 for m in self.materials)

    @property
    def has_secondary(self) -> bool:
        """Whether any material spawns reflection or refraction rays."""
        return any(m.ior > 0 or m.reflectivity > 0 for m in self.materials)

    @property
    def n_triangles(self) -> int:
        return sum(m["n_triangles"] for m in self.meshes)

    # -- device tables ---------------------------------------------------------------------
    def _build_layout(self) -> None:
        rt = self.rt
        nv = sum(m["n_vertices"] for m in self.meshes if not m.get("owned"))
        nt = sum(m["n_triangles"] for m in self.meshes)
        info = np.zeros(len(self.meshes), MESHINFO)
        pos = np.zeros((max(nv, 1), 4), np.float32)
        nrm = np.zeros((max(nv, 1), 4), np.float32)
        uv = np.zeros((max(nv, 1), 2), np.float32)
        tris = np.zeros((max(nt, 1), 3), np.uint32)
        tmat = np.zeros(max(nt, 1), np.uint16)
        vo = to = 0
        for k, m in enumerate(self.meshes):
            n, t = m["n_vertices"], m["n_triangles"]
            if m.get("owned"):  # vertices in the dynamic arrays; triangles here as any mesh's
                info[k] = (m["dyn_offset"], to, m["material"], m["flags"])
                tris[to:to + t] = m["triangles"]
                if m["tri_materials"] is not None:
                    tmat[to:to + t] = m["tri_materials"]
                m["vert_offset"], m["tri_offset"] = m["dyn_offset"], to
                to += t
                continue
            info[k] = (vo, to, m["material"], m["flags"])
            if m["vertices"] is not None:
                pos[vo:vo + n, :3] = m["vertices"]
            if m["normals"] is not None:
                nrm[vo:vo + n, :3] = m["normals"]
            if m["uvs"] is not None:
                uv[vo:vo + n] = m["uvs"]
            if m["triangles"] is not None:
                tris[to:to + t] = m["triangles"]
            if m["tri_materials"] is not None:
                tmat[to:to + t] = m["tri_materials"]
            m["vert_offset"], m["tri_offset"] = vo, to
            vo += n
            to += t
        self.mesh_info = rt.to_device(info if len(info) else np.zeros(1, MESHINFO))
        self.positions = rt.to_device(pos)
        self.normals = rt.to_device(nrm)
        self.uvs = rt.to_device(uv)
        self.triangles = rt.to_device(tris)
        self.tri_materials = rt.to_device(tmat)
        for m in self.meshes:  # device-only triangles: copied once
            if m["triangles"] is None:
                cl.enqueue_copy(rt.queue, self.triangles, m["tbuf"],
                                dst_offset=12 * m["tri_offset"], byte_count=12 * m["n_triangles"])
        self._layout_meshes = len(self.meshes)

    def _copy_dynamic(self) -> None:
        rt = self.rt
        for m in self.meshes:
            if m["vbuf"] is None or m.get("owned"):  # owned: written in place, never copied
                continue
            n = 16 * m["n_vertices"]
            rt.record("render.geometry", cl.enqueue_copy(
                rt.queue, self.positions, m["vbuf"], dst_offset=16 * m["vert_offset"],
                byte_count=n))
            if m["nbuf"] is not None:
                rt.record("render.geometry", cl.enqueue_copy(
                    rt.queue, self.normals, m["nbuf"], dst_offset=16 * m["vert_offset"],
                    byte_count=n))

    def _upload_tables(self) -> None:
        rt = self.rt
        if "materials" in self._dirty:
            recs = np.array([m.record() for m in self.materials] or [Material().record()],
                            MATERIAL)
            self.material_buf = rt.to_device(recs)
        if "textures" in self._dirty:
            info = np.zeros(max(len(self.textures), 1), TEXINFO)
            off = 0
            for k, t in enumerate(self.textures):
                info[k] = (off, t.shape[1], t.shape[0], 0)
                off += t.shape[0] * t.shape[1]
            texels = (np.concatenate([t.reshape(-1, 4) for t in self.textures])
                      if self.textures else np.zeros((1, 4), np.float32))
            self.texinfo_buf = rt.to_device(info)
            self.texel_buf = rt.to_device(texels)
        if "lights" in self._dirty:
            self.light_buf = rt.to_device(self.lights if len(self.lights) else np.zeros(1, LIGHT))
        if "instances" in self._dirty:
            recs = self.instances if len(self.instances) else np.zeros(1, INSTANCEINFO)
            if getattr(self, "_inst_n", -1) != len(recs):
                self.instance_buf = rt.buffer(recs.nbytes)
                self._inst_n = len(recs)
            rt.record("render.geometry", cl.enqueue_copy(rt.queue, self.instance_buf, recs.copy(),
                                                         is_blocking=False))
        self._dirty.clear()

    def instance_materials(self, instance_id: int) -> set:
        """The material ids an instance's triangles can have."""
        rec = self.instances[int(instance_id)]
        if int(rec["material"]) >= 0:
            return {int(rec["material"])}
        m = self.meshes[int(rec["mesh"])]
        if m["tri_materials"] is not None:
            return {int(x) for x in np.unique(m["tri_materials"])}
        return {int(m["material"])}

    def _set_masks(self) -> None:
        """Each instance's visibility bit: MASK_OPAQUE when every material it can show is
        opaque, else MASK_TRANSMISSIVE (render_shade.cl's shadow rays trace them apart); and
        :attr:`crossing_instance`."""
        holding = []
        for i in range(len(self.instances)):
            diel = any(self.materials[k].ior > 0 for k in self.instance_materials(i))
            self.scene.set_instance_mask(i, MASK_TRANSMISSIVE if diel else MASK_OPAQUE)
            if diel:
                holding.append(i)
        self.crossing_instance = holding[0] if len(holding) == 1 else -1

    def update(self, rebuild: bool = False) -> None:
        """Bring BVHs and shading tables up to date (enqueued; no host sync)."""
        if not self.materials:
            self.add_material(Material())
        if len(self.meshes) != self._layout_meshes:
            self._build_layout()
        self._copy_dynamic()
        if self._dirty & {"instances", "materials"}:
            self._set_masks()
        self._upload_tables()
        self.scene.update(rebuild=rebuild)

    def shade_args(self) -> list:
        """Buffers for ``RENDER_GEOM_PARAMS`` in order; valid after :meth:`update`."""
        return list(self.shade_bindings().values())

    def shade_bindings(self) -> dict:
        """``RENDER_GEOM_PARAMS`` (kernels/render_surface.h) by name, for ``Kernel.bind``."""
        return {"g_inst": self.instance_buf, "g_xform": self.scene.transform_buffer,
                "g_nxform": self.scene.normal_buffer, "g_mesh": self.mesh_info,
                "g_pos": self.positions, "g_nrm": self.normals, "g_uv": self.uvs,
                "g_tri": self.triangles,
                "g_tri_mat": self.tri_materials, "g_mat": self.material_buf,
                "g_tex": self.texinfo_buf, "g_texels": self.texel_buf,
                "g_dpos": self.dyn_positions, "g_dnrm": self.dyn_normals}

    def tables(self) -> dict:
        """Host copies for the float64 reference (dynamic meshes are read back: test use only)."""
        meshes = []
        for m in self.meshes:
            d = dict(m)
            if d["vertices"] is None:
                d["vertices"] = self.rt.to_host(m["vbuf"], np.float32,
                                                4 * m["n_vertices"]).reshape(-1, 4)[:, :3]
            if d["triangles"] is None:
                d["triangles"] = self.rt.to_host(m["tbuf"], np.uint32,
                                                 3 * m["n_triangles"]).reshape(-1, 3)
            if d["nbuf"] is not None:
                d["normals"] = self.rt.to_host(m["nbuf"], np.float32,
                                               4 * m["n_vertices"]).reshape(-1, 4)[:, :3]
            meshes.append(d)
        # the reference's instance table: mesh, material and world_from_object (as on the device)
        inst = np.zeros(len(self.instances), [("mesh", np.uint32), ("material", np.int32),
                                              ("world_from_object", np.float32, (3, 4))])
        inst["mesh"], inst["material"] = self.instances["mesh"], self.instances["material"]
        inst["world_from_object"] = self.scene.read_transforms()
        return {"meshes": meshes, "instances": inst,
                "materials": np.array([m.record() for m in self.materials], MATERIAL),
                "textures": list(self.textures)}

    def bytes_per_triangle(self) -> dict:
        """Device bytes per triangle: BVH (nodes + leaf triangles) and shading attributes."""
        from raytrace.bvh import NODE_DTYPE, TRI_DTYPE, node_count
        nt = max(self.n_triangles, 1)
        nv = sum(m["n_vertices"] for m in self.meshes)
        in_bvh = [0 if r.grid is not None else r.n_triangles for r in self.scene.meshes]
        bvh = sum(node_count(n) for n in in_bvh) * NODE_DTYPE.itemsize \
            + sum(in_bvh) * TRI_DTYPE.itemsize
        shading = nv * (16 + 16 + 8) + self.n_triangles * (12 + 2)
        return {"bvh": bvh / nt, "shading": shading / nt, "total": (bvh + shading) / nt}
