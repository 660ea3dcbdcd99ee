"""The wavefront Whitted renderer: one :class:`Renderer` per image size, driven once per frame.

A frame is a list of launches with no host sync inside (kernels launched at their maximum size,
the device-side ray count decides who works). For each chunk of pixels (the whole image unless
the ray buffers would not fit in device memory):

    render.raygen      primary rays, 8x8 tiles in Morton order, spp per pixel, weight 1/spp
    per depth 0..bounces (every level, every frame: a frame never depends on the last one):
      render.trace     closest hit (render.trace_secondary for depth >= 1)
      render.shade     ambient, sky on a miss, Beer-Lambert, child counts, primary AOVs
      render.shadow    shadow rays and Phong direct light per light
      render.secondary prefix-sum compaction offsets of the reflection/refraction children (one
                       launch: block scans, the last block scans the block totals)
      render.gather    children scattered into the next wavefront; each pixel gathers its rays'
                       radiance (rays stay sorted by pixel); after the last level, tonemap + sRGB

That is the order with ``overlap_levels`` off. On (the default), level d's shadow rays and level
d + 1's trace, independent once level d's children are scattered, share one launch
(render.shadow_trace, named after level d + 1), so the tail levels' few shadow rays cost no
traversal latency of their own (NVIDIA runs no two kernels of one queue at once):

    render.trace, render.shade                                    level 0
    per depth d < deepest:
      render.secondary, render.gather (scatter only)              children of level d
      render.shadow_trace  level d's shadow rays + level d+1's trace (and shade, fused)
      render.gather (accumulate only)                             level d into the framebuffer
      render.shade                                                level d+1 (unless fused)
    render.shadow, render.gather, tonemap                         the deepest level

``overlap_from`` D keeps the levels before D in the first order (their shadow rays alone), e.g.
to overlap only the tail levels of few rays. The levels' hits live in two buffers by parity
(level d's shadow rays read theirs while d + 1 traces), and with ``fuse_trace_shade`` the
radiance too; unfused, level d + 1's shade runs after level d's accumulation on the in-order
queue and one radiance buffer serves.

``shadow_list`` (``device_shadow_list``: on a GPU) replaces every level's shadow launch with
one after the last level (``kernels/render_shadow_list.cl``): the shading lists its shadow rays
(render.shade), a ray with no room spills to its level's own launch (render.shadow, returning
at once when none did), and the list's launch (render.shadow) adds each traced ray's light to
its pixel in fixed point, which the tonemap pass adds to the framebuffer:

    render.raygen (which zeroes the chunk's pixels' shadow light)
    per depth: trace, shade (and list), spill, scan, gather
    render.shadow (the list), tonemap

``coop_from`` D (None: off; ``device_coop_from``: 2 on a GPU) lets the trace and shadow rays
of the levels from D on be traversed one per work-group of 32 (``kernels/traverse_coop.h``,
the ``*_coop`` kernels of a ``TRACE_COOP=1`` build, about one group per ray): a tail level of
few rays is latency-bound, its launch about one ray's chain of ~200-300 dependent node reads
(0.16 ms for 884 rays on the H200), and 32 work-items popping 32 nodes a round shorten that
chain. With many rays a work-item per ray is faster (the pool's 36k depth-2 rays: 2x), so a
level takes the cooperative kernel only while its last ray count is at most ``COOP_MAX_RAYS``, and
that kernel goes one ray per work-item if the device-side count is above it. Both walks give
the same hit, ties included (of two triangles at one distance, the smaller instance and
triangle ids: kernels/traverse.h ``trace_tie_wins``), so the choice never shows in the image.

``cost_bins`` (``device_cost_bins``: on a GPU) sends the shadow rays of the levels from depth 1
with at least ``BIN_MIN_RAYS`` rays by the last counts through the ``*_binned`` kernels
(``kernels/render_bins.h``): each work-group of ``BIN_WG`` takes its rays grouped by cost class,
so a warp's lanes do alike work (a water hit's refraction crosses the surface, its reflection
mostly meets the sky); the same image.

Five launches per depth level (four with ``fuse_trace_shade``: render.trace then includes
the shading), either order. Every kernel (``kernels.launch.Kernel``) belongs to this renderer
(one per depth level; the tonemap pass and the scatter alone have their own gather objects) and
its arguments are bound by name when the scene's buffers change; per-launch values are the
by-value RaygenParams/GatherParams records.
The frame's launches are a plan (kernel, sizes, stage; binds between them where several chunks
need them) made once per launch sizes, depth, lights, order and bindings, and replayed each frame
as bare enqueues. Per-ray kernels loop with a grid stride over the device-side count and are
launched for about the last arrived count (``size_hints``) rather than every slot: any size
gives the same image.

Reads: :meth:`Renderer.enqueue_read_rgba` / :meth:`Renderer.enqueue_read_stats` copy into pinned
host memory without a wait (``kernels.pinned``); ``read_*`` synchronise (tests, tools).
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pyopencl as cl

from kernels.launch import Kernel
from kernels.limits import check_fits
from kernels.pinned import PinnedRing, ReadHandle
from kernels.runtime import Runtime
from raytrace.bvh import HIT_DTYPE
from raytrace.caustics import CAUSTIC_PARAMS
from raytrace.light_buffer import MAX_CELLS as MAX_LIGHT_BUFFER_CELLS
from raytrace.light_buffer import LightBuffer
from raytrace.query import COOP_MAX_GROUPS, COOP_MAX_RAYS, COOP_WIDTH
from raytrace.render_scene import RenderScene
from raytrace.render_types import (
    AOV,
    CAMERA,
    GATHER_FINISH_SHADOW_LIST,
    GATHER_PARAMS,
    MASK_OPAQUE,
    MAX_DEPTH,
    RAY,
    RAYGEN_PARAMS,
    RENDERPARAMS,
    SCAN_BLOCK,
    SCAN_WG,
    SHADOW_LIST_PARAMS,
    SHADOW_RAY,
    STAT_DROPPED,
    STAT_SHADOW_LISTED,
    STAT_SHADOW_SPILLED,
    STATS_LEN,
    TILE,
    FresnelMode,
    PixelOrder,
    SamplePattern,
    SkyKind,
    Tonemap,
)

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
    size_hints: bool = True       #: size each level's launches from the last counts read back
                                  #: (any size is correct: the image never depends on it)
    local_size: int = 64          #: work-group size of the per-ray and per-pixel stages
    fuse_trace_shade: bool = False  #: one kernel traces and shades (render.trace includes shade)
    overlap_levels: bool = True   #: shadow rays of level d and trace of d + 1 in one launch
                                  #: (render.shadow_trace; the same image, one hit buffer more)
    overlap_from: int = 1         #: with overlap_levels, the first level d whose shadow rays
                                  #: go with level d + 1's trace (the levels before: alone;
                                  #: level 0's 2M shadow rays with level 1's trace were slower
                                  #: on the H200 than apart: BENCHMARKS.md)
    coop_from: int | None = None  #: the first level d whose trace and shadow rays may be
                                  #: traversed one per work-group of 32 while few (at most
                                  #: COOP_MAX_RAYS; kernels/traverse_coop.h); None: never
    cost_bins: bool = False       #: the shadow launches of levels of many rays hand each
                                  #: work-group's rays to its work-items grouped by cost
                                  #: (kernels/render_bins.h: whole warps of shadow rays that
                                  #: cross the water); the same image
    direct_crossings: bool = True  #: a shadow ray's crossings of the scene's one instance
                                   #: holding dielectrics (the water) walk it alone, with no
                                   #: TLAS walk (RenderScene.crossing_instance); the same image
    one_crossing: bool = True     #: where that instance is the height field and the shadow
                                  #: ray climbs faster than its slopes, the crossings end
                                  #: after the first (none from over the surface): the walks
                                  #: that can find nothing are left out; the same image
    light_buffer: int = 0         #: cells along the longer side of each directional light's
                                  #: map of the opaque triangles' shadows (raytrace.light_buffer:
                                  #: the shadow rays' any-hit query without a BVH walk, the
                                  #: same image); 0: none
    shadow_list: bool = False     #: every level's shadow rays written by the shading to one
                                  #: list and traced in one launch after the last level
                                  #: (kernels/render_shadow_list.cl); no per-level shadow
                                  #: launches, so overlap_levels, cost_bins and fuse_trace_shade
                                  #: have no effect. The image differs from the per-level
                                  #: stage's by float rounding only
    shadow_list_room: float = 0.5  #: the list's entries per ray slot (and an eighth more for
                                   #: rays in full light-buffer cells); a ray with no room is
                                   #: spilled: traced by its level's own launch (the same image)

    @property
    def overlaps(self) -> bool:
        """Whether level d's shadow rays go with level d + 1's trace (``overlap_levels``, no
        ``shadow_list``)."""
        return self.overlap_levels and not self.shadow_list

    @property
    def fuses(self) -> bool:
        """Whether one kernel traces and shades (``fuse_trace_shade``, no ``shadow_list``)."""
        return self.fuse_trace_shade and not self.shadow_list

    def resolved(self) -> RenderSettings:
        """Validated copy with the sample pattern decided; one-line ValueErrors."""
        for name, lo, hi in (("width", 1, 16384), ("height", 1, 16384), ("spp", 1, 4096),
                             ("bounces", 0, MAX_DEPTH), ("overlap_from", 0, MAX_DEPTH)):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or not lo <= v <= hi:
                raise ValueError(f"render {name} must be an integer in [{lo}, {hi}], got {v!r}")
        c = self.coop_from
        if c is not None and (not isinstance(c, int | np.integer) or not 0 <= c <= MAX_DEPTH):
            raise ValueError(f"render coop_from must be None or an integer in [0, {MAX_DEPTH}], "
                             f"got {c!r}")
        if not (math.isfinite(self.exposure) and self.exposure > 0):
            raise ValueError(f"render exposure must be > 0, got {self.exposure}")
        if not 0 <= self.min_weight < 1:
            raise ValueError(f"render min_weight must lie in [0, 1), got {self.min_weight}")
        if self.local_size not in (32, 64, 128, 256, 512):
            raise ValueError(f"local_size must be 32, 64, 128, 256 or 512, got {self.local_size}")
        if not 1.0 <= self.capacity_factor <= 64:
            raise ValueError(f"capacity_factor must lie in [1, 64], got {self.capacity_factor}")
        if not (math.isfinite(self.shadow_list_room) and 0 <= self.shadow_list_room <= 8):
            raise ValueError(f"render shadow_list_room must lie in [0, 8], got "
                             f"{self.shadow_list_room}")
        lb = self.light_buffer
        if not isinstance(lb, int | np.integer) or not 0 <= lb <= MAX_LIGHT_BUFFER_CELLS:
            raise ValueError(f"render light_buffer must be an integer in "
                             f"[0, {MAX_LIGHT_BUFFER_CELLS}], got {lb!r}")
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


def bytes_per_ray_slot(settings: RenderSettings) -> int:
    """:data:`BYTES_PER_RAY_SLOT` plus, with ``overlap_levels``, a second hit record (two levels'
    hits live at once) and, with ``fuse_trace_shade`` too, a second radiance; with
    ``shadow_list``, the list's entries instead."""
    s = settings
    if s.shadow_list:
        return BYTES_PER_RAY_SLOT + math.ceil(SHADOW_RAY.itemsize * s.shadow_list_room * 9 / 8)
    return BYTES_PER_RAY_SLOT + s.overlap_levels * (HIT_DTYPE.itemsize + 16 * s.fuse_trace_shade)


def shadow_list_rooms(settings: RenderSettings, capacity: int) -> tuple[int, int]:
    """The shadow list's main and full parts, in entries, for ``capacity`` ray slots."""
    main = int(capacity * settings.shadow_list_room)
    return main, main // 8


#: ``coop_from`` on a GPU (binary BVH layout): depth 2, so that the launch of level 1's ~1M
#: shadow rays (a work-item each) with a depth 2 of few rays takes the cooperative kernel too
#: (0.852 against 0.867 ms on the H200; BENCHMARKS.md, "third session").
GPU_COOP_FROM = 2


def device_coop_from(rt: Runtime) -> int | None:
    """The ``coop_from`` a frame uses on ``rt``'s device: :data:`GPU_COOP_FROM` on a GPU with the
    binary BVH layout; None elsewhere (a CPU runs one work-item per core: a 32-wide group
    would trace each ray 32 times over)."""
    return GPU_COOP_FROM if rt.is_gpu and rt.bvh_layout == "binary" else None


#: Fewest work-items a level's per-ray launches take when the last counts size them: a count
#: that jumps past it in one frame (a camera cut) costs that frame a few grid-stride rounds,
#: and the tail levels' launches of a few hundred rays cost a bare launch (1/8 of the slots, the
#: floor before, was 1M work-items at 1080p: 0.01-0.03 ms a launch on the H200).
LAUNCH_FLOOR = 1 << 16

#: Most work-items of a render_shadow_spill launch (a grid stride covers the level's rays): it
#: returns at once when nothing spilled, as a rule. 8192 or 2048 saved 0.003 ms of the five
#: empty launches' 0.024 on an H100 (BENCHMARKS.md, fifteenth session), and would leave a
#: frame whose list overflows 8-32 times the rounds over a level's million rays: kept at the floor.
SPILL_WORK_ITEMS = LAUNCH_FLOOR

#: Work-items per work-group of the binned shadow kernels (kernels/render_bins.h RENDER_BIN_WG).
BIN_WG = 256
#: With ``cost_bins``, the levels from depth 1 whose shadow rays are binned: those whose last
#: count is at least this (about one wave of the H200's 132 x 2048 work-items), or all when no
#: count has arrived. On the H200 the baseline scene's level 1 (958k shadow rays, half of them
#: crossing the water) took 0.62 instead of 0.89 ms binned, while level 0 (2M hits of one kind)
#: and the tail levels of 4k-50k rays were 5-15% slower binned (BENCHMARKS.md, 2026-12-02). The
#: secondary trace binned the same way (refracted rays apart from reflected) was 3-6% slower.
BIN_MIN_RAYS = 1 << 18


def device_cost_bins(rt: Runtime) -> bool:
    """``cost_bins`` on ``rt``'s device: on a GPU, whose warps run as long as their costliest
    lane; off on a CPU (a work-item per core: nothing to regroup)."""
    return bool(rt.is_gpu)


#: ``light_buffer`` on a GPU: cells along a map's longer side.
GPU_LIGHT_BUFFER = 1024


def device_shadow_list(rt: Runtime) -> bool:
    """``shadow_list`` on ``rt``'s device: on a GPU, where every level's shadow rays in one
    launch took the baseline frame from 2.04 to 1.92-1.94 kernel ms on the H200; off on a
    CPU, where PoCL's frames took the same either way (BENCHMARKS.md, fourteenth session)."""
    return bool(rt.is_gpu)


def device_light_buffer(rt: Runtime) -> int:
    """``light_buffer`` on ``rt``'s device: :data:`GPU_LIGHT_BUFFER` cells on a GPU; none on a
    CPU, where the map's build every frame costs what a floating boat's scene gains (PoCL, 2
    cores, 480x270: the pool 180.6 against 178.1 ms a frame with 256 cells; a still scene 104.9
    against 108.8: BENCHMARKS.md, ninth session)."""
    return GPU_LIGHT_BUFFER if rt.is_gpu else 0


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
        self.settings = s = settings.resolved()
        order = PixelOrder.from_str(s.order)
        self.n_pixels = s.width * s.height
        self.n_q = (self.n_pixels if order == PixelOrder.ROWS
                    else -(-s.width // TILE) * -(-s.height // TILE) * TILE * TILE)
        # chunk of pixels whose ray buffers fit in the memory budget
        budget = s.memory_fraction * rt.device.global_mem_size
        max_alloc = rt.device.max_mem_alloc_size
        slot_limit = min(budget / bytes_per_ray_slot(s), max_alloc / RAY.itemsize)
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
        self._check_fits(s)  # kernels.limits
        self.rays = [rt.buffer(cap * RAY.itemsize), rt.buffer(cap * RAY.itemsize)]
        # the hits and radiance of the levels of each parity (one buffer for both unless two
        # levels' are live at once: _level_buffers)
        self.hits = [rt.buffer(cap * HIT_DTYPE.itemsize)] * 2
        self.radiance = [rt.buffer(cap * 16)] * 2
        self._level_buffers()
        self.child = rt.buffer(cap * 4)
        self.block_sums = rt.buffer(4 * -(-cap // SCAN_BLOCK))
        self.counts = rt.buffer(4 * (MAX_DEPTH + 2))
        self.stats = rt.buffer(4 * STATS_LEN)
        self._stats_reads = PinnedRing(rt, 4 * STATS_LEN, np.uint32, (STATS_LEN,), slots=4)
        self._rgba_reads = PinnedRing(rt, 4 * self.n_pixels, np.uint8, (s.height, s.width, 4))
        self._stats_handle: ReadHandle | None = None  # the last frame's counts (size hints)
        self._levels = s.bounces
        self.framebuffer = rt.buffer(16 * self.n_pixels)
        self.rgba = rt.buffer(4 * self.n_pixels)
        self.aov = rt.buffer(AOV.itemsize * (self.n_pixels if s.aov else 1))
        self.camera_buf = rt.buffer(CAMERA.itemsize)
        self.params_buf = rt.buffer(RENDERPARAMS.itemsize)
        self._camera = None
        self.ticket = rt.to_device(np.zeros(1, np.uint32))  # render_scan's last-block ticket
        # the caustic map render_shadow reads under the water (raytrace.caustics); off until set
        self.caustic_map = rt.buffer(16)
        self.caustic_params = np.zeros(1, CAUSTIC_PARAMS)[0]
        # the directional lights' maps of what blocks them (raytrace.light_buffer)
        self.light_buffer = LightBuffer(rt, s.light_buffer)
        # the shadow list (shadow_list): its counts (full part, main part, spilled), its
        # entries, and each pixel's fixed-point light (render_shadow_list.h); made when on
        self.list_counts = rt.to_device(np.zeros(4, np.uint32))
        self.shadow_list = self.shadow_light = None
        self.k_shadow_list: Kernel | None = None
        self._shadow_list_buffers()
        self._listed_hint: int | None = None  # shadow rays listed in the last frame that arrived
        # this renderer's own kernels: raygen, and per depth level trace/shade/scan/gather
        self.k_raygen = rt.kernel_launcher("render_raygen.cl", "render_raygen",
                                           stage="render.raygen")
        self._k: list[dict[str, Kernel]] = []
        self._bound_sig: tuple | None = None  # the buffers the kernels were bound to
        self._bind_version = 0                # counts rebinds (the launch plans' key)
        self._caustic_bound: tuple | None = None  # caustics bound to the shadow kernels
        self._plans: dict = {}                # launch plans by what they depend on
        self._last_ops: list | None = None    # the plan of the last frame
        self._uploaded: tuple = (None, None)  # camera and params bytes on the device
        self._params_key = self._params_rec = None
        ls = s.local_size

        self._stage_per_depth = False  # set_stage_per_depth: stages named per depth level
        self._last_hint: tuple | None = None  # rays per depth of the last frame that arrived
        self._sizes: dict = {}

        def rnd(n: int) -> int:
            return -(-int(n) // ls) * ls

        # per chunk: q0, n_q, primary rays, raygen size, and per depth level the ray slots that
        # can be in use (work-items of trace/shade/shadow, rounded to the work-group size), the
        # scan size (work-groups x SCAN_WG) and the pixels (rounded)
        self._plan = []
        for q0, nq in self.chunks:
            n_rays = nq * s.spp
            depths, launch_n = [], n_rays
            for _ in range(s.bounces + 1):
                blocks = max(1, -(-launch_n // SCAN_BLOCK))
                depths.append((rnd(launch_n), (blocks * SCAN_WG,), rnd(nq)))
                launch_n = min(self.capacity, 2 * launch_n)
            raygen = np.array([(q0, n_rays, int(q0 == 0), 0)], RAYGEN_PARAMS)[0]
            # the GatherParams (scatter, accumulate, q0, n_q, finish) of a level that scatters
            # and accumulates, of an accumulation alone (the last level; overlap_levels: every
            # level, after its shadow rays), of the tonemap pass, and of a scatter alone
            # (and of the tonemap pass that adds the shadow list's light first)
            gather = tuple(np.array([(sc, acc, q0, nq, fin)], GATHER_PARAMS)[0]
                           for sc, acc, fin in ((1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 0),
                                                (0, 0, GATHER_FINISH_SHADOW_LIST)))
            self._plan.append((raygen, gather, (max(n_rays, STATS_LEN),), depths))

    def _launch_sizes(self, depths: list, hint: tuple | None) -> tuple:
        """Per depth level: (rays work-items, scan size, gather size over rays, tonemap size over
        the chunk's pixels). The per-ray kernels loop with a grid stride over the device-side count,
        so any size is correct; with the last frame's counts (one chunk) a level is launched
        for 5/4 of them (at least :data:`LAUNCH_FLOOR` work-items, or 1/8 of its slots if fewer)
        instead of all its slots, which are mostly empty past depth 0 (reflections and
        refractions double the slots, not the rays)."""
        key = (id(depths), hint)
        sizes = self._sizes.get(key)
        if sizes is None:
            ls = self.settings.local_size
            sizes = []
            for d, (slots, scan, pixels) in enumerate(depths):
                n = slots
                if d > 0 and hint is not None and d < len(hint):
                    want = max(hint[d] * 5 // 4 + ls, min(slots // 8, LAUNCH_FLOOR))
                    n = min(slots, -(-want // ls) * ls)
                sizes.append(((n,), scan, (n,), (pixels,)))
            if len(self._sizes) > 64:
                self._sizes.clear()
            sizes = self._sizes[key] = tuple(sizes)
        return sizes

    def _check_fits(self, s: RenderSettings) -> None:
        """One-line DeviceLimitError when the ray slots and per-pixel buffers do not fit."""
        check_fits(self.rt, self.capacity * bytes_per_ray_slot(s)
                   + self.n_pixels * (20 + s.aov * AOV.itemsize) + s.shadow_list * 24 * self.n_q,
                   f"render {s.width}x{s.height}", largest=16 * self.n_pixels)

    def _shadow_list_buffers(self) -> None:
        """With ``shadow_list``, the list (its main part, then the part for full light-buffer
        cells) and 24 bytes of fixed-point light per tile-order pixel (render_raygen zeroes a
        chunk's); without, a pixel's worth that the gather and raygen kernels bind."""
        s, rt = self.settings, self.rt
        if not s.shadow_list:
            if self.shadow_light is None:
                self.shadow_light = rt.to_device(np.zeros(3, np.uint64))
            return
        main, full = shadow_list_rooms(s, self.capacity)
        self.list_params = np.array([(main, full, 0, 0)], SHADOW_LIST_PARAMS)[0]
        if self.shadow_list is None or self.shadow_list.size < (main + full) * SHADOW_RAY.itemsize:
            self.shadow_list = rt.buffer(max(1, main + full) * SHADOW_RAY.itemsize)
        if self.shadow_light is None or self.shadow_light.size < 24 * self.n_q:
            self.shadow_light = rt.to_device(np.zeros(3 * self.n_q, np.uint64))
        self._bound_sig = None

    def set_shadow_list(self, on: bool, room: float | None = None) -> None:
        """Trace every level's shadow rays as one list (``shadow_list``) from the next frame
        on, with ``room`` entries per ray slot (None: keep ``shadow_list_room``); an A/B switch
        (bench frame --shadow-list). The image differs from the per-level stage's by float
        rounding only."""
        room = self.settings.shadow_list_room if room is None else room
        new = dataclasses.replace(self.settings, shadow_list=bool(on),
                                  shadow_list_room=room).resolved()
        if new == self.settings:
            return
        self._check_fits(new)
        self.settings = new
        self._shadow_list_buffers()
        self._level_buffers()
        self._bound_sig = None

    def _level_buffers(self) -> None:
        """With ``overlap_levels``, the odd levels' hits (and, fused, radiance) in buffers of
        their own: render.shadow_trace traces (and shades) level d + 1 while level d's shadow
        rays read its hits and add to its radiance, and the accumulation of level d reads that
        radiance after it. Unfused, render.shade of level d + 1 runs after that accumulation on
        the in-order queue, so one radiance buffer serves both parities."""
        s = self.settings
        if not s.overlaps:
            return
        cap = self.capacity
        if self.hits[1] is self.hits[0]:
            self.hits = [self.hits[0], self.rt.buffer(cap * HIT_DTYPE.itemsize)]
        if s.fuse_trace_shade and self.radiance[1] is self.radiance[0]:
            self.radiance = [self.radiance[0], self.rt.buffer(cap * 16)]

    def set_overlap(self, on: bool = True, first: int | None = None) -> None:
        """Turn ``overlap_levels`` on or off for the next frames, overlapping from level
        ``first`` (None: keep ``overlap_from``); an A/B switch (bench frame --no-overlap,
        --overlap-from). On after a renderer made without it allocates the second hit buffer
        (and radiance, fused) then; the image is the same either way."""
        first = self.settings.overlap_from if first is None else first
        new = dataclasses.replace(self.settings, overlap_levels=bool(on), overlap_from=first)
        new = new.resolved()   # one-line ValueError for a bad level
        if new == self.settings:
            return
        if new.overlap_levels and not self.settings.overlap_levels:
            self._check_fits(new)
        self.settings = new
        self._level_buffers()
        self._bound_sig = None  # rebind: the kernels of the new order, to these buffers

    def set_coop(self, first: int | None) -> None:
        """Let the trace and shadow rays of levels ``first`` and deeper go one per work-group
        while few (``coop_from``; None: none) from the next frame on; an A/B switch (bench
        frame --coop-from). The same image either way (the same hits, ties included)."""
        new = dataclasses.replace(self.settings, coop_from=first).resolved()
        if new == self.settings:
            return
        self.settings = new
        self._bound_sig = None  # rebind: the cooperative kernels of these levels

    def set_cost_bins(self, on: bool) -> None:
        """Group each work-group's shadow rays by cost (``cost_bins``) from the next frame on;
        an A/B switch (bench frame --cost-bins on|off). The same image either way."""
        new = dataclasses.replace(self.settings, cost_bins=bool(on))
        if new == self.settings:
            return
        self.settings = new
        self._bound_sig = None  # rebind: the binned kernels

    def set_direct_crossings(self, on: bool) -> None:
        """Walk the one dielectric instance alone for the shadow rays' crossings
        (``direct_crossings``) from the next frame on; an A/B switch (bench frame
        --direct-crossings on|off). The same image either way."""
        self.settings = dataclasses.replace(self.settings, direct_crossings=bool(on))

    def set_one_crossing(self, on: bool) -> None:
        """Leave out the crossing walks that can find nothing (``one_crossing``) from the next
        frame on; an A/B switch (bench frame --one-crossing on|off). The same image either
        way."""
        self.settings = dataclasses.replace(self.settings, one_crossing=bool(on))

    def set_stage_per_depth(self, on: bool = True) -> None:
        """Time each depth level's trace, shade, shadow, scan and gather under its own stage
        (``render.shadow.d3``), e.g. to see the tail levels of few rays (bench frame
        --per-depth); off: one stage per kind over all levels."""
        self._stage_per_depth = bool(on)
        for d, ks in enumerate(self._k):
            for k in ks.values():
                k.stage = self._stage_name(re.sub(r"\.d\d+$", "", k.stage), d)

    def _stage_name(self, stage: str, depth: int) -> str:
        return f"{stage}.d{depth}" if self._stage_per_depth else stage

    def _depth_kernels(self, depth: int) -> dict:
        rt = self.rt
        while len(self._k) <= depth:
            d = len(self._k)
            trace = "render.trace_secondary" if d else "render.trace"

            def launcher(source, name, stage, d=d):
                return rt.kernel_launcher(source, name, stage=self._stage_name(stage, d))

            ks = {
                "trace": launcher("render_trace.cl", "render_trace", trace),
                "trace_shade": launcher("render_trace.cl", "render_trace_shade", trace),
                "shade": launcher("render_shade.cl", "render_shade", "render.shade"),
                "shadow": launcher("render_shade.cl", "render_shadow", "render.shadow"),
                "scan": launcher("render_secondary.cl", "render_scan", "render.secondary"),
                "gather": launcher("render_frame.cl", "render_gather", "render.gather"),
                # the same kernel for the tonemap pass after the last level: its own object,
                # so neither changes arguments between frames
                "finish": launcher("render_frame.cl", "render_gather", "render.gather"),
                # the scatter half of gather when the accumulation runs apart (overlap_levels)
                "scatter": launcher("render_frame.cl", "render_gather", "render.gather")}
            self._k.append(ks)
            self._bound_sig = None
        s = self.settings
        if s.shadow_list:   # the shading that writes the list, the launch that traces it
            for d, ks in enumerate(self._k):
                if "shade_list" not in ks:
                    ks["shade_list"] = rt.kernel_launcher(
                        "render_shadow_list.cl", "render_shade_list",
                        stage=self._stage_name("render.shade", d))
                    ks["shadow_spill"] = rt.kernel_launcher(
                        "render_shadow_list.cl", "render_shadow_spill",
                        stage=self._stage_name("render.shadow", d))
                    self._bound_sig = None
            if self.k_shadow_list is None:
                self.k_shadow_list = rt.kernel_launcher(
                    "render_shadow_list.cl", "render_shadow_list", stage="render.shadow")
                self._bound_sig = None
        if s.overlaps:   # level d's shadow rays with level d + 1's trace
            for d, ks in enumerate(self._k[1:], 1):
                if "shadow_trace" not in ks:
                    ks["shadow_trace"] = rt.kernel_launcher(
                        "render_shadow_trace.cl", "render_shadow_trace",
                        stage=self._stage_name("render.shadow_trace", d))
                    ks["shadow_trace_shade"] = rt.kernel_launcher(
                        "render_shadow_trace.cl", "render_shadow_trace_shade",
                        stage=self._stage_name("render.shadow_trace", d))
                    self._bound_sig = None
        if s.cost_bins:   # the shadow launches with their rays grouped by cost
            for d, ks in enumerate(self._k):
                self._add_flavour(ks, d, "_binned", self._SHADOW)
        if s.coop_from is not None:   # the cooperative flavours of the levels from coop_from
            # on a CPU the serial walk per work-item (kernels/traverse_coop.h TRACE_COOP_SERIAL:
            # PoCL compiles the walk inside these kernels for minutes; the hits are the same)
            coop = {"TRACE_COOP": 1, "TRACE_COOP_SERIAL": int(not rt.is_gpu)}
            for d, ks in enumerate(self._k[s.coop_from:], s.coop_from):
                self._add_flavour(ks, d, "_coop", self._TRACE + self._SHADOW, coop)
        return self._k[depth]

    #: Kernels (key, source, name) that come in flavours (``*_coop``, ``*_binned``) with the
    #: plain kernel's arguments: the traces, the shadow rays, and from depth 1 with
    #: overlap_levels the combined shadow + trace launches.
    _TRACE = (("trace", "render_trace.cl", "render_trace"),
              ("trace_shade", "render_trace.cl", "render_trace_shade"))
    _SHADOW = (("shadow", "render_shade.cl", "render_shadow"),)
    _SHADOW_TRACE = (("shadow_trace", "render_shadow_trace.cl", "render_shadow_trace"),
                     ("shadow_trace_shade", "render_shadow_trace.cl",
                      "render_shadow_trace_shade"))

    def _add_flavour(self, ks: dict, d: int, suffix: str, kernels: tuple,
                     defines: dict | None = None) -> None:
        """Level ``d``'s ``suffix`` flavour of ``kernels`` (and of the combined launches where
        the level has them) in ``ks``, made once, timed under the plain kernel's stage."""
        if d > 0 and self.settings.overlaps:
            kernels = kernels + self._SHADOW_TRACE
        for key, source, name in kernels:
            if key + suffix not in ks:
                ks[key + suffix] = self.rt.kernel_launcher(
                    source, name + suffix, stage=ks[key].stage, defines=defines)
                self._bound_sig = None

    def _bind(self, levels: int) -> None:
        """Bind every kernel's arguments by name when the scene's buffers changed (a rebuild,
        new tables) or a deeper level is needed; per-launch values are bound each frame as
        GatherParams/RaygenParams records (set only when their bytes change)."""
        if self.scene.scene.layout != self.rt.bvh_layout:
            raise ValueError(f"the scene's BVH layout is {self.scene.scene.layout!r} but the "
                             f"renderer's kernels were built for {self.rt.bvh_layout!r}")
        scene = self.scene.scene.trace_bindings()
        geom = self.scene.shade_bindings()
        lbuf = self.light_buffer.bindings()
        bufs = (*scene.values(), *geom.values(), self.scene.light_buf, *lbuf.values(),
                self.shadow_list, self.shadow_light)
        self._depth_kernels(levels)
        old = self._bound_sig
        if old is not None and len(old) == len(bufs) and all(
                a is b for a, b in zip(old, bufs, strict=True)):
            return
        s = self.settings
        self.k_raygen.bind(cam=self.camera_buf, rays=self.rays[0], counts=self.counts,
                           stats=self.stats, list_counts=self.list_counts,
                           shadow_light=self.shadow_light)
        shading = {**geom, "prm": self.params_buf}
        listing = {}
        if s.shadow_list:
            listing = {"shadow_list": self.shadow_list, "list_counts": self.list_counts,
                       "lp": self.list_params, "shadow_light": self.shadow_light}
            self.k_shadow_list.bind(**scene, **shading, **lbuf, **listing, stats=self.stats,
                                    lights=self.scene.light_buf)
        for d, k in enumerate(self._k):
            wave = {"rays": self.rays[d % 2], "counts": self.counts, "depth": d}
            hits, radiance = self.hits[d % 2], self.radiance[d % 2]
            k["trace"].bind(**scene, **wave, hits=hits)
            out = {"radiance": radiance, "child_counts": self.child, "aov": self.aov,
                   "write_aov": int(s.aov)}
            k["shade"].bind(**shading, cam=self.camera_buf, **wave, hits=hits, **out)
            k["trace_shade"].bind(**scene, **shading, cam=self.camera_buf, **wave,
                                  hits=hits, **out)
            light = {"lights": self.scene.light_buf, "caustic_map": self.caustic_map,
                     "cprm": self.caustic_params, **lbuf}
            if "shade_list" in k and s.shadow_list:
                k["shade_list"].bind(**scene, **shading, cam=self.camera_buf, **wave, hits=hits,
                                     **out, **light, **listing)
                k["shadow_spill"].bind(**scene, **shading, lights=self.scene.light_buf,
                                       cprm=self.caustic_params, **lbuf, **wave, hits=hits,
                                       radiance=radiance, list_counts=self.list_counts,
                                       shadow_light=self.shadow_light)
            for f in ("", "_binned"):   # the binned flavour: the plain kernel's arguments
                if "shadow" + f in k:
                    k["shadow" + f].bind(**scene, **shading, **light, **wave, hits=hits,
                                         radiance=radiance)
            if "shadow_trace" in k:   # level d - 1's shadow rays, level d's trace (and shade)
                last = {"shadow_rays": self.rays[(d - 1) % 2],
                        "shadow_hits": self.hits[(d - 1) % 2],
                        "shadow_radiance": self.radiance[(d - 1) % 2]}
                for f in ("", "_binned"):
                    if "shadow_trace" + f in k:
                        k["shadow_trace" + f].bind(**scene, **shading, **light, **last, **wave,
                                                   hits=hits)
                        k["shadow_trace_shade" + f].bind(**scene, **shading, **light, **last,
                                                         cam=self.camera_buf, **wave,
                                                         hits=hits, **out)
            if "trace_coop" in k:   # the cooperative flavours: the same arguments
                k["trace_coop"].bind(**scene, **wave, hits=hits)
                k["trace_shade_coop"].bind(**scene, **shading, cam=self.camera_buf, **wave,
                                           hits=hits, **out)
                k["shadow_coop"].bind(**scene, **shading, **light, **wave, hits=hits,
                                      radiance=radiance)
            if "shadow_trace_coop" in k:
                both = int(s.coop_from is not None and d - 1 >= s.coop_from)
                k["shadow_trace_coop"].bind(**scene, **shading, **light, **last, **wave,
                                            hits=hits, coop_shadow=both)
                k["shadow_trace_shade_coop"].bind(**scene, **shading, **light, **last,
                                                  cam=self.camera_buf, **wave, hits=hits,
                                                  **out, coop_shadow=both)
            k["scan"].bind(child_counts=self.child, counts=self.counts, depth=d,
                           capacity=self.capacity, block_sums=self.block_sums,
                           ticket=self.ticket, stats=self.stats)
            for g in (k["gather"], k["finish"], k["scatter"]):
                g.bind(**shading, cam=self.camera_buf, **wave, hits=hits,
                       child_offsets=self.child, block_sums=self.block_sums,
                       out=self.rays[(d + 1) % 2], radiance=radiance,
                       fb=self.framebuffer, rgba=self.rgba, shadow_light=self.shadow_light)
        self._bound_sig = bufs
        self._bind_version += 1

    # -- inputs -----------------------------------------------------------------------------
    def set_caustics(self, caustic_map: cl.Buffer | None, params=None) -> None:
        """Read direct light under the water from ``caustic_map`` (a float4 irradiance atlas
        made by :class:`raytrace.caustics.Caustics`, described by its CausticParams record);
        None turns it off (shadow rays through the water, as before)."""
        if caustic_map is None:
            self.caustic_params = np.zeros(1, CAUSTIC_PARAMS)[0]
            return
        self.caustic_map = caustic_map
        self.caustic_params = np.asarray(params, CAUSTIC_PARAMS).reshape(()).copy()

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
        p["crossing_instance"] = sc.crossing_instance if s.direct_crossings else -1
        p["one_crossing"] = int(s.one_crossing)
        p["tonemap"] = int(Tonemap.from_str(s.tonemap))
        p["max_depth"] = s.bounces
        p["capacity"] = self.capacity
        # the cut-off is a share of the pixel: a ray of weight w stands for w * spp of a sample
        p["min_weight"] = s.min_weight / s.spp
        return p

    # -- the frame ----------------------------------------------------------------------------
    def enqueue_frame(self, *, update_scene: bool = True, read_stats: bool = True) -> None:
        """Queue one frame (scene update, all chunks, tonemap) and, with ``read_stats``, the
        read of its ray counts (:attr:`stats_handle`). No host sync.

        Every depth level up to ``bounces`` is launched whatever the last frame needed, so a
        frame's picture depends only on the scene and camera (per-ray kernels grid-stride over
        the device-side count: an empty level costs a few bare launches). The last frame's ray
        counts, when they have arrived, only size the launches."""
        s = self.settings
        if update_scene:
            self.scene.update()
        self._upload_inputs()
        # no material reflects or refracts: no secondary wavefront can exist, launch none
        deepest = s.bounces if self.scene.has_secondary else 0
        self._levels = deepest
        self.light_buffer.plan(self.scene, self.any_hit_mask)
        self._bind(deepest)
        self._bind_caustics()
        self.light_buffer.enqueue(self.scene.transform_buffer, self.scene.scene.rows_version)
        hint = self._count_hint() if len(self._plan) == 1 and s.size_hints else None
        sizes = tuple(self._launch_sizes(depths, hint) for *_, depths in self._plan)
        # levels of few rays by the last counts: their trace and shadow rays one per work-group,
        # about that many groups (the count's next power of two: the plan stays while it holds)
        few = tuple(None if hint is None or d >= len(hint) or s.coop_from is None
                    or d < s.coop_from or hint[d] > COOP_MAX_RAYS
                    else 1 << max(0, int(hint[d]) - 1).bit_length()
                    for d in range(deepest + 1))
        # levels of many rays by the last counts (all from depth 1 with none): their shadow
        # rays grouped by cost in each work-group (cost_bins)
        bins = tuple(s.cost_bins and d >= 1 and (hint is None or d >= len(hint)
                                                 or hint[d] >= BIN_MIN_RAYS)
                     for d in range(deepest + 1))
        list_size = self._list_size() if s.shadow_list else None
        key = (sizes, deepest, len(self.scene.lights) > 0, self._stage_per_depth,
               s.overlap_levels, s.overlap_from, few, bins, self._bind_version, s.shadow_list,
               list_size, len(self.scene.lights) if s.shadow_list else 0)
        ops = self._plans.get(key)
        if ops is None:
            if len(self._plans) >= 16:
                self._plans.clear()
            ops = self._plans[key] = self._make_plan(sizes, deepest, key[2], few, bins,
                                                     list_size)
        self._run(ops, rebind=len(self._plan) > 1 or ops is not self._last_ops)
        self._last_ops = ops
        if read_stats:
            self.use_stats_handle(self.enqueue_read_stats())

    def _list_size(self) -> tuple:
        """render_shadow_list's work-items: 5/4 of the rays the last frame that arrived listed
        (at least :data:`LAUNCH_FLOOR`), else the list's room (any size is correct)."""
        ls = self.settings.local_size
        room = int(self.list_params["main_room"]) + int(self.list_params["full_room"])
        n = room
        if self._listed_hint is not None and len(self._plan) == 1 and self.settings.size_hints:
            n = min(room, max(self._listed_hint * 5 // 4 + ls, LAUNCH_FLOOR))
        return (max(ls, -(-n // ls) * ls),)

    def use_stats_handle(self, handle: ReadHandle) -> None:
        """Size the next frames' launches from the ray counts ``handle`` reads (after a frame
        queued with ``read_stats=False``, whose caller queued that read)."""
        old = self._stats_handle
        if old is not None:  # its event waits for the read when released: kept until done
            self.rt.keep(old.event)
        self._stats_handle = handle

    #: Plan steps: a launch (cl kernel, global size, local size, stage), arguments to bind
    #: (Kernel, {name: value}; with one chunk only when the plan changes), and a flush.
    _LAUNCH, _BIND, _FLUSH = 0, 1, 2

    def _make_plan(self, sizes: tuple, deepest: int, has_lights: bool, few: tuple,
                   bins: tuple, list_size: tuple | None = None) -> list:
        """The frame's launches in order, sizes and arguments decided: what the per-frame loop
        did, made once per (sizes, depth, lights, stage names, levels of few rays, binned
        levels, bindings, shadow list). ``few[d]``: where level d's rays go one per work-group,
        the power of two at or above its last ray count (its work-groups), else None;
        ``bins[d]``: level d's shadow rays go through the binned kernels; ``list_size``: with
        ``shadow_list``, render_shadow_list's work-items."""
        s, ks = self.settings, self._k
        ls, scan_ls = (s.local_size,), (SCAN_WG,)
        ops = []

        def launch(k: Kernel, gs: tuple, lsz: tuple | None) -> None:
            if k._unbound:
                k._check_bound()
            ops.append((self._LAUNCH, k.kernel, gs, lsz, k.stage))

        def bind(k: Kernel, **values) -> None:  # now too, so that launch() can check
            k.bind(**values)
            ops.append((self._BIND, k, values))

        trace = "trace_shade" if s.fuses else "trace"

        def overlapped(d: int) -> bool:   # level d's shadow rays go with level d + 1's trace
            return s.overlaps and s.overlap_from <= d < deepest

        def coop(d: int) -> bool:   # level d's rays go one per work-group (the hits are the
            return few[d] is not None   # same either way)

        def coop_size(d: int, size: int) -> int:   # work-items for level d: a work-group per
            if coop(d):                            # ray (the kernel checks the device count)
                return COOP_WIDTH * min(few[d], COOP_MAX_GROUPS)
            return -(-size // COOP_WIDTH) * COOP_WIDTH   # else a work-item per ray

        def per_ray(k: dict, name: str, d: int, size: tuple) -> None:  # any flavour
            if coop(d):
                launch(k[name + "_coop"], (coop_size(d, size[0]),), (COOP_WIDTH,))
            elif bins[d] and name + "_binned" in k:
                launch(k[name + "_binned"], (-(-size[0] // BIN_WG) * BIN_WG,), (BIN_WG,))
            else:
                launch(k[name], size, ls)

        listed = s.shadow_list and has_lights
        for (rp, (g_both, g_accumulate, g_finish, g_scatter, g_finish_list), raygen_size, _), \
                sz in zip(self._plan, sizes, strict=True):
            if listed:   # each pixel's shadow-list light starts the frame at zero
                rp = rp.copy()
                rp["zero_light"] = 1
            bind(self.k_raygen, rp=rp)
            launch(self.k_raygen, raygen_size, None)
            if listed:   # the shading lists every level's shadow rays, one launch traces them
                spill_from = self._first_spill(rp["n_rays"])
                for depth in range(deepest + 1):
                    k = ks[depth]
                    ray_size, scan_size, scatter_size, pixel_size = sz[depth]
                    per_ray(k, "trace", depth, ray_size)
                    if depth == 0 and rp["zero_stats"]:
                        ops.append((self._FLUSH,))
                    launch(k["shade_list"], ray_size, ls)
                    # the rays with no room in the list, before this level's buffers go
                    if depth >= spill_from:
                        launch(k["shadow_spill"], (min(ray_size[0], SPILL_WORK_ITEMS),), ls)
                    if depth < deepest:
                        launch(k["scan"], scan_size, scan_ls)
                    bind(k["gather"], gp=g_both if depth < deepest else g_accumulate)
                    launch(k["gather"], scatter_size, ls)
                launch(self.k_shadow_list, list_size, ls)
                bind(ks[deepest]["finish"], gp=g_finish_list)
                launch(ks[deepest]["finish"], sz[deepest][3], ls)
                continue
            for depth in range(deepest + 1):
                k = ks[depth]
                ray_size, scan_size, scatter_size, pixel_size = sz[depth]
                if depth == 0 or not overlapped(depth - 1):  # else traced with the last
                    per_ray(k, trace, depth, ray_size)
                    if depth == 0 and rp["zero_stats"]:
                        ops.append((self._FLUSH,))  # the device starts while the rest is queued
                    if not s.fuses:
                        launch(k["shade"], ray_size, ls)
                if not overlapped(depth):
                    if has_lights:
                        per_ray(k, "shadow", depth, ray_size)
                    if depth < deepest:
                        launch(k["scan"], scan_size, scan_ls)
                        bind(k["gather"], gp=g_both)
                        launch(k["gather"], scatter_size, ls)
                    else:
                        bind(k["gather"], gp=g_accumulate)
                        launch(k["gather"], scatter_size, ls)
                        bind(k["finish"], gp=g_finish)
                        launch(k["finish"], pixel_size, ls)
                    continue
                # overlap_levels: scatter the children, then this level's shadow rays with the
                # next level's trace in one launch, then accumulate this level, shade the next
                nxt = ks[depth + 1]
                next_size = sz[depth + 1][0]
                launch(k["scan"], scan_size, scan_ls)
                bind(k["scatter"], gp=g_scatter)
                launch(k["scatter"], scatter_size, ls)
                if has_lights and coop(depth + 1) and coop(depth):
                    # a group per ray of level d + 1 and of level d's shadow rays, both few;
                    # not for many shadow rays beside few traces, which the cooperative kernel
                    # runs a work-item each slower than the plain one (on the H200 a tail
                    # level's 4231 with 884: 0.25 against 0.21 ms; the static scene's level 1,
                    # 958k beside 3404: 0.998 against 0.881). The shadow part runs first
                    launch(nxt["shadow_" + trace + "_coop"],
                           (max(coop_size(depth + 1, next_size[0]),
                                coop_size(depth, ray_size[0])),), (COOP_WIDTH,))
                elif has_lights:
                    both = ray_size[0] + next_size[0]
                    if bins[depth]:
                        launch(nxt["shadow_" + trace + "_binned"],
                               (-(-both // BIN_WG) * BIN_WG,), (BIN_WG,))
                    else:
                        launch(nxt["shadow_" + trace], (both,), ls)
                else:
                    per_ray(nxt, trace, depth + 1, next_size)
                bind(k["gather"], gp=g_accumulate)
                launch(k["gather"], scatter_size, ls)
                if not s.fuses:
                    launch(nxt["shade"], next_size, ls)
        return ops

    def _first_spill(self, n_rays: int) -> int:
        """The first level whose shadow rays can find the shadow list full: before it, the
        levels' rays (a level at most twice the last, at most the slots) times the lights fit in
        its main part (rays of full cells past their part go there too), so they need no
        render_shadow_spill launch."""
        main = int(self.list_params["main_room"])
        lights = len(self.scene.lights)
        total, n = 0, n_rays
        for depth in range(self.settings.bounces + 1):
            total += lights * n
            if total > main:
                return depth
            n = min(self.capacity, 2 * n)
        return self.settings.bounces + 1

    def _run(self, ops: list, rebind: bool) -> None:
        """Enqueue a plan: each launch one bare enqueue, its event recorded under its stage."""
        q, enqueue, record = self.rt.queue, cl.enqueue_nd_range_kernel, self.rt.timer.record
        launch, bind = self._LAUNCH, self._BIND
        for op in ops:
            kind = op[0]
            if kind == launch:
                record(op[4], enqueue(q, op[1], op[2], op[3]))
            elif kind == bind:
                if rebind:
                    op[1].bind(**op[2])
            else:
                q.flush()

    def _bind_caustics(self) -> None:
        """Bind the caustic map and its record to every level's shadow kernel when they (or the
        kernels' bindings) changed."""
        cmap, cprm = self.caustic_map, self.caustic_params.tobytes()
        old = self._caustic_bound
        if old is not None and old[0] is cmap and old[1] == cprm and \
                old[2] == self._bind_version:
            return
        for k in self._k:
            if "shadow_spill" in k:
                k["shadow_spill"].bind(cprm=self.caustic_params)
            for name in ("shade_list", "shadow", "shadow_trace", "shadow_trace_shade",
                         "shadow_coop", "shadow_trace_coop", "shadow_trace_shade_coop",
                         "shadow_binned", "shadow_trace_binned", "shadow_trace_shade_binned"):
                if name in k:
                    k[name].bind(caustic_map=cmap, cprm=self.caustic_params)
        self._caustic_bound = (cmap, cprm, self._bind_version)

    def _count_hint(self) -> tuple | None:
        """Rays per depth of the last frame whose counts have arrived (never waits)."""
        h = self._stats_handle
        if h is None or not h.ready():
            return self._last_hint
        st = h.array
        self._last_hint = tuple(st[: self.settings.bounces + 1].tolist()) if h.valid else None
        self._listed_hint = int(st[STAT_SHADOW_LISTED]) if h.valid else None
        return self._last_hint

    @property
    def any_hit_mask(self) -> int:
        """The instances a shadow ray's any-hit query sees (render_shadow.h): the opaque ones
        when the scene has a dielectric (its surfaces are crossed apart), else all."""
        return MASK_OPAQUE if self.scene.has_dielectric else 0xFFFFFFFF

    def _upload_inputs(self) -> None:
        """Copy the camera and the RenderParams record to the device when they changed."""
        cam = self.camera.tobytes()
        sc, s = self.scene, self.settings
        key = (sc.sky, tuple(sc.ambient), len(sc.lights), len(sc.materials),
               sc.crossing_instance, s.direct_crossings, s.one_crossing)
        if key != self._params_key:
            self._params_key, self._params_rec = key, np.array([self.params()])
        prm = self._params_rec.tobytes()
        old_cam, old_prm = self._uploaded
        q = self.rt.queue
        keep = self.rt.keep  # released at once, a copy's event would wait for the copy
        if cam != old_cam:
            keep(cl.enqueue_copy(q, self.camera_buf, np.frombuffer(cam, np.uint8),
                                 is_blocking=False))
        if prm != old_prm:
            keep(cl.enqueue_copy(q, self.params_buf, np.frombuffer(prm, np.uint8),
                                 is_blocking=False))
        self._uploaded = (cam, prm)

    # -- non-blocking reads -------------------------------------------------------------------
    def enqueue_read_rgba(self) -> ReadHandle:
        """Queue a copy of the last enqueued frame's RGBA8 image into pinned host memory; no
        wait. ``handle.wait()`` (or ``handle.event`` then ``handle.array``) gives the
        (height, width, 4) image; two reads may be in flight, a third reuses the first's memory
        (its handle then refuses to read)."""
        return self._rgba_reads.enqueue_read(self.rt.queue, self.rgba)

    def enqueue_read_stats(self) -> ReadHandle:
        """Queue a copy of the last enqueued frame's ray counts (STATS_LEN uint32: rays per
        depth, [STAT_DROPPED] children dropped) into pinned host memory; no wait.
        :meth:`enqueue_frame` already queues one per frame: :attr:`stats_handle`."""
        return self._stats_reads.enqueue_read(self.rt.queue, self.stats)

    @property
    def stats_handle(self) -> ReadHandle | None:
        """The ray-count read queued with the last frame (read it a frame late: no wait)."""
        return self._stats_handle

    def stats_from(self, counts: np.ndarray) -> dict:
        """:meth:`read_stats`'s dictionary from a stats array (e.g. ``stats_handle.wait()``)."""
        st = np.asarray(counts)
        L = self._levels
        per_depth = st[: L + 1].tolist()
        if L == 0 and not self.scene.has_secondary:  # no scan ran: the chunks' primary rays
            per_depth = [sum(nq * self.settings.spp for _, nq in self.chunks)]
        return {"rays_per_depth": per_depth, "dropped": int(st[STAT_DROPPED]),
                "secondary_rays": int(sum(per_depth[1:])), "levels": L,
                "shadow_rays_listed": int(st[STAT_SHADOW_LISTED]),
                "shadow_rays_spilled": int(st[STAT_SHADOW_SPILLED])}

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
        return self.stats_from(self.rt.to_host(self.stats, np.uint32, STATS_LEN))

    def memory_report(self) -> dict:
        """Device bytes per ray slot and per primary ray, and per triangle of the scene."""
        per_slot = bytes_per_ray_slot(self.settings)
        return {"bytes_per_ray_slot": per_slot,
                "bytes_per_primary_ray": per_slot * self.capacity / self.n_primary_max,
                "ray_slots": self.capacity, "chunks": len(self.chunks),
                "bytes_per_triangle": self.scene.bytes_per_triangle()}
