"""The wavefront Whitted renderer: one :class:`Renderer` per image size, driven once per frame.

A frame is a list of launches with no host sync inside (kernels launched at their maximum size,
the device-side ray count decides who works). For each chunk of pixels (the whole image unless
the ray buffers would not fit in device memory):

    render.raygen      primary rays, 8x8 tiles in Morton order, spp per pixel, weight 1/spp
    per depth 0..levels (levels: bounces, or as many as the last frame needed):
      render.trace     closest hit (render.trace_secondary for depth >= 1)
      render.shade     ambient, sky on a miss, Beer-Lambert, child counts, primary AOVs
      render.shadow    shadow rays and Phong direct light per light
      render.secondary prefix-sum compaction of reflection/refraction children (3 launches)
      render.accumulate  each pixel gathers its rays' radiance (rays stay sorted by pixel)
    render.tonemap     exposure, tonemap, sRGB -> RGBA8

Only the RGBA8 image is read back (:meth:`Renderer.read_rgba`); ray counts stay on the device
and are read on request (:meth:`Renderer.read_stats`, used by the benchmark).
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pyopencl as cl

from kernels.runtime import Runtime
from raytrace.bvh import HIT_DTYPE
from raytrace.render_scene import RenderScene
from raytrace.render_types import (
    AOV,
    CAMERA,
    MAX_DEPTH,
    RAY,
    RENDERPARAMS,
    SCAN_BLOCK,
    SCAN_WG,
    STAT_DROPPED,
    STATS_LEN,
    TILE,
    FresnelMode,
    PixelOrder,
    SamplePattern,
    SkyKind,
    Tonemap,
)

#: kernel id -> (id of the renderer that last bound it, its arguments); see Renderer._bind
_BOUND: dict[int, tuple[int, list]] = {}
_TOKENS = itertools.count()

#: Device bytes per ray slot: input and output ray, hit record, radiance, child count/offset.
BYTES_PER_RAY_SLOT = 2 * RAY.itemsize + HIT_DTYPE.itemsize + 16 + 4


@dataclasses.dataclass(frozen=True)
class RenderSettings:
    width: int = 640
    height: int = 480
    spp: int = 1                  #: samples (primary rays) per pixel
    bounces: int = 5              #: maximum reflection/refraction depth
    pattern: str | None = None    #: center | rgss | jittered; None: center (1), rgss (4), jittered
    order: str = "tiles"          #: tiles (8x8 Morton) | rows
    fresnel: str = "exact"        #: exact | schlick
    tonemap: str = "aces"         #: clamp | reinhard | aces
    exposure: float = 1.0
    min_weight: float = 1e-3      #: children whose contribution falls below this are cut
    seed: int = 0                 #: jitter seed
    capacity_factor: float = 4.0  #: wavefront slots per primary ray of a chunk
    memory_fraction: float = 0.25  #: most of the device memory the ray buffers may take
    max_chunk_rays: int | None = None  #: cap on primary rays per chunk (tests of the tiling)
    aov: bool = False             #: write primary depth/normal/prim/inst per pixel
    adaptive_depth: bool = True   #: launch only as many levels as the last frame needed
    local_size: int = 64          #: work-group size of the per-ray and per-pixel stages

    def resolved(self) -> RenderSettings:
        """Validated copy with the sample pattern decided; one-line ValueErrors."""
        for name, lo, hi in (("width", 1, 16384), ("height", 1, 16384), ("spp", 1, 4096),
                             ("bounces", 0, MAX_DEPTH)):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or not lo <= v <= hi:
                raise ValueError(f"render {name} must be an integer in [{lo}, {hi}], got {v!r}")
        if not (math.isfinite(self.exposure) and self.exposure > 0):
            raise ValueError(f"render exposure must be > 0, got {self.exposure}")
        if not 0 <= self.min_weight < 1:
            raise ValueError(f"render min_weight must lie in [0, 1), got {self.min_weight}")
        if self.local_size not in (32, 64, 128, 256, 512):
            raise ValueError(f"local_size must be 32, 64, 128, 256 or 512, got {self.local_size}")
        if not 1.0 <= self.capacity_factor <= 64:
            raise ValueError(f"capacity_factor must lie in [1, 64], got {self.capacity_factor}")
        pattern = self.pattern or ("center" if self.spp == 1 else
                                   "rgss" if self.spp == 4 else "jittered")
        p = SamplePattern.from_str(pattern)
        if p == SamplePattern.CENTER and self.spp != 1:
            raise ValueError(f"sample pattern center needs spp 1, got {self.spp}")
        if p == SamplePattern.RGSS and self.spp != 4:
            raise ValueError(f"sample pattern rgss needs spp 4, got {self.spp}")
        PixelOrder.from_str(self.order)
        FresnelMode.from_str(self.fresnel)
        Tonemap.from_str(self.tonemap)
        return dataclasses.replace(self, pattern=str(p))


def jitter_cols(spp: int) -> int:
    """Columns of the jittered grid: the largest divisor of spp not above sqrt(spp)."""
    return max(c for c in range(1, math.isqrt(spp) + 1) if spp % c == 0)


def make_camera(eye, target, up, fov_deg: float, settings: RenderSettings) -> np.ndarray:
    """The device Camera record (pinhole, vertical field of view in degrees)."""
    eye = np.asarray(eye, np.float64)
    fwd = np.asarray(target, np.float64) - eye
    if not np.linalg.norm(fwd) > 0:
        raise ValueError("camera target equals eye")
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(up, np.float64))
    if not np.linalg.norm(right) > 1e-9:
        raise ValueError("camera up is parallel to the view direction")
    right /= np.linalg.norm(right)
    true_up = np.cross(right, fwd)
    if not 0 < fov_deg < 180:
        raise ValueError(f"camera fov must lie in (0, 180) degrees, got {fov_deg}")
    th = math.tan(math.radians(fov_deg) / 2)
    s = settings
    cam = np.zeros(1, CAMERA)[0]
    cam["origin"][:3] = eye
    cam["right"][:3] = right * th * s.width / s.height
    cam["up"][:3] = true_up * th
    cam["forward"][:3] = fwd
    cam["width"], cam["height"], cam["spp"] = s.width, s.height, s.spp
    cam["pattern"] = int(SamplePattern.from_str(s.pattern))
    cam["order"] = int(PixelOrder.from_str(s.order))
    cam["tiles_x"] = -(-s.width // TILE)
    cam["jitter_cols"] = jitter_cols(s.spp)
    cam["seed"] = s.seed & 0xFFFFFFFF
    return cam


class Renderer:
    """Renders a :class:`RenderScene` into an RGBA8 device buffer, one frame per call."""

    def __init__(self, rt: Runtime, scene: RenderScene, settings: RenderSettings):
        self.rt, self.scene = rt, scene
        self._token = next(_TOKENS)  # never reused, unlike id(self)
        self.settings = s = settings.resolved()
        order = PixelOrder.from_str(s.order)
        self.n_pixels = s.width * s.height
        self.n_q = (self.n_pixels if order == PixelOrder.ROWS
                    else -(-s.width // TILE) * -(-s.height // TILE) * TILE * TILE)
        # chunk of pixels whose ray buffers fit in the memory budget
        budget = s.memory_fraction * rt.device.global_mem_size
        max_alloc = rt.device.max_mem_alloc_size
        slot_limit = min(budget / BYTES_PER_RAY_SLOT, max_alloc / RAY.itemsize)
        chunk_q = int(slot_limit / (s.capacity_factor * s.spp))
        if s.max_chunk_rays is not None:
            chunk_q = min(chunk_q, max(1, s.max_chunk_rays // s.spp))
        if order == PixelOrder.TILES:
            chunk_q = max(TILE * TILE, chunk_q // (TILE * TILE) * TILE * TILE)
        self.chunk_q = max(1, min(self.n_q, chunk_q))
        self.chunks = [(q0, min(self.chunk_q, self.n_q - q0))
                       for q0 in range(0, self.n_q, self.chunk_q)]
        self.n_primary_max = self.chunk_q * s.spp
        self.capacity = max(self.n_primary_max,
                            int(math.ceil(s.capacity_factor * self.n_primary_max)))
        cap = self.capacity
        self.rays = [rt.buffer(cap * RAY.itemsize), rt.buffer(cap * RAY.itemsize)]
        self.hits = rt.buffer(cap * HIT_DTYPE.itemsize)
        self.radiance = rt.buffer(cap * 16)
        self.child = rt.buffer(cap * 4)
        self.block_sums = rt.buffer(4 * -(-cap // SCAN_BLOCK))
        self.counts = rt.buffer(4 * (MAX_DEPTH + 2))
        self.stats = rt.buffer(4 * STATS_LEN)
        self._stats_host = np.zeros(STATS_LEN, np.uint32)  # last frame's, copied without a wait
        self._stats_evt: cl.Event | None = None
        self._levels = self._deepest = s.bounces
        self.framebuffer = rt.buffer(16 * self.n_pixels)
        self.rgba = rt.buffer(4 * self.n_pixels)
        self.aov = rt.buffer(AOV.itemsize * (self.n_pixels if s.aov else 1))
        self.camera_buf = rt.buffer(CAMERA.itemsize)
        self.params_buf = rt.buffer(RENDERPARAMS.itemsize)
        self._camera = None
        k = rt.kernel
        self.k_raygen = k("render_raygen.cl", "render_raygen")
        self.k_trace = k("render_trace.cl", "render_trace")
        self.k_shade = k("render_shade.cl", "render_shade")
        self.k_shadow = k("render_shade.cl", "render_shadow")
        self.k_scan_blocks = k("render_secondary.cl", "render_scan_blocks")
        self.k_scan_sums = k("render_secondary.cl", "render_scan_sums")
        self.k_scatter = k("render_secondary.cl", "render_scatter")
        self.k_accumulate = k("render_frame.cl", "render_accumulate")
        self.k_tonemap = k("render_frame.cl", "render_tonemap")

    def _bind(self, kernel, *args) -> None:
        """Set only the arguments that changed since ``kernel`` was last bound, by this renderer
        (kernel objects are shared per device; arguments are captured at enqueue time)."""
        owner, prev = _BOUND.get(id(kernel), (None, None))
        if owner != self._token:  # another renderer bound it since: set everything
            prev = None
        for i, a in enumerate(args):
            if prev is not None and (prev[i] is a or (isinstance(a, np.generic)
                                                      and type(prev[i]) is type(a)
                                                      and prev[i] == a)):
                continue
            kernel.set_arg(i, a)
        _BOUND[id(kernel)] = (self._token, list(args))

    # -- inputs -----------------------------------------------------------------------------
    def set_camera(self, eye, target, up=(0.0, 1.0, 0.0), fov: float = 60.0) -> None:
        """Camera for the next frames (uploaded with the frame, 96 bytes)."""
        self._camera = make_camera(eye, target, up, fov, self.settings)

    def set_camera_record(self, camera: np.ndarray) -> None:
        """Use a Camera record made by :func:`make_camera` (same image size and samples)."""
        c = np.asarray(camera, CAMERA).reshape(())
        s = self.settings
        if (int(c["width"]), int(c["height"]), int(c["spp"])) != (s.width, s.height, s.spp):
            raise ValueError("camera record was made for another image size or spp")
        self._camera = c.copy()

    @property
    def camera(self) -> np.ndarray:
        if self._camera is None:
            raise ValueError("Renderer: call set_camera() before rendering")
        return self._camera

    def params(self) -> np.ndarray:
        """The RenderParams record of the current scene and settings."""
        s, sc = self.settings, self.scene
        sky = sc.sky
        p = np.zeros(1, RENDERPARAMS)[0]
        p["ambient"][:3] = sc.ambient
        p["sky_zenith"][:3] = sky.zenith
        p["sky_horizon"][:3] = sky.horizon
        p["sky_ground"][:3] = sky.ground
        sd = np.asarray(sky.sun_direction, np.float64)
        p["sun_dir"][:3] = sd / np.linalg.norm(sd)
        p["sun_dir"][3] = math.cos(math.radians(sky.sun_radius))
        p["sun_color"][:3] = sky.sun_color
        p["sun_color"][3] = sky.sun_glow
        p["exposure"][0] = s.exposure
        p["n_lights"] = len(sc.lights)
        p["fresnel"] = int(FresnelMode.from_str(s.fresnel))
        p["sky"] = int(sky.kind)
        p["cubemap_tex"] = max(sky.cubemap, 0) if sky.kind == SkyKind.CUBEMAP else 0
        p["transmissive_shadows"] = int(sc.has_dielectric)
        p["tonemap"] = int(Tonemap.from_str(s.tonemap))
        p["max_depth"] = s.bounces
        p["capacity"] = self.capacity
        # the cut-off is a share of the pixel: a ray of weight w stands for w * spp of a sample
        p["min_weight"] = s.min_weight / s.spp
        return p

    # -- the frame ----------------------------------------------------------------------------
    def enqueue_frame(self, *, update_scene: bool = True) -> None:
        """Queue one frame (scene update, all chunks, tonemap). No host sync."""
        rt, s, q = self.rt, self.settings, self.rt.queue
        if update_scene:
            self.scene.update()
        cl.enqueue_copy(q, self.camera_buf, self.camera.copy(), is_blocking=False)
        cl.enqueue_copy(q, self.params_buf, np.array([self.params()]), is_blocking=False)
        rt.record("render.raygen", cl.enqueue_fill_buffer(q, self.stats, np.uint32(0), 0,
                                                          4 * STATS_LEN))
        scene_args = self.scene.scene.trace_args()
        geom = self.scene.shade_args()
        lights = self.scene.light_buf
        has_lights = len(self.scene.lights) > 0
        # no material reflects or refracts: no secondary wavefront can exist, launch none
        deepest = s.bounces if self.scene.has_secondary else 0
        bounces = min(deepest, self._level_hint()) if s.adaptive_depth else deepest
        self._levels, self._deepest = bounces, deepest
        u32 = np.uint32
        ls = s.local_size
        for q0, nq in self.chunks:
            n_rays = nq * s.spp
            self._bind(self.k_raygen, self.camera_buf, u32(q0), u32(n_rays), self.rays[0],
                       self.counts)
            rt.launch("render.raygen", self.k_raygen, n_rays)
            cur, nxt = 0, 1
            launch_n = n_rays
            for depth in range(bounces + 1):
                d = u32(depth)
                rays, hits = self.rays[cur], self.hits
                self._bind(self.k_trace, *scene_args, rays, self.counts, d, hits)
                rt.launch("render.trace" if depth == 0 else "render.trace_secondary",
                          self.k_trace, launch_n, ls)
                self._bind(self.k_shade, *geom, self.params_buf, self.camera_buf, rays, hits,
                           self.counts, d, self.radiance, self.child, self.aov, u32(s.aov))
                rt.launch("render.shade", self.k_shade, launch_n, ls)
                if has_lights:
                    self._bind(self.k_shadow, *scene_args, *geom, self.params_buf, lights, rays,
                               hits, self.counts, d, self.radiance)
                    rt.launch("render.shadow", self.k_shadow, launch_n, ls)
                if depth < deepest:  # the last launched level still counts its children
                    n_blocks = -(-launch_n // SCAN_BLOCK)
                    self._bind(self.k_scan_blocks, self.child, self.counts, d, self.block_sums)
                    rt.launch("render.secondary", self.k_scan_blocks, n_blocks * SCAN_WG, SCAN_WG)
                    self._bind(self.k_scan_sums, self.block_sums, u32(n_blocks), self.counts, d,
                               u32(self.capacity), self.stats)
                    rt.launch("render.secondary", self.k_scan_sums, SCAN_WG, SCAN_WG)
                if depth < bounces:
                    self._bind(self.k_scatter, *geom, self.params_buf, rays, hits, self.counts, d,
                               self.child, self.block_sums, self.rays[nxt])
                    rt.launch("render.secondary", self.k_scatter, launch_n, ls)
                self._bind(self.k_accumulate, self.camera_buf, u32(q0), u32(nq), rays,
                           self.radiance, self.counts, d, self.framebuffer)
                rt.launch("render.accumulate", self.k_accumulate, nq, ls)
                cur, nxt = nxt, cur
                launch_n = min(self.capacity, 2 * launch_n)
        self._bind(self.k_tonemap, self.framebuffer, u32(self.n_pixels), self.params_buf, self.rgba)
        rt.launch("render.tonemap", self.k_tonemap, self.n_pixels, ls)
        self._stats_evt = cl.enqueue_copy(q, self._stats_host, self.stats, is_blocking=False)

    def _level_hint(self) -> int:
        """Depth levels to launch: the deepest level with rays in the last frame whose counts
        have arrived (never waits; all levels before any has). The last launched level records
        the children it could not trace, so a scene that needs one level more gets it in the
        next frame (for one frame those rays are missing: read_stats()['untraced'])."""
        evt = self._stats_evt
        if evt is None or evt.command_execution_status != cl.command_execution_status.COMPLETE:
            return self.settings.bounces if evt is None else self._levels
        deep = [d for d in range(1, self.settings.bounces + 1) if self._stats_host[d] > 0]
        return max(deep, default=0)

    # -- outputs (each one synchronises) ------------------------------------------------------
    def read_rgba(self) -> np.ndarray:
        """The last frame as (height, width, 4) uint8, row 0 at the top."""
        s = self.settings
        return self.rt.to_host(self.rgba, np.uint8, 4 * self.n_pixels).reshape(
            s.height, s.width, 4)

    def render(self) -> np.ndarray:
        self.enqueue_frame()
        return self.read_rgba()

    def read_framebuffer(self) -> np.ndarray:
        """Linear radiance (height, width, 3) float32 before exposure and tonemap."""
        s = self.settings
        fb = self.rt.to_host(self.framebuffer, np.float32, 4 * self.n_pixels)
        return fb.reshape(s.height, s.width, 4)[..., :3]

    def read_aov(self) -> dict:
        """Primary-hit depth (m, inf on a miss), normal, prim and instance ids (-1 on a miss)."""
        s = self.settings
        if not s.aov:
            raise ValueError("Renderer was made without aov=True")
        a = self.rt.to_host(self.aov, AOV, self.n_pixels).reshape(s.height, s.width)
        return {"depth": a["depth"].copy(), "normal": a["normal"][..., :3].copy(),
                "prim": a["prim"].copy(), "inst": a["inst"].copy(),
                "material": a["material"].copy()}

    def read_stats(self) -> dict:
        """Rays traced per depth over the last frame and children dropped (wavefront full)."""
        st = self.rt.to_host(self.stats, np.uint32, STATS_LEN)
        L = self._levels
        per_depth = [int(x) for x in st[: L + 1]]
        if self._deepest == 0:  # no scan ran: the primary count is the chunks' sum
            per_depth = [sum(nq * self.settings.spp for _, nq in self.chunks)]
        untraced = int(st[L + 1]) if L < self._deepest else 0
        return {"rays_per_depth": per_depth, "dropped": int(st[STAT_DROPPED]),
                "secondary_rays": int(sum(per_depth[1:])), "levels": L, "untraced": untraced}

    def memory_report(self) -> dict:
        """Device bytes per ray slot and per primary ray, and per triangle of the scene."""
        return {"bytes_per_ray_slot": BYTES_PER_RAY_SLOT,
                "bytes_per_primary_ray": BYTES_PER_RAY_SLOT * self.capacity / self.n_primary_max,
                "ray_slots": self.capacity, "chunks": len(self.chunks),
                "bytes_per_triangle": self.scene.bytes_per_triangle()}
