"""The one frame loop: a :class:`World` is a scene made live on one device, and every driver
(``render``, ``capture``, ``sweep``, the studies, the window, the benchmarks) advances it through
:meth:`World.enqueue_frame` / :meth:`World.read_frame` (or :meth:`World.frame`, both at once).
The API drivers use is documented in docs/frame_api.md; nothing deeper is theirs.

A frame is an ordered list of stages, each only enqueuing device work (no host sync inside):

    inputs      drops and pushes queued since the last frame (by-value kernel arguments)
    water       LBM steps for the frame's simulated time (the remainder of seconds/dt is
                carried to the next frame), then the surface into the water mesh's buffers
    scene       water BLAS refit (or rebuild), TLAS over the scene's device transform buffer
    caustics    photons through the water into the pool's caustic map (raytrace.caustics;
                only with ``[shading] caustics = "traced"`` or ``set_caustics("traced")``)
    render      the wavefront Whitted frame, tonemapped to RGBA8 on the device
    readback    non-blocking copies of the RGBA8 image (or, with ``image="yuv420p"``, of its
                yuv420p planes made on the device: kernels.video_yuv), the guard record and
                the ray counts into this frame's slot of host arrays; the image on a second
                queue (Runtime.copy_queue), so its copy overlaps the next frame's water and
                BVH stages (the next render waits for it before it rewrites the image)

A new stage (floating boats, caustics, a HUD) is one more object with a ``name`` and an
``enqueue(frame)`` method, inserted in :attr:`World.stages` where its inputs are ready.
Up to ``frames_in_flight`` frames are queued before the host waits on the oldest; a frame's
stage times and stats are read when it has completed (a frame late), from a bounded ring.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import deque
from pathlib import Path

import numpy as np
import pyopencl as cl

from app.errors import InputError


@dataclasses.dataclass(frozen=True)
class FrameStats:
    """What one completed frame did and cost."""

    frame: int                       #: frame index (0 is the first)
    sim_time: float                  #: s of simulated water time at the end of the frame
    lbm_steps: int                   #: LBM steps this frame took
    stage_ms: dict                   #: stage name -> ms of device time (OpenCL events)
    kernel_ms: float                 #: sum of stage_ms
    wall_ms: float                   #: host ms from enqueueing the frame to its image
    rays_per_depth: tuple            #: rays traced per bounce depth
    n_rays: int                      #: their sum
    n_triangles: int                 #: triangles in the scene
    device_bytes: int                #: device memory held by this runtime's live buffers
    guard: dict                      #: what the water guard saw and did this frame
    water_cells: tuple | None        #: (nx, ny) of the water grid
    device_span_ms: float = 0.0      #: device ms from the frame's first command's start to its
                                     #: last one's end (kernel_ms + idle gaps between them)


@dataclasses.dataclass(frozen=True)
class Pick:
    """A surface under a pixel: the world point, the instance and, on the water, the point in
    pool coordinates (x, y in metres from the pool's corner, as add_drop and push take)."""

    point: tuple
    instance: int
    water: bool
    pool_xy: tuple | None


@dataclasses.dataclass
class Frame:
    """One frame's inputs, as the stages see them."""

    index: int
    seconds: float
    lbm_steps: int = 0
    sim_time_end: float = 0.0
    drops: list = dataclasses.field(default_factory=list)
    pushes: list = dataclasses.field(default_factory=list)
    boats: list = dataclasses.field(default_factory=list)   # (method name, args, kwargs)


class _Slot:
    """One frame in flight: its inputs and the non-blocking reads of its outputs."""

    def __init__(self):
        self.frame: Frame | None = None
        self.t0 = 0.0
        self.image = self.counts = self.guard = None  # kernels.pinned.ReadHandle
        self.guard_copy: cl.Buffer | None = None      # the device copy its guard read reads


def buffer_bytes(*roots) -> int:
    """Sum of the sizes of the distinct device buffers reachable from ``roots`` through object
    attributes, lists, tuples and dicts (objects of this project's packages only)."""
    seen, total, stack = set(), 0, list(roots)
    while stack:
        o = stack.pop()
        if o is None or id(o) in seen:
            continue
        seen.add(id(o))
        if isinstance(o, cl.Buffer):
            total += o.size
        elif isinstance(o, list | tuple):
            stack.extend(o)
        elif isinstance(o, dict):
            stack.extend(o.values())
        elif type(o).__module__.split(".")[0] in ("raytrace", "lbm", "kernels", "app"):
            stack.extend(vars(o).values() if hasattr(o, "__dict__") else ())
    return total


def _orbit_ok(eye, target) -> None:
    if not np.isfinite(np.r_[eye, target]).all():
        raise InputError("camera eye and target must be finite")
    if np.allclose(eye, target):
        raise InputError(f"camera target equals eye {tuple(eye)}")


class World:
    """A scene made live on one device: water, geometry, lights, camera and renderer.

    ``scene``: an :class:`app.scene.Scene` or a path to a scene file. ``width``, ``height``,
    ``spp``, ``bounces`` override ``[render]``; ``cells`` resizes the water grid (cells along
    its longer side); ``water_steps`` overrides ``[pool] steps`` (LBM steps before the first
    frame); ``seed`` overrides ``[shading] seed``; ``water_accel`` picks how rays find the
    water, ``"grid"`` (its cells walked as a height field: the default) or ``"bvh"`` (an LBVH,
    refitted; ``rebuild_water_bvh`` rebuilds it each frame instead and implies ``"bvh"``);
    ``caustics`` (off | traced) overrides ``[shading]
    caustics`` (True/False: traced/off). ``image``: what :meth:`read_frame` returns, ``"rgba"``
    (height, width, 4) or ``"yuv420p"`` (the flat Y, U, V planes a video encoder takes,
    converted on the device: 1.5 bytes a pixel cross to the host instead of 4).
    ``light_buffer``: cells along each directional light's map of what blocks it
    (raytrace.light_buffer; the same image, faster shadow rays); None: the device's choice,
    0: none.
    """

    IMAGES = ("rgba", "yuv420p")

    def __init__(self, scene, device=None, *, width=None, height=None, spp=None, bounces=None,
                 aov=False, water_steps=None, cells=None, rebuild_water_bvh=False,
                 water_accel=None, seed=None, frames_in_flight: int = 2, caustics=None,
                 image: str = "rgba", light_buffer: int | None = None):
        from app.assemble import assemble, caustic_settings, check_water_accel, render_settings
        from app.scene import Scene, load_scene
        from kernels import get_runtime
        from raytrace.light_buffer import MAX_CELLS
        from raytrace.render import (
            Renderer,
            device_coop_from,
            device_cost_bins,
            device_light_buffer,
            device_shadow_list,
        )
        from raytrace.render_types import STATS_LEN

        if isinstance(scene, str | Path):
            scene = load_scene(scene)
        if not isinstance(scene, Scene):
            raise InputError(f"World: scene must be a scene file or app.scene.Scene, got "
                             f"{type(scene).__name__}")
        if image not in self.IMAGES:   # before any device work
            raise InputError(f"World: image {image!r} must be one of {', '.join(self.IMAGES)}")
        if water_accel is None:
            water_accel = "bvh" if rebuild_water_bvh else "grid"
        if check_water_accel(water_accel) == "grid" and rebuild_water_bvh:
            raise InputError("rebuild_water_bvh needs water_accel 'bvh': a height field has no "
                             "BVH")
        if not 1 <= int(frames_in_flight) <= 8:
            raise InputError(f"frames_in_flight {frames_in_flight} out of range; allowed [1, 8]")
        if light_buffer is not None and (isinstance(light_buffer, bool)
                                         or not isinstance(light_buffer, int)
                                         or not 0 <= light_buffer <= MAX_CELLS):
            raise InputError(f"light_buffer {light_buffer!r} out of range; allowed None or "
                             f"an integer in [0, {MAX_CELLS}]")
        self.scene = scene
        self.rt = get_runtime(device)
        a = assemble(scene, self.rt, cells=cells, water_steps=water_steps,
                     water_accel=water_accel)
        self.water_accel = water_accel
        self.render_scene, self.sim, self.water = a.render_scene, a.sim, a.water
        self.instances = a.instances
        self.boats = a.boats  # lbm.bodies.Boats: stepped inside every water step (a step hook)
        self.rebuild_water_bvh = bool(rebuild_water_bvh)
        self.renderer = Renderer(self.rt, self.render_scene, render_settings(
            scene, width=width, height=height, spp=spp, bounces=bounces, aov=aov, seed=seed,
            coop_from=device_coop_from(self.rt), cost_bins=device_cost_bins(self.rt),
            light_buffer=device_light_buffer(self.rt) if light_buffer is None else light_buffer,
            shadow_list=device_shadow_list(self.rt)))
        self._caustic_box = a.caustic_box
        self._caustics = None           # raytrace.caustics.Caustics, made when first turned on
        self.set_caustics(caustic_settings(scene).mode if caustics is None else caustics)
        c = scene.camera
        self.set_camera(c.eye, c.target, c.up, c.fov)
        self._rain = scene.water.rain if scene.water is not None else None
        self._carry = 0.0               # LBM steps owed to simulated time, < 1
        self._time = 0.0                # simulated seconds when there is no water
        self._next = 0                  # index of the next frame
        self._drops: list = []
        self._pushes: list = []
        self._boat_moves: list = []
        self._stage_ms: dict = {}       # frame index -> (stage times, device span), until its
                                        # stats are made
        self._stats: FrameStats | None = None
        self._picker = None
        from kernels.pinned import PinnedRing
        from lbm.structs import GUARD_DTYPE

        n = int(frames_in_flight)
        w, h = self.size
        self.image, self._yuv = None, None   # set_image: kernels.video_yuv with yuv420p
        self._display = None   # set_display: images copied on the device to the window's GL
        self._image_read: cl.Event | None = None   # the last image read (Runtime.copy_queue)
        self._rings = {"image": None,
                       "counts": PinnedRing(self.rt, 4 * STATS_LEN, np.uint32, (STATS_LEN,),
                                            slots=n)}
        if self.sim is not None:
            self._rings["guard"] = PinnedRing(self.rt, GUARD_DTYPE.itemsize, GUARD_DTYPE, (1,),
                                              slots=n)
        self._slots = [_Slot() for _ in range(n)]
        self.set_image(image)
        self._free = deque(self._slots)
        self._in_flight: deque[_Slot] = deque()
        self._guard_prev = None
        if self.sim is not None:
            self._guard_prev = self.sim.guard_record()
            self.sim.read_guard_each_check = False   # each frame's _Readback reads it
            # the record as of each frame's last check, copied by that check (two frames'
            # copies: the next frame's steps and the copy queue's read of this one overlap)
            self._guard_copies = [self.rt.buffer(GUARD_DTYPE.itemsize) for _ in range(2)]
        self.stages = [_Inputs(self), _Water(self), _SceneUpdate(self), _Caustics(self),
                       _Render(self), _Readback(self)]
        self.rt.finish()
        self.rt.timer.reset()

    # -- inputs -----------------------------------------------------------------------------
    def set_camera(self, eye, target, up=(0.0, 1.0, 0.0), fov=None) -> None:
        """Camera for the next frames: eye and target in metres, vertical fov in degrees."""
        eye = tuple(float(x) for x in eye)
        target = tuple(float(x) for x in target)
        up = tuple(float(x) for x in up)
        fov = float(self.scene.camera.fov if fov is None else fov)
        _orbit_ok(eye, target)
        try:
            self.renderer.set_camera(eye, target, up, fov)
        except ValueError as exc:
            raise InputError(f"camera: {exc}") from None
        self._camera = (eye, target, up, fov)

    @property
    def camera(self) -> tuple:
        """(eye, target, up, fov) of the next frame."""
        return self._camera

    def _need_water(self, what: str) -> None:
        if self.sim is None:
            raise InputError(f"{what}: the scene has no [water]")

    def add_drop(self, x: float, y: float, radius: float, height: float) -> None:
        """A drop of water (a smooth bump, ``height`` m, ``radius`` m) at pool point (x, y) m,
        applied at the start of the next frame."""
        self._need_water("add_drop")
        self._drops.append(tuple(float(v) for v in (x, y, radius, height)))

    def push(self, x: float, y: float, dx: float, dy: float, strength: float) -> None:
        """Push the water along the drag from (x, y) to (x + dx, y + dy) m with ``strength``
        m/s, applied at the start of the next frame."""
        self._need_water("push")
        self._pushes.append(tuple(float(v) for v in (x, y, dx, dy, strength)))

    def set_rain(self, rate: float) -> None:
        """Rain of ``rate`` drops per second over the pool (0 stops it); drop size and seed from
        the scene's ``[water.rain]`` (defaults 3 cm radius, 5 mm height, seed 1)."""
        self._need_water("set_rain")
        rate = float(rate)
        if not (math.isfinite(rate) and 0 <= rate <= 1e5):
            raise InputError(f"rain rate {rate:g} is out of range; allowed [0, 1e5] per second")
        r = self._rain
        radius, height, seed = (r.radius, r.height, r.seed) if r else (0.03, 0.005, 1)
        # a drop narrower than the grid resolves is widened to one cell, keeping its volume
        wide = max(radius, self.sim.dx)
        height *= (radius / wide) ** 2
        try:
            self.sim.set_rain(rate, wide, height, seed)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        self.rain_rate = rate

    def set_caustics(self, mode: str | bool) -> None:
        """Caustics for the next frames: ``off`` (or False: shadow rays through the water) or
        ``traced`` (or True: photons into a caustic map over the pool; the window's C key
        toggles). The other ``[shading] caustic_*`` settings stay the scene's."""
        from app.assemble import caustic_settings

        if isinstance(mode, bool):
            mode = "traced" if mode else "off"
        mode = caustic_settings(self.scene, mode).mode
        if mode == "off":
            if self._caustics is not None:
                self._caustics.set_mode("off")
            self.renderer.set_caustics(None)
            self.caustics = mode
            return
        if self._caustic_box is None:
            raise InputError(f"caustics {mode!r}: the scene has no pool ([water] and [pool])")
        if self._caustics is None:
            from raytrace.caustics import Caustics

            rs = self.renderer.settings
            self._caustics = Caustics(self.rt, self.render_scene, self._caustic_box,
                                      caustic_settings(self.scene, mode), fresnel=rs.fresnel,
                                      seed=rs.seed)
        self._caustics.set_mode(mode)
        self.renderer.set_caustics(self._caustics.map, self._caustics.view_params())
        self.caustics = mode

    def drop_boat(self, x: float, y: float, height: float = 0.5, index: int = 0) -> None:
        """Lift boat ``index`` to ``height`` m above the still water at pool point (x, y) m,
        upright and at rest, to fall from there (the window's B key)."""
        if self.boats is None or not self.boats.names:
            raise InputError("drop_boat: the scene has no [[boats]]")
        if not 0 <= index < len(self.boats.names):
            raise InputError(f"drop_boat: boat {index} out of range [0, {len(self.boats.names)})")
        w = self.scene.water
        sx, sy = self.sim.size
        if not (0 <= x <= sx and 0 <= y <= sy):
            raise InputError(f"drop_boat: ({x:g}, {y:g}) m is outside the pool [0, {sx:g}] x "
                             f"[0, {sy:g}] m")
        ox, oy, oz = w.origin
        self.drain()
        self.boats.place(index, (ox + x, oy + w.depth + float(height), oz + y))

    def boat_index(self, boat: int | str) -> int:
        """Index of a boat given by index or by its ``[[boats]]`` name; one InputError if none."""
        names = [b.name for b in self.scene.boats] if self.boats is not None else []
        if isinstance(boat, str):
            if boat not in names:
                raise InputError(f"boat {boat!r} is not in the scene (boats: "
                                 f"{', '.join(names) or 'none'})")
            return names.index(boat)
        if isinstance(boat, bool) or not isinstance(boat, int) or not 0 <= boat < len(names):
            raise InputError(f"boat {boat!r} out of range [0, {len(names)})")
        return boat

    def place_boat(self, boat: int | str, x: float, y: float, *, height: float | None = None,
                   heading: float | None = None, velocity=(0.0, 0.0), hold: bool = False) -> None:
        """Put a boat (index or ``[[boats]]`` name) upright over pool point (x, y) m, its keel
        ``height`` m above the still water (None: afloat at its rest draft), turned ``heading``
        deg about the vertical as ``[[boats]] rotation``'s y (None: the heading it has), moving
        at ``velocity`` (pool x, y m/s); ``hold``: kept there at rest until
        :meth:`release_boat`. Applied at the start of the next frame (a timeline ``boat``)."""
        i = self.boat_index(boat)
        sx, sy = self.sim.size
        if not (0 <= x <= sx and 0 <= y <= sy):
            raise InputError(f"place_boat: ({x:g}, {y:g}) m is outside the pool [0, {sx:g}] x "
                             f"[0, {sy:g}] m")
        vals = [x, y, *velocity] + [v for v in (height, heading) if v is not None]
        if not all(math.isfinite(float(v)) for v in vals):
            raise InputError(f"place_boat: values must be finite, got {vals}")
        self._boat_moves.append(("place", i, (float(x), float(y)), dict(
            height=height, heading=heading, velocity=tuple(map(float, velocity)),
            hold=bool(hold))))

    def release_boat(self, boat: int | str, velocity=None) -> None:
        """Let a held boat go, at rest or moving at ``velocity`` (pool x, y m/s), at the start
        of the next frame."""
        i = self.boat_index(boat)
        v = None if velocity is None else tuple(map(float, velocity))
        if v is not None and not all(map(math.isfinite, v)):
            raise InputError(f"release_boat: velocity {v} must be finite")
        self._boat_moves.append(("release", i, (), {"velocity": v}))

    def _move_boat(self, action: str, i: int, args: tuple, kw: dict) -> None:
        """Apply one queued boat move (the inputs stage: a host round trip in queue order)."""
        v = kw.get("velocity")
        vel = None if v is None else (v[0], 0.0, v[1])   # pool (x, y) -> world (x, z)
        if action == "release":
            self.boats.release(i, vel)
            return
        ox, _, oz = self.scene.water.origin
        pos = self.boats.rest_position(i, ox + args[0], oz + args[1], kw["height"])
        h = kw["heading"]
        self.boats.place(i, pos, heading=None if h is None else -math.radians(h), velocity=vel,
                         hold=kw["hold"])

    def boat_poses(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(positions (boats, 3) m, quaternions (boats, 4) w, x, y, z) now; a host read."""
        if self.boats is None:
            return None
        self.drain()
        return self.boats.poses()

    # -- facts ------------------------------------------------------------------------------
    @property
    def size(self) -> tuple[int, int]:
        s = self.renderer.settings
        return s.width, s.height

    @property
    def spp(self) -> int:
        return self.renderer.settings.spp

    @property
    def bounces(self) -> int:
        return self.renderer.settings.bounces

    @property
    def device_name(self) -> str:
        return self.rt.name

    @property
    def sim_time(self) -> float:
        return self.sim.time if self.sim is not None else self._time

    @property
    def stats(self) -> FrameStats | None:
        """The last completed frame's :class:`FrameStats` (None before the first)."""
        return self._stats

    @property
    def frames_enqueued(self) -> int:
        return self._next

    def steps_for(self, seconds: float) -> int:
        """LBM steps the next frame takes for ``seconds`` of simulated time (carrying the
        remainder from earlier frames); 0 without water."""
        if self.sim is None:
            return 0
        return int(math.floor(self._carry + seconds / self.sim.dt + 1e-9))

    def set_image(self, image: str) -> None:
        """What :meth:`read_frame` returns from the next frame on: ``"rgba"`` or ``"yuv420p"``
        (frames in flight are completed first)."""
        from kernels.pinned import PinnedRing
        from kernels.video_yuv import YuvConverter

        if image not in self.IMAGES:
            raise InputError(f"World: image {image!r} must be one of {', '.join(self.IMAGES)}")
        if image == self.image:
            return
        if getattr(self, "_in_flight", None):
            self.drain()
        w, h = self.size
        n = len(self._slots)
        if image == "yuv420p":
            self._yuv = YuvConverter(self.rt, w, h)
            ring = PinnedRing(self.rt, self._yuv.nbytes, np.uint8, (self._yuv.nbytes,), slots=n)
        else:
            self._yuv = None
            ring = PinnedRing(self.rt, 4 * w * h, np.uint8, (h, w, 4), slots=n)
        self._rings["image"], self.image = ring, image

    def set_display(self, targets) -> None:
        """Send the next frames' RGBA8 images to ``targets`` on the device instead of reading
        them back (the window's shared path: app.ext_share.ExternalTargets, whose
        ``enqueue(queue, rgba)`` queues the copy and returns a frame to ``wait()`` for);
        :meth:`read_frame` then returns that frame. None: read back to host memory again."""
        if targets is not None:
            if self.image != "rgba":
                raise ValueError("World.set_display needs image='rgba'")
            if tuple(targets.size) != tuple(self.size):
                raise ValueError(f"World.set_display: targets of {targets.size}, image of "
                                 f"{self.size}")
        if getattr(self, "_in_flight", None):
            self.drain()
        self._display = targets

    # -- the frame --------------------------------------------------------------------------
    def enqueue_frame(self, seconds: float = 0.0) -> int:
        """Queue one frame advancing the water by ``seconds``; returns its index. Waits only
        when ``frames_in_flight`` frames are already queued (for the oldest of them)."""
        frame = self._next_frame(seconds, "frame")
        return self._enqueue(frame, self.stages)

    def _next_frame(self, seconds, what: str) -> Frame:
        """The next frame's inputs: ``seconds`` of water (checked; ``what`` names the call in
        the error) and the drops, pushes and boat moves queued since the last frame."""
        seconds = float(seconds)
        if not (math.isfinite(seconds) and 0 <= seconds <= 3600):
            raise InputError(f"{what} seconds {seconds:g} is out of range; allowed [0, 3600]")
        frame = Frame(self._next, seconds, drops=self._drops, pushes=self._pushes,
                      boats=self._boat_moves)
        self._drops, self._pushes, self._boat_moves = [], [], []
        return frame

    def _enqueue(self, frame: Frame, stages) -> int:
        """Queue ``stages`` of ``frame`` into a free slot (waiting for the oldest if none)."""
        if not self._free:
            self._complete(self._in_flight.popleft(), keep_image=False)
        slot = self._free.popleft()
        slot.frame, slot.t0, slot.guard_copy = frame, time.perf_counter(), None
        for stage in stages:
            stage.enqueue(frame, slot)
        self.rt.timer.close_frame(frame.index)
        self._in_flight.append(slot)
        self._next += 1
        return frame.index

    def advance(self, seconds: float) -> None:
        """Advance the water by ``seconds`` (inputs applied) without rendering: the frame's
        index still counts, so a frame rendered afterwards is the one a run would render."""
        frame = self._next_frame(seconds, "advance")
        for stage in self.stages:
            if stage.name in ("inputs", "water"):
                stage.enqueue(frame, None)
        if self._caustics is not None:  # the next map starts afresh (no blend over the gap)
            self._caustics.reset_history()
        self._next += 1

    def read_frame(self, copy: bool = True) -> tuple[int, np.ndarray]:
        """Wait for the oldest frame in flight; its index and image: RGBA8 (height, width, 4),
        or with ``image="yuv420p"`` the flat uint8 Y, U, V planes. ``copy=False`` returns the
        pinned read-back array itself (no host copy; the window uploads it at once): its bytes
        are this frame's only until the next :meth:`enqueue_frame` reuses the slot. With a
        display set (:meth:`set_display`), the image is the display's frame, on the device."""
        if not self._in_flight:
            raise InputError("read_frame: no frame in flight (call enqueue_frame first)")
        slot = self._in_flight.popleft()
        return slot.frame.index, self._complete(slot, keep_image="copy" if copy else "view")

    def frame(self, seconds: float = 0.0) -> np.ndarray:
        """One whole frame: advance the water by ``seconds``, render, return RGBA8 (height,
        width, 4), row 0 at the top. Frames still in flight are completed first."""
        index = self.enqueue_frame(seconds)
        while True:
            i, img = self.read_frame()
            if i == index:
                return img

    # -- snapshots: one World steps, others render (app.snapshot, app.cluster) ----------------
    def snapshot_frame(self, seconds: float = 0.0) -> bytes:
        """Advance one frame as :meth:`enqueue_frame` would (inputs, water, guard and, with
        caustics on, the scene and the caustic map) but render nothing; return the frame's
        snapshot (:mod:`app.snapshot`): the surface heights the mesh kernel reads, the scene's
        transform rows, the camera, the caustic map. :meth:`render_snapshot` on a World of the
        same scene and settings turns it into the image this World's frame would have shown.
        Waits for the frame's water (host copies of the heights)."""
        from app import snapshot
        from lbm.structs import GUARD_DTYPE

        frame = self._next_frame(seconds, "frame")
        traced = self._caustics is not None and self._caustics.enabled
        for stage in self.stages:   # the stages that change state; the picture's are skipped
            if stage.name in ("render", "readback") or (
                    stage.name in ("scene", "caustics") and not traced):
                continue
            stage.enqueue(frame, None)
        self.rt.timer.close_frame(frame.index)
        self._next += 1
        arrays, guard = {}, {"nan": False, "acted": False, "report": "ok"}
        if self.sim is not None:   # what the readback stage reads, read the same way
            g = self.rt.to_host(self.sim.guard_buffer, GUARD_DTYPE, 1)[0]
            guard = self.sim.guard_summary(g, self._guard_prev)
            self._guard_prev = g.copy()
            guard["acted"] = guard.get("acted", bool(guard["restored"] or guard["damped"]
                                                      or guard["clamped"]))
            arrays["eta"] = self.rt.to_host(self.sim.surface_buffer, np.float32,
                                            self.sim.n_cells).reshape(self.sim.ny, self.sim.nx)
        arrays["transforms"] = self.render_scene.scene.read_transforms()
        if traced:
            arrays["caustic_map"] = self.rt.to_host(
                self._caustics.map, np.float32, 4 * self._caustics.n_texels).reshape(-1, 4)
        return snapshot.encode(frame=frame.index, sim_time=self.sim_time,
                               lbm_steps=frame.lbm_steps, guard=guard, camera=self.camera,
                               caustics=self.caustics, arrays=arrays)

    def render_snapshot(self, snap: bytes, *, image: bool = True) -> np.ndarray | None:
        """Render a snapshot from :meth:`snapshot_frame` of a World of the same scene and
        settings without stepping: its heights go through the same mesh launch, its transform
        rows, camera and caustic map are uploaded, then the scene, render and readback stages
        run. Returns RGBA8 (height, width, 4), byte-identical to the snapshotting World's own
        frame on the same kind of device. ``image=False`` updates the geometry only: give a
        fresh World the run's first snapshot so, as in a World's first frame, its water BVH is
        built over frame 0's surface and later frames refit it. Stats as for :meth:`frame`."""
        from app import snapshot

        s = snapshot.decode(snap)
        self._apply_snapshot(s)
        frame = Frame(self._next, 0.0, lbm_steps=s.lbm_steps, sim_time_end=s.sim_time)
        if not image:
            self._update_scene_only(frame)
            return None
        index = self._enqueue(frame, [st for st in self.stages
                                      if st.name in ("scene", "render", "readback")])
        while True:
            i, img = self.read_frame()
            if i == index:
                return img

    def _update_scene_only(self, frame: Frame) -> None:
        """The scene stage alone (BVHs and TLAS over the uploaded state); counts as a frame."""
        for st in self.stages:
            if st.name == "scene":
                st.enqueue(frame, None)
        self._next += 1

    def _apply_snapshot(self, s) -> None:
        """Upload a decoded snapshot's state (heights -> mesh, transforms, camera, caustics)."""
        from app.snapshot import SnapshotError

        a, rs = s.arrays, self.render_scene
        rows = a.get("transforms")
        n = rs.scene.n_instances
        if rows is None or rows.shape != (n, 3, 4) or rows.dtype != np.float32:
            raise SnapshotError(f"snapshot of another scene: transforms "
                                f"{None if rows is None else rows.shape}, this one has {n} "
                                "instances")
        eta = a.get("eta")
        if (eta is None) != (self.sim is None) or (
                eta is not None and eta.shape != (self.sim.ny, self.sim.nx)):
            raise SnapshotError(f"snapshot of another scene: heights "
                                f"{None if eta is None else eta.shape}, this water "
                                f"{None if self.sim is None else (self.sim.ny, self.sim.nx)}")
        q = self.rt.queue
        if eta is not None:
            w = self.water
            self.sim.write_surface_heights(eta, w.vertices, w.normals, w.origin)
        self.rt.keep(cl.enqueue_copy(q, rs.transform_buffer, rows, is_blocking=False))
        rs.scene.rows_written()
        self.set_camera(*s.camera)
        if s.caustics != self.caustics:
            self.set_caustics(s.caustics)
        if "caustic_map" in a:
            m = a["caustic_map"]
            if self._caustics is None or m.size != 4 * self._caustics.n_texels:
                raise SnapshotError(f"snapshot of another scene: caustic map of {m.size // 4} "
                                    "texels")
            self.rt.keep(cl.enqueue_copy(q, self._caustics.map, m, is_blocking=False))

    def drain(self) -> None:
        """Complete every frame in flight (their stats become available)."""
        while self._in_flight:
            self._complete(self._in_flight.popleft(), keep_image=False)

    def _complete(self, slot: _Slot, keep_image: str | bool):
        """Finish ``slot``'s frame (stats); its image: a copy (``"copy"``), the pinned array
        itself (``"view"``), or None (False)."""
        rgba = slot.image.wait()
        wall = (time.perf_counter() - slot.t0) * 1e3
        timer = self.rt.timer
        for tag, ms in timer.completed():
            self._stage_ms[tag] = (ms, timer.take_span_ms(tag))
        f = slot.frame
        stage_ms, span_ms = self._stage_ms.pop(f.index, ({}, 0.0))
        for old in [k for k in self._stage_ms if k < f.index]:
            del self._stage_ms[old]
        if not isinstance(rgba, np.ndarray):   # a frame of the shared display path
            keep_image = keep_image and "view"
        img = rgba.copy() if keep_image == "copy" else rgba if keep_image else None
        self._stats = self._make_stats(slot, stage_ms, wall, span_ms)
        self._free.append(slot)
        return img

    def _make_stats(self, slot: _Slot, stage_ms: dict, wall_ms: float,
                    span_ms: float = 0.0) -> FrameStats:
        f = slot.frame
        per_depth = tuple(self.renderer.stats_from(slot.counts.wait())["rays_per_depth"])
        guard = {"nan": False, "acted": False, "report": "ok"}
        if self.sim is not None:
            g = slot.guard.wait()[0]
            guard = self.sim.guard_summary(g, self._guard_prev)
            self._guard_prev = g.copy()
            guard["acted"] = guard.get("acted", bool(guard["restored"] or guard["damped"]
                                                      or guard["clamped"]))
            guard.pop("time", None)
            guard.pop("steps", None)
        return FrameStats(
            frame=f.index, sim_time=f.sim_time_end, lbm_steps=f.lbm_steps,
            stage_ms=stage_ms, kernel_ms=float(sum(stage_ms.values())), wall_ms=wall_ms,
            rays_per_depth=per_depth, n_rays=int(sum(per_depth)),
            n_triangles=self.render_scene.n_triangles,
            device_bytes=self._device_bytes(), guard=guard,
            water_cells=None if self.sim is None else (self.sim.nx, self.sim.ny),
            device_span_ms=span_ms)

    def _device_bytes(self) -> int:
        """Bytes of the device buffers the frame's objects hold (walked once, then cached until
        the scene reallocates)."""
        key = (id(self.render_scene.scene.trace_args()[0]), self.render_scene.n_triangles,
               id(self._caustics))
        if getattr(self, "_bytes_key", None) != key:
            self._bytes_key = key
            self._bytes = buffer_bytes(self.renderer, self.render_scene, self.sim,
                                       self._caustics)
        return self._bytes

    # -- queries (each synchronises) ---------------------------------------------------------
    def pick(self, px: float, py: float) -> Pick | None:
        """The surface under pixel (px, py) (0, 0 is the top-left corner) as the camera of the
        next frame sees it, traced against the live scene (water mesh included), or None."""
        from raytrace.bvh import HIT_DTYPE
        from raytrace.query import RayQuery

        w, h = self.size
        if not (0 <= px < w and 0 <= py < h):
            return None
        cam = self.renderer.camera
        sx = 2.0 * (px / w) - 1.0
        sy = 1.0 - 2.0 * (py / h)
        d = (np.asarray(cam["forward"][:3], np.float64) + sx * cam["right"][:3]
             + sy * cam["up"][:3])
        d /= np.linalg.norm(d)
        o = np.asarray(cam["origin"][:3], np.float64)
        rt = self.rt
        scene = self.render_scene.scene
        if self._picker is None or self._picker[1] is not scene.trace_args()[0]:
            bufs = (rt.buffer(16), rt.buffer(16), rt.buffer(HIT_DTYPE.itemsize))
            self._picker = (RayQuery(scene, *bufs, 1, stage="pick"), scene.trace_args()[0])
        q = self._picker[0]
        q.rebind_scene()
        cl.enqueue_copy(rt.queue, q.org, np.array([*o, 0.0], np.float32))
        cl.enqueue_copy(rt.queue, q.dirs, np.array([*d, np.inf], np.float32))
        q.enqueue()
        hit = rt.to_host(q.hits, HIT_DTYPE, 1)[0]
        if hit["prim"] < 0:
            return None
        p = o + float(hit["t"]) * d
        inst = int(hit["inst"])
        on_water = self.water is not None and inst == self.water.instance
        xy = None
        if on_water:
            ox, _, oz = self.water.origin
            xy = (float(p[0] - ox), float(p[2] - oz))
        return Pick(tuple(float(v) for v in p), inst, on_water, xy)

    def read_aov(self) -> dict:
        """Primary-hit AOVs of the last frame (the World must be made with ``aov=True``)."""
        self.drain()
        return self.renderer.read_aov()

    def read_caustics(self) -> dict | None:
        """The last frame's caustic map, irradiance (W/m^2, rgb) per face of the pool:
        {"floor": (nz, nx, 3), "z0", "z1": (ny, nx, 3), "x0", "x1": (ny, nz, 3)}; None when
        caustics are off. Synchronises (studies, tests)."""
        self.drain()
        if self._caustics is None or not self._caustics.enabled:
            return None
        return self._caustics.read_map()

    def read_radiance(self) -> np.ndarray:
        """Linear radiance (height, width, 3) of the last frame, before tonemapping."""
        self.drain()
        return self.renderer.read_framebuffer()

    def water_fields(self) -> dict | None:
        """h, u, v, bed of the water now (host copies; for saving and tests)."""
        self.drain()
        return None if self.sim is None else self.sim.fields()

    def close(self) -> None:
        """Complete the frames in flight."""
        self.drain()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ---- the stages ---------------------------------------------------------------------------
class _Inputs:
    """Drops and pushes queued since the last frame, applied first (by-value arguments), and
    boat moves (a host round trip each, in queue order: only on frames that have one)."""

    name = "inputs"

    def __init__(self, world: World):
        self.world = world

    def enqueue(self, frame: Frame, slot: _Slot) -> None:
        sim = self.world.sim
        if sim is None:
            return
        try:
            for d in frame.drops:
                sim.add_drop(*d)
            for p in frame.pushes:
                sim.push(*p)
            for move in frame.boats:
                self.world._move_boat(*move)
        except ValueError as exc:
            raise InputError(str(exc)) from None


class _Water:
    """LBM steps for the frame's simulated time, then the surface into the water mesh."""

    name = "water"

    def __init__(self, world: World):
        self.world = world

    def enqueue(self, frame: Frame, slot: _Slot) -> None:
        w = self.world
        if w.sim is None:
            w._time += frame.seconds
            frame.sim_time_end = w._time
            return
        owed = w._carry + frame.seconds / w.sim.dt
        steps = int(math.floor(owed + 1e-9))
        w._carry = max(0.0, owed - steps)
        frame.lbm_steps = steps
        if slot is not None:   # a rendered frame: its read-back reads this copy of the record
            w.sim.guard_snapshot = slot.guard_copy = w._guard_copies[frame.index % 2]
        if steps:
            w.sim.step(steps)
        else:
            w.sim.copy_guard_to_snapshot()
        if w.boats is not None:   # their step and moves write their transform rows
            w.render_scene.scene.rows_written()
        w.sim.guard_snapshot = None   # checks outside frames leave the copies alone
        if steps or frame.drops or frame.pushes:
            w.sim.write_surface(w.water.vertices, w.water.normals, w.water.origin)
        frame.sim_time_end = w.sim.time


class _SceneUpdate:
    """Water BLAS refit (or rebuild) and the TLAS over the scene's transforms."""

    name = "scene"

    def __init__(self, world: World):
        self.world = world

    def enqueue(self, frame: Frame, slot: _Slot) -> None:
        self.world.render_scene.update(rebuild=self.world.rebuild_water_bvh)


class _Caustics:
    """The caustic map of the frame's water (raytrace.caustics): after the scene stage, whose
    BVH its photons trace; nothing when caustics are off."""

    name = "caustics"

    def __init__(self, world: World):
        self.world = world

    def enqueue(self, frame: Frame, slot: _Slot) -> None:
        c = self.world._caustics
        if c is not None and c.enabled:
            c.enqueue(frame.index)


class _Render:
    """The wavefront frame, tonemapped to RGBA8 on the device."""

    name = "render"

    def __init__(self, world: World):
        self.world = world

    def enqueue(self, frame: Frame, slot: _Slot) -> None:
        w = self.world
        if w._image_read is not None:   # the last image's read (copy queue) before its rewrite
            cl.enqueue_barrier(w.rt.queue, wait_for=[w._image_read])
            w._image_read = None
        w.renderer.enqueue_frame(update_scene=False, read_stats=False)   # _Readback reads them


class _Readback:
    """Non-blocking copies of the image (RGBA8, or yuv420p converted here on the device), the
    ray counts and the guard record into the slot."""

    name = "readback"

    def __init__(self, world: World):
        self.world = world

    def enqueue(self, frame: Frame, slot: _Slot) -> None:
        w = self.world
        q, r, rings = w.rt.queue, w.renderer, w._rings
        src = r.rgba
        if w.sim is not None and slot.guard_copy is None:   # no water stage: the live record
            slot.guard = rings["guard"].enqueue_read(q, w.sim.guard_buffer)
        if w._display is not None:   # to the window's GL on the device: no read-back
            slot.counts = rings["counts"].enqueue_read(q, r.stats)
            r.use_stats_handle(slot.counts)
            if slot.guard_copy is not None:
                slot.guard = rings["guard"].enqueue_read(q, slot.guard_copy)
            slot.image = w._display.enqueue(q, src)
            q.flush()
            return
        if w._yuv is not None:
            w._yuv.enqueue(src)
            src = w._yuv.yuv
        # the counts, the guard record's copy and the image on the copy queue, after this
        # frame's kernels: they overlap the next frame's water and BVH stages, and the next
        # render, which rewrites the counts and the image (and precedes the next rewrite of
        # this guard copy), waits for the image's read (_Render), the last of them
        done = cl.enqueue_marker(q)
        q.flush()
        copy = w.rt.copy_queue
        slot.counts = rings["counts"].enqueue_read(copy, r.stats, wait_for=[done])
        r.use_stats_handle(slot.counts)
        if slot.guard_copy is not None:
            slot.guard = rings["guard"].enqueue_read(copy, slot.guard_copy, wait_for=[done])
        slot.image = rings["image"].enqueue_read(copy, src, wait_for=[done])
        w._image_read = slot.image.event
        copy.flush()
