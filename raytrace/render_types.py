"""Renderer device structs as NumPy dtypes (one mirror per struct in ``kernels/render_types.h``,
layouts proved on the device by ``tests/raytrace/test_render_layout.py``) and its closed sets of
choices as enums whose integers equal the ``#define``s of the header."""

from __future__ import annotations

import enum

import numpy as np

from kernels.errors import InputError

MAX_LIGHTS = 8
MAX_DEPTH = 32
STAT_DROPPED = MAX_DEPTH + 1
STAT_SHADOW_LISTED = MAX_DEPTH + 2
STAT_SHADOW_SPILLED = MAX_DEPTH + 3
STATS_LEN = MAX_DEPTH + 4
SHADOW_RAY_LIGHT_SHIFT = 28
GATHER_FINISH_SHADOW_LIST = 2
SCAN_BLOCK = 1024
SCAN_WG = 256
TILE = 8


class _Choice(enum.IntEnum):
    @classmethod
    def from_str(cls, name: str | _Choice):
        if isinstance(name, cls):
            return name
        try:
            return cls[str(name).upper()]
        except KeyError:
            valid = ", ".join(m.name.lower() for m in cls)
            raise InputError(f"unknown {cls.__name__} {name!r}; valid: {valid}") from None

    def __str__(self) -> str:
        return self.name.lower()


class SamplePattern(_Choice):
    CENTER = 0      # one ray through the pixel centre (spp must be 1)
    RGSS = 1        # rotated grid, 4 rays
    JITTERED = 2    # stratified cols x rows grid, one random point per cell


class PixelOrder(_Choice):
    ROWS = 0        # scanlines
    TILES = 1       # 8x8 tiles, Morton order inside (coherent primary rays)


class FresnelMode(_Choice):
    EXACT = 0       # unpolarised dielectric Fresnel equations
    SCHLICK = 1     # Schlick's approximation


class LightKind(_Choice):
    DIRECTIONAL = 0
    SPOT = 1


class SkyKind(_Choice):
    PROCEDURAL = 0  # gradient + sun disk and glow
    CUBEMAP = 1     # six face images


class Tonemap(_Choice):
    CLAMP = 0
    REINHARD = 1
    ACES = 2


f4 = (np.float32, 4)

RAY = np.dtype([("ox", np.float32), ("oy", np.float32), ("oz", np.float32), ("pixel", np.uint32),
                ("dx", np.float32), ("dy", np.float32), ("dz", np.float32), ("medium", np.int32),
                ("wr", np.float32), ("wg", np.float32), ("wb", np.float32), ("sample", np.uint32)])

SHADOW_RAY = np.dtype([("ox", np.float32), ("oy", np.float32), ("oz", np.float32),
                       ("pixel_light", np.uint32), ("cr", np.float32), ("cg", np.float32),
                       ("cb", np.float32), ("medium", np.int32)])

CAMERA = np.dtype([("origin", f4), ("right", f4), ("up", f4), ("forward", f4),
                   ("width", np.uint32), ("height", np.uint32), ("spp", np.uint32),
                   ("pattern", np.uint32), ("order", np.uint32), ("tiles_x", np.uint32),
                   ("jitter_cols", np.uint32), ("seed", np.uint32)])

MATERIAL = np.dtype([("diffuse", f4), ("specular", f4), ("absorption", f4),
                     ("reflectivity", np.float32), ("texture", np.int32),
                     ("uv_scale_u", np.float32), ("uv_scale_v", np.float32)])

LIGHT = np.dtype([("position", f4), ("direction", f4), ("color", f4), ("kind", np.int32),
                  ("cos_inner", np.float32), ("cos_outer", np.float32), ("pad", np.float32)])

TEXINFO = np.dtype([("offset", np.uint32), ("width", np.uint32), ("height", np.uint32),
                    ("pad", np.uint32)])

MESHINFO = np.dtype([("vert_offset", np.uint32), ("tri_offset", np.uint32),
                     ("material", np.int32), ("flags", np.uint32)])

INSTANCEINFO = np.dtype([("mesh", np.uint32), ("material", np.int32),
                         ("pad0", np.uint32), ("pad1", np.uint32)])

RENDERPARAMS = np.dtype([("ambient", f4), ("sky_zenith", f4), ("sky_horizon", f4),
                         ("sky_ground", f4), ("sun_dir", f4), ("sun_color", f4),
                         ("exposure", f4),
                         ("n_lights", np.uint32), ("fresnel", np.uint32), ("sky", np.uint32),
                         ("cubemap_tex", np.uint32), ("transmissive_shadows", np.uint32),
                         ("tonemap", np.uint32), ("max_depth", np.uint32),
                         ("capacity", np.uint32), ("min_weight", np.float32),
                         ("crossing_instance", np.int32), ("one_crossing", np.uint32),
                         ("pad2", np.float32)])

AOV = np.dtype([("normal", f4), ("depth", np.float32), ("prim", np.int32), ("inst", np.int32),
                ("material", np.int32)])

#: render_raygen's, render_gather's and the shadow list's per-launch values (by value, 16, 20
#: and 16 bytes).
RAYGEN_PARAMS = np.dtype([("q0", np.uint32), ("n_rays", np.uint32), ("zero_stats", np.uint32),
                          ("zero_light", np.uint32)])
GATHER_PARAMS = np.dtype([("scatter", np.uint32), ("accumulate", np.uint32), ("q0", np.uint32),
                          ("n_q", np.uint32), ("finish", np.uint32)])
SHADOW_LIST_PARAMS = np.dtype([("main_room", np.uint32), ("full_room", np.uint32),
                               ("pad0", np.uint32), ("pad1", np.uint32)])

#: Instance visibility bits (kernels/render_types.h): all opaque, or holding a dielectric.
MASK_OPAQUE = 1
MASK_TRANSMISSIVE = 2
MESH_HAS_NORMALS = 1
MESH_HAS_UVS = 2
MESH_TRI_MATERIALS = 4
MESH_DYNAMIC = 8

#: (header, struct name, dtype) for every device struct of the renderer.
STRUCTS = [
    ("render_types.h", "Ray", RAY),
    ("render_types.h", "ShadowRay", SHADOW_RAY),
    ("render_types.h", "ShadowListParams", SHADOW_LIST_PARAMS),
    ("render_types.h", "Camera", CAMERA),
    ("render_types.h", "Material", MATERIAL),
    ("render_types.h", "Light", LIGHT),
    ("render_types.h", "TexInfo", TEXINFO),
    ("render_types.h", "MeshInfo", MESHINFO),
    ("render_types.h", "InstanceInfo", INSTANCEINFO),
    ("render_types.h", "RenderParams", RENDERPARAMS),
    ("render_types.h", "Aov", AOV),
    ("render_types.h", "RaygenParams", RAYGEN_PARAMS),
    ("render_types.h", "GatherParams", GATHER_PARAMS),
]
