"""Open an interactive window on a scene: rain, mouse ripples, an orbit camera and a HUD.

Display path (--upload, default auto): where the device offers it, the shared path
(app.ext_share): each frame is copied on the device into memory that GL reads as a pixel buffer
(external memory allocated by Vulkan, imported by OpenCL and GL), then into the texture: no
read-back, no host copy. NVIDIA's OpenCL offers it (cl_khr_external_memory_opaque_fd); it has no
cl_khr_gl_sharing, and PoCL has neither. Elsewhere the copy path: the image is read back without
blocking (two frames in flight, World.enqueue_frame / read_frame(copy=False)) into a pinned
buffer handed as it is to the texture upload (--upload pbo: through two pixel buffers in turn;
direct: from the pinned buffer), no host copy or conversion in Python. Either way one quad is
drawn with the HUD over it; the start line and the HUD name the path and, for the copy, why the
shared one is unavailable.

Mouse: drag on the water makes ripples where the mouse ray meets the water; Shift+drag pushes the
water along the drag; drag elsewhere orbits; right drag pans; the wheel zooms. Keys: R rain,
[ ] rain rate, Space pause, N one step, B drop a boat above the cursor (the scene's first
[[boats]]), + - bounces, 1 2 4 samples, G / Shift+G grid, S screenshot, C caustics traced/off,
H help, F2 HUD, F fullscreen, Esc quit.

Quality: --quality auto (default) shows a small probe World for a few frames at start, measures
it, and picks the water grid, render scale, bounce depth and caustic photons (the scene's, a
quarter, a sixteenth, or off) predicted to hold --target-fps; the start line and the HUD say
what it chose, and where it turned caustics off, C turns on the fewest photons. --quality
low|medium|high fixes them; --cells, --scale, --bounces and --caustics pin their own part. The
boats' physics always runs. Scripting: --frames N, --screenshot PATH, --record-events FILE and
--events FILE (a deterministic replay: events at their frame indices, recorded frame times),
--report FILE (the settings and the FPS as JSON). Without a display it says so and exits with
status 2: use `lbwater capture`.

    lbwater window scenes/pool.toml --size 1280x720
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from app.controls import (
    HELP,
    Action,
    Button,
    Controls,
    OrbitCamera,
    Water,
)
from app.errors import InputError, LbwaterError

SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"
HUD_REFRESH = 0.25   #: seconds between renewals of the HUD's text
EVENTS_VERSION = 1


class NoDisplayError(LbwaterError):
    """No display to open a window on (the CLI prints one line, exit status 2)."""


# ---- arguments ----------------------------------------------------------------------------------
def parse_size(text: str, what: str = "--size") -> tuple[int, int]:
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise InputError(f"{what} {text!r} must look like WIDTHxHEIGHT, e.g. 1280x720") from None
    if not (16 <= w <= 16384 and 16 <= h <= 16384):
        raise InputError(f"{what} {text!r}: width and height must lie in [16, 16384]")
    return w, h


def add_arguments(p) -> None:
    from app.quality import QUALITIES

    p.add_argument("scene", nargs="?", default=str(SCENES_DIR / "pool.toml"),
                   help="scene TOML file (default scenes/pool.toml)")
    p.add_argument("--device", help="OpenCL device: gpu, cpu, P:D or part of a name")
    p.add_argument("--size", help="window size WxH in pixels (default: the scene's [render])")
    p.add_argument("--quality", choices=QUALITIES, default="auto",
                   help="auto: measure and pick grid, scale, bounces and caustic photons "
                        "for --target-fps; low/medium/high: fixed presets")
    p.add_argument("--target-fps", type=float, default=60.0, help="frame rate auto aims for")
    p.add_argument("--caustics", choices=("off", "traced", "projected"),
                   help="caustics under the water (key C in the window); default from "
                        "[shading] caustics; given, auto quality keeps the mode")
    p.add_argument("--cells", type=int, help="water cells along the pool's longer side")
    p.add_argument("--scale", type=float, help="image pixels per window pixel, (0, 1]")
    p.add_argument("--bounces", type=int, help="reflection/refraction depth")
    p.add_argument("--spp", type=int, choices=(1, 2, 4), help="samples per pixel")
    p.add_argument("--no-vsync", action="store_true", help="do not wait for the display refresh")
    p.add_argument("--frames", type=int, help="exit after this many frames")
    p.add_argument("--screenshot", help="write the last frame to this PNG on exit")
    p.add_argument("--screenshot-hud", action="store_true",
                   help="the --screenshot includes the HUD and overlays")
    p.add_argument("--events", help="replay input events from this JSON-lines file")
    p.add_argument("--record-events", help="write the input events to this JSON-lines file")
    p.add_argument("--frame-time", type=float,
                   help="simulated seconds per frame (default: the measured frame interval)")
    p.add_argument("--upload", choices=UPLOADS, default="auto",
                   help="display path: shared (OpenCL writes the GL texture's memory on the "
                        "device through external memory, no host copy; needs "
                        "cl_khr_external_memory_opaque_fd, GL_EXT_memory_object_fd and "
                        "Vulkan, as on NVIDIA GPUs), pbo (read back, upload through two "
                        "pixel buffers) or direct (read back, upload from the read-back "
                        "buffer; the faster on Mesa's llvmpipe); auto (default): shared where "
                        "available, else pbo. The HUD and the start line name the path and why")
    p.add_argument("--report", help="write the run's settings and FPS to this JSON file")


def check_args(args) -> None:
    if args.target_fps is not None and not 1 <= args.target_fps <= 1000:
        raise InputError(f"--target-fps {args.target_fps} must lie in [1, 1000]")
    if args.scale is not None and not 0.05 <= args.scale <= 1.0:
        raise InputError(f"--scale {args.scale} must lie in [0.05, 1]")
    if args.cells is not None and not 4 <= args.cells <= 16384:
        raise InputError(f"--cells {args.cells} must lie in [4, 16384]")
    if args.bounces is not None and not 0 <= args.bounces <= 8:
        raise InputError(f"--bounces {args.bounces} must lie in [0, 8]")
    if args.frames is not None and args.frames < 1:
        raise InputError(f"--frames {args.frames} must be >= 1")
    if args.frame_time is not None and not 0 < args.frame_time <= 1:
        raise InputError(f"--frame-time {args.frame_time} must lie in (0, 1] s")
    if args.screenshot is not None and Path(args.screenshot).suffix.lower() != ".png":
        raise InputError(f"--screenshot {args.screenshot!r} must end in .png")
    report = getattr(args, "report", None)
    if report is not None and Path(report).suffix.lower() != ".json":
        raise InputError(f"--report {report!r} must end in .json")


def require_display() -> None:
    """Raise :class:`NoDisplayError` (one line) where no window can be opened."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        raise NoDisplayError("no display (DISPLAY is not set): the window needs one; render "
                             "without a display with `lbwater capture SCENE`")


# ---- worlds -------------------------------------------------------------------------------------
def make_world(scene, device, *, size, spp, bounces, cells, caustics: str | None = None):
    """The World the window drives (docs/frame_api.md), ``cells`` along the pool's longer side;
    ``caustics`` a mode ("off" | "traced") over the scene's (None keeps the scene's)."""
    from app.world import World

    return World(scene, device, width=size[0], height=size[1], spp=spp, bounces=bounces,
                 cells=None if scene.water is None else cells, caustics=caustics)


def caustics_label(scene, world) -> str:
    """What the HUD says of the world's caustics: "off", "traced (N photons)", or ""."""
    from app.assemble import caustic_settings

    mode = str(getattr(world, "caustics", "") or "")
    if mode == "traced":
        return f"traced ({caustic_settings(scene).photons} photons)"
    return mode


UPLOADS = ("auto", "shared", "pbo", "direct")
SHARED_PATH = "shared (OpenCL writes GL's memory on the device: no host copy)"


def display_path(upload: str = "pbo", shared_why_not: str | None = None) -> str:
    """Which display path is used and why, for the HUD and the start line: the shared one
    (``upload`` "shared", app.ext_share), or the copy with the reason the shared one is not
    used (``shared_why_not``)."""
    if upload == "shared":
        return SHARED_PATH
    how = "direct" if upload == "direct" else "pixel-buffer"
    copy = f"copy (2 in flight, {how} upload)"
    return f"{copy}; shared path unavailable: {shared_why_not}" if shared_why_not else copy


def attach_display(world, gl_ctx, upload: str, old=None):
    """Give ``world`` the shared display path where ``upload`` allows it ("auto", "shared") and
    the device and GL offer it; releases ``old`` targets first. Returns ``(targets or None,
    path text)``; ``upload="shared"`` where it is unavailable is a one-line InputError."""
    from app.ext_share import ExternalShareError, ExternalTargets

    if old is not None:
        world.set_display(None)
        old.release()
    if upload not in ("auto", "shared"):
        return None, display_path(upload)
    try:
        targets = ExternalTargets(gl_ctx, world.rt, tuple(world.size))
    except ExternalShareError as exc:
        if upload == "shared":
            raise InputError(f"--upload shared: unavailable here ({exc}); use --upload auto "
                             "or pbo") from None
        return None, display_path("pbo", str(exc))
    world.set_display(targets)
    return targets, display_path("shared")


def water_of(scene, cells: int | None) -> Water | None:
    """The water as the World lays it out with ``cells`` along its longer side."""
    from app.assemble import water_spec

    w = water_spec(scene, cells)
    if w is None:
        return None
    return Water(tuple(w.origin), tuple(w.size), float(w.depth), float(w.size[0]) / w.cells[0])


def caustic_scene(scene, photons: int | None):
    """``scene`` tracing ``photons`` caustic photons per frame, its caustic map's resolution
    scaled to keep the photons per texel (:func:`app.quality.caustic_map_resolution`); None
    or the scene's own count: the scene unchanged."""
    from app.assemble import caustic_settings
    from app.frames import with_shading
    from app.quality import caustic_map_resolution

    cs = caustic_settings(scene)
    if not photons or photons == cs.photons:
        return scene
    return with_shading(scene, {"caustic_photons": int(photons), "caustic_resolution":
                                caustic_map_resolution(photons, cs.photons, cs.resolution)})


def decide_quality(args, scene, rt, window_size, frame_seconds, present=None):
    """The quality for this run (``--quality``, overrides, or a short measurement of a probe
    World; ``present(world, image)`` shows its frames, as :func:`app.quality.measure` says)."""
    from app import quality as q
    from app.assemble import caustic_settings

    water = scene.water
    max_cells = max(water.cells) if water is not None else 2
    max_bounces = args.bounces if args.bounces is not None else scene.render.bounces
    cs = caustic_settings(scene)
    photons = cs.photons if cs.mode == "traced" and water is not None else 0
    asked = getattr(args, "caustics", None)       # --caustics pins the mode
    if args.quality != "auto":
        base = q.preset(args.quality, max_cells=max_cells, max_bounces=max(max_bounces, 1),
                        photons=photons)
        return dataclasses.replace(
            base, cells=args.cells or base.cells, scale=args.scale or base.scale,
            bounces=base.bounces if args.bounces is None else args.bounces,
            caustics=None if asked else base.caustics)
    if water is None:
        return q.Quality(2, args.scale or 1.0, max_bounces, "auto (no water)")
    if args.cells and args.scale and args.bounces is not None and (asked or not photons):
        return q.Quality(args.cells, args.scale, args.bounces, "fixed")
    probe_cells = args.cells or min(max_cells, 64)
    probe_size = q.scaled_size(window_size, min(0.5, args.scale or 0.5))
    probe_bounces = min(2, max_bounces) if args.bounces is None else args.bounces
    probe_photons = min(photons, q.PROBE_PHOTONS)
    world = make_world(caustic_scene(scene, probe_photons), rt, size=probe_size,
                       spp=args.spp or 1, bounces=probe_bounces, cells=probe_cells)
    try:
        stats, wall_ms = q.measure(world, frame_seconds, present=present)
    finally:
        world.close()
    nx, ny = stats[-1].water_cells
    steps = sum(s.lbm_steps for s in stats) / len(stats)
    costs = q.costs_from_stats(stats, wall_ms, n_cells=nx * ny, steps=steps,
                               photons=probe_photons)
    return q.choose(costs, target_fps=args.target_fps, window=window_size, max_cells=max_cells,
                    max_bounces=max(max_bounces, 1), aspect=q.aspect_of(water.size),
                    spp=args.spp or 1, base_cells=probe_cells, photons=photons,
                    keep_caustics=asked == "traced", fixed_cells=args.cells,
                    fixed_scale=args.scale, fixed_bounces=args.bounces)


# ---- event files ---------------------------------------------------------------------------
class EventLog:
    """Input events as JSON lines: a header, then ``{"frame": i, "t": s, "kind": ...}`` records
    (kinds: button, cursor, scroll, action, resize, tick). ``frame`` is the index of the frame
    the event reaches; a ``tick`` holds that frame's simulated seconds."""

    KINDS = {"button": ("button", "pressed", "shift"), "cursor": ("x", "y"), "scroll": ("dy",),
             "action": ("action",), "resize": ("width", "height"), "tick": ("seconds",)}

    def __init__(self, header: dict, events: list[dict]):
        self.header = header
        self.events = events
        self.by_frame: dict[int, list[dict]] = {}
        for e in events:
            self.by_frame.setdefault(e["frame"], []).append(e)

    @classmethod
    def load(cls, path) -> EventLog:
        path = Path(path)
        try:
            text = path.read_text()
        except OSError as exc:
            raise InputError(f"--events {path}: cannot read ({exc.strerror})") from None
        header, events = None, []
        for n, line in enumerate(text.splitlines(), 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
            except json.JSONDecodeError as exc:
                raise InputError(f"{path}:{n}: not JSON ({exc.msg})") from None
            if not isinstance(rec, dict):
                raise InputError(f"{path}:{n}: each line must be a JSON object")
            if header is None:
                if rec.get("kind") != "header" or rec.get("version") != EVENTS_VERSION:
                    raise InputError(f"{path}:{n}: the first line must be the header "
                                     f"{{\"kind\": \"header\", \"version\": {EVENTS_VERSION}}}")
                bad = [k for k in ("window", "cells", "scale", "bounces") if k not in rec]
                if bad:
                    raise InputError(f"{path}:{n}: the header lacks {', '.join(bad)}")
                header = rec
                continue
            kind = rec.get("kind")
            if kind not in cls.KINDS:
                raise InputError(f"{path}:{n}: kind={kind!r}; allowed: {', '.join(cls.KINDS)}")
            missing = [k for k in ("frame", *cls.KINDS[kind]) if k not in rec]
            if missing:
                raise InputError(f"{path}:{n}: {kind} event lacks {', '.join(missing)}")
            if not isinstance(rec["frame"], int) or rec["frame"] < 0:
                raise InputError(f"{path}:{n}: frame={rec['frame']!r} must be an integer >= 0")
            if kind == "action":
                try:
                    Action.from_str(rec["action"])
                except ValueError as exc:
                    raise InputError(f"{path}:{n}: {exc}") from None
            if kind == "button" and str(rec["button"]).upper() not in Button.__members__:
                raise InputError(f"{path}:{n}: button={rec['button']!r}; allowed: left, right, "
                                 "middle")
            events.append(rec)
        if header is None:
            raise InputError(f"{path}: empty event file (no header)")
        return cls(header, events)

    def write(self, path) -> None:
        from app.io import atomic_path

        with atomic_path(path) as tmp:
            with open(tmp, "w") as fh:
                fh.write(json.dumps({"kind": "header", "version": EVENTS_VERSION,
                                     **self.header}) + "\n")
                for e in self.events:
                    fh.write(json.dumps(e) + "\n")


# ---- GL: the image on screen ----------------------------------------------------------------
_QUAD_VS = """
#version 330
in vec2 pos;
out vec2 uv;
void main() {
    uv = vec2(0.5 * pos.x + 0.5, 0.5 - 0.5 * pos.y);   // image row 0 at the top
    gl_Position = vec4(pos, 0.0, 1.0);
}
"""
_QUAD_FS = """
#version 330
uniform sampler2D image;
in vec2 uv;
out vec4 frag;
void main() { frag = vec4(texture(image, uv).rgb, 1.0); }
"""


class Presenter:
    """Uploads RGBA8 frames into a texture and draws them over the current framebuffer's
    viewport. Works in any moderngl context (window or EGL).

    ``upload="pbo"`` (default) writes the frame's array (the pinned read-back buffer itself,
    World.read_frame(copy=False)) into one of two pixel buffers in turn (frame N's write does
    not wait for frame N-1's upload from the other) and uploads the texture from that buffer;
    ``"direct"`` hands the array straight to glTexSubImage2D (the driver's one host copy).
    On the NVIDIA H200 the pixel buffers were the faster (bench/h200_window.sh: 1.06x against
    1.15x the bare frame at 1920x1080, medians of three), on Mesa's llvmpipe the direct one. Neither
    copies or converts the array in Python (row 0 at the top is flipped in the quad's texture
    coordinates), nor waits for the GPU."""

    def __init__(self, ctx, upload: str = "pbo"):
        if upload not in ("pbo", "direct"):
            raise ValueError(f"upload={upload!r}; allowed: pbo, direct")
        self.ctx, self.upload_mode = ctx, upload
        self.prog = ctx.program(vertex_shader=_QUAD_VS, fragment_shader=_QUAD_FS)
        quad = np.array([-1, -1, 1, -1, -1, 1, 1, 1], np.float32)
        self.vbo = ctx.buffer(quad.tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "2f", "pos")])
        self.texture = None
        self.pbos: list = []
        self.uploads = 0
        self.size = None

    def _ensure_texture(self, w: int, h: int) -> None:
        if self.size != (w, h):
            self.reset()
            self.texture = self.ctx.texture((w, h), 4)
            self.pbos = ([self.ctx.buffer(reserve=w * h * 4, dynamic=True) for _ in range(2)]
                         if self.upload_mode == "pbo" else [])
            self.size = (w, h)

    def reset(self) -> None:
        """Release the texture and pixel buffers (made again at the next upload's size)."""
        if self.texture is not None:
            self.texture.release()
        for pbo in self.pbos:
            pbo.release()
        self.texture, self.pbos, self.size = None, [], None

    def upload(self, img) -> None:
        """Upload ``img``, (H, W, 4) uint8, C-contiguous (else it is copied once here); its
        bytes are consumed before this returns, so the caller may reuse the array at once.
        ``img`` may also be a frame of the shared path (app.ext_share.SharedFrame, waited
        for): GL then copies it into the texture on the device."""
        if hasattr(img, "upload_into"):
            self._ensure_texture(*img.size)
            img.upload_into(self.texture)
            self.uploads += 1
            return
        h, w = img.shape[:2]
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 4:
            raise ValueError(f"Presenter.upload: need (H, W, 4) uint8, got {img.shape} "
                             f"{img.dtype}")
        self._ensure_texture(w, h)
        data = img if img.flags.c_contiguous else np.ascontiguousarray(img)
        if self.upload_mode == "pbo":
            pbo = self.pbos[self.uploads % 2]
            pbo.write(data)
            self.texture.write(pbo)
        else:
            self.texture.write(data)
        self.uploads += 1

    def draw(self, viewport_size) -> None:
        """Draw the last uploaded image over (0, 0, w, h) of the bound framebuffer."""
        if self.texture is None:
            return
        exact = tuple(viewport_size) == self.size
        f = self.ctx.NEAREST if exact else self.ctx.LINEAR
        self.texture.filter = (f, f)
        self.ctx.viewport = (0, 0, *viewport_size)
        self.texture.use(0)
        self.vao.render(self.ctx.TRIANGLE_STRIP)

    def snapshot(self, size) -> np.ndarray:
        """The last image drawn as it appears on a ``size`` framebuffer, HUD excluded:
        (H, W, 4) uint8, row 0 on top."""
        prev = self.ctx.fbo
        fbo = self.ctx.simple_framebuffer(tuple(size), components=4)
        try:
            fbo.use()
            fbo.clear(0, 0, 0, 1)
            self.draw(size)
            data = fbo.read(components=4, alignment=1)
        finally:
            fbo.release()
            if prev is not None:
                prev.use()
            else:   # a standalone context without a default framebuffer
                self.ctx.fbo = None
        return np.frombuffer(data, np.uint8).reshape(size[1], size[0], 4)[::-1].copy()


def write_png(path, img: np.ndarray) -> None:
    import imageio.v3 as iio

    from app.io import atomic_path

    with atomic_path(path) as tmp:
        iio.imwrite(tmp, img, extension=".png")


# ---- the window ---------------------------------------------------------------------------------
#: glfw key name -> action (Shift variants handled in the callback).
KEYMAP = {
    "ESCAPE": Action.QUIT, "R": Action.TOGGLE_RAIN, "LEFT_BRACKET": Action.RAIN_LESS,
    "RIGHT_BRACKET": Action.RAIN_MORE, "SPACE": Action.PAUSE, "N": Action.STEP,
    "B": Action.DROP_BOAT, "EQUAL": Action.BOUNCES_UP, "KP_ADD": Action.BOUNCES_UP,
    "MINUS": Action.BOUNCES_DOWN, "KP_SUBTRACT": Action.BOUNCES_DOWN, "1": Action.SPP_1,
    "2": Action.SPP_2, "4": Action.SPP_4, "G": Action.GRID_UP, "S": Action.SCREENSHOT,
    "C": Action.TOGGLE_CAUSTICS, "H": Action.TOGGLE_HELP, "F": Action.FULLSCREEN,
    "F2": Action.TOGGLE_HUD,
}


def _open_window(glfw, size, title, visible):
    """A GL 3.3 core window: an EGL context first on Linux (so a headless EGL context can live in
    the same process, as in the tests and `bench window`; GLX and EGL contexts of one thread
    clash under libglvnd), else the platform's native one."""
    apis = [glfw.NATIVE_CONTEXT_API]
    if sys.platform.startswith("linux"):
        apis.insert(0, glfw.EGL_CONTEXT_API)
    for api in apis:
        glfw.default_window_hints()
        for hint, value in ((glfw.CONTEXT_VERSION_MAJOR, 3), (glfw.CONTEXT_VERSION_MINOR, 3),
                            (glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE),
                            (glfw.OPENGL_FORWARD_COMPAT, True), (glfw.VISIBLE, visible),
                            (glfw.CONTEXT_CREATION_API, api)):
            glfw.window_hint(hint, value)
        win = glfw.create_window(size[0], size[1], title, None, None)
        if win:
            return win
    return None


class _GlfwLoader:
    """GL entry points for moderngl from glfw (whatever API made the window's context)."""

    def __init__(self, glfw):
        self.glfw = glfw

    def load_opengl_function(self, name: str) -> int:
        import ctypes

        return ctypes.cast(self.glfw.get_proc_address(name), ctypes.c_void_p).value or 0

    def release(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass


class Viewer:
    """The window: glfw callbacks -> :class:`Controls`; a frame loop with two frames in flight.

    ``replay`` (an :class:`EventLog`) replaces live input; ``record`` collects it. Tests call
    the ``on_*`` callbacks directly with synthesized events, as glfw would."""

    def __init__(self, scene, rt, *, window_size, quality, spp=1, frame_time=None,
                 vsync=True, upload="pbo", replay: EventLog | None = None, record=False,
                 title="lbwater", visible=True):
        import glfw
        import moderngl

        from app.quality import scaled_size

        self.glfw = glfw
        self.rt = rt
        self.frame_time = frame_time
        self.replay = replay
        self.recording = [] if record else None
        glfw.ERROR_REPORTING = "ignore"
        if not glfw.init():
            desc = glfw.get_error()[1] if hasattr(glfw, "get_error") else None
            why = desc.decode() if isinstance(desc, bytes) else str(desc or "glfw.init failed")
            raise NoDisplayError(f"no display ({why}); render without a display with "
                                 "`lbwater capture SCENE`")
        self.win = _open_window(glfw, window_size, title, visible)
        if not self.win:
            glfw.terminate()
            raise NoDisplayError("could not open an OpenGL 3.3 window on this display; render "
                                 "without a display with `lbwater capture SCENE`")
        glfw.make_context_current(self.win)
        glfw.swap_interval(1 if vsync else 0)
        self.ctx = moderngl.create_context(context=_GlfwLoader(glfw))
        self.upload_mode = upload
        self.presenter = Presenter(self.ctx, "direct" if upload == "direct" else "pbo")
        self.targets = None   # the shared display path's (attach_display)
        from app.hud import Hud
        self.hud = Hud(self.ctx)
        self.fb_size = tuple(glfw.get_framebuffer_size(self.win))
        self._start_window = tuple(window_size)
        self.win_size = tuple(glfw.get_window_size(self.win))
        self.path = display_path("direct" if upload == "direct" else "pbo")  # probe: a copy
        if callable(quality):   # decided here, its probe frames shown as the window shows
            glfw.swap_interval(0)   # them, but not waiting for the display's refresh
            quality = quality(self)
            glfw.swap_interval(1 if vsync else 0)
        self.quality = quality
        self.scene = scene = caustic_scene(scene, quality.photons)
        logical = tuple(replay.header.get("window", self.win_size)) if replay else self.win_size
        c = scene.camera
        bounces = quality.bounces
        self.cells = quality.cells if scene.water is not None else None
        image = scaled_size(logical, quality.scale)
        self.controls = Controls(OrbitCamera.from_look(c.eye, c.target, c.fov),
                                 water_of(scene, self.cells), spp=spp, bounces=bounces,
                                 cells=self.cells, window_size=logical, image_size=image,
                                 frame_time=frame_time or 1 / 60)
        self.world = make_world(scene, rt, size=image, spp=spp, bounces=bounces,
                                cells=self.cells, caustics=quality.caustics)
        self.controls.caustics = quality.caustics   # C toggles from here; rebuilds keep it
        self.controls.reapply(self.world, camera=False)
        self.targets, self.path = attach_display(self.world, self.ctx, upload)
        self.next_frame = 0       # index of the next frame to enqueue (event time base)
        self._size_seen = tuple(self.world.size)
        self.in_flight = 0
        self.shown = 0
        self.t0 = time.perf_counter()
        self._t_last = None
        self._dt_ema = None
        self.fullscreen_saved = None
        self._hud = (None, [], None)   # (when, lines, world) of the HUD's text
        self.screenshots: list[Path] = []
        self.last_snapshot = None
        self._keys = {getattr(glfw, f"KEY_{name}"): a for name, a in KEYMAP.items()}
        if replay is None:
            glfw.set_mouse_button_callback(self.win, self._glfw_button)
            glfw.set_cursor_pos_callback(self.win, self._glfw_cursor)
            glfw.set_scroll_callback(self.win, self._glfw_scroll)
            glfw.set_key_callback(self.win, self._glfw_key)
        else:  # replay: only Esc from the keyboard
            glfw.set_key_callback(self.win, self._glfw_key_replay)
        glfw.set_framebuffer_size_callback(self.win, self._glfw_fb)

    def present_probe(self, world, img) -> None:
        """Show a probe World's frame as the loop shows frames (image, HUD, help; swap), so
        that the auto quality's measurement includes the display's cost."""
        from app.hud import help_lines, hud_lines

        self.glfw.poll_events()
        self.presenter.upload(img)
        ctx = self.ctx
        ctx.screen.use()
        ctx.viewport = (0, 0, *self.fb_size)
        ctx.clear(0.0, 0.0, 0.0, 1.0)
        self.presenter.draw(self.fb_size)
        lines = hud_lines(world.stats, fps=0.0, path=self.path, size=tuple(world.size),
                          device=world.device_name, quality="quality auto: measuring ...",
                          bounces=world.bounces, caustics=caustics_label(world.scene, world))
        self.hud.draw([(lines, 8, 8), (help_lines(HELP), -8, -8)], self.fb_size)
        self.glfw.swap_buffers(self.win)

    # -- time -------------------------------------------------------------------------------
    def now(self) -> float:
        return time.perf_counter() - self.t0

    # -- recording + the callbacks a user triggers ------------------------------------------
    def _rec(self, kind: str, **fields) -> None:
        if self.recording is not None:
            self.recording.append({"frame": self.next_frame, "t": round(self.now(), 4),
                                   "kind": kind, **fields})

    def on_button(self, button: Button, pressed: bool, shift: bool = False) -> None:
        self._rec("button", button=Button(button).name.lower(), pressed=bool(pressed),
                  shift=bool(shift))
        self.controls.mouse_button(self.world, button, pressed, shift)

    def on_cursor(self, x: float, y: float) -> None:
        self._rec("cursor", x=float(x), y=float(y))
        self.controls.cursor(self.world, x, y)

    def on_scroll(self, dy: float) -> None:
        self._rec("scroll", dy=float(dy))
        self.controls.scroll(self.world, dy)

    def on_action(self, action: Action) -> None:
        self._rec("action", action=Action(action).name.lower())
        self.controls.action(self.world, action, self.now())

    def on_resize(self, width: int, height: int) -> None:
        """The framebuffer is now width x height (window pixels = framebuffer pixels here)."""
        self._rec("resize", width=int(width), height=int(height))
        self.controls.resize(self.world, width, height)

    def _replay(self, e: dict) -> None:
        """One recorded event, through the same callbacks as live input (so a replay can be
        recorded again)."""
        k = e["kind"]
        if k == "button":
            self.on_button(Button[str(e["button"]).upper()], bool(e["pressed"]),
                           bool(e["shift"]))
        elif k == "cursor":
            self.on_cursor(float(e["x"]), float(e["y"]))
        elif k == "scroll":
            self.on_scroll(float(e["dy"]))
        elif k == "action":
            self.on_action(Action.from_str(e["action"]))
        elif k == "resize":
            self.on_resize(int(e["width"]), int(e["height"]))

    def _glfw_button(self, win, button, action, mods) -> None:
        g = self.glfw
        b = {g.MOUSE_BUTTON_LEFT: Button.LEFT, g.MOUSE_BUTTON_RIGHT: Button.RIGHT,
             g.MOUSE_BUTTON_MIDDLE: Button.MIDDLE}.get(button)
        if b is not None and action in (g.PRESS, g.RELEASE):
            self.on_button(b, action == g.PRESS, bool(mods & g.MOD_SHIFT))

    def _glfw_cursor(self, win, x, y) -> None:
        self.on_cursor(x, y)

    def _glfw_scroll(self, win, dx, dy) -> None:
        self.on_scroll(dy)

    def _glfw_key(self, win, key, scancode, action, mods) -> None:
        g = self.glfw
        if action != g.PRESS:
            return
        a = self._keys.get(key)
        if a == Action.GRID_UP and mods & g.MOD_SHIFT:
            a = Action.GRID_DOWN
        if a is not None:
            self.on_action(a)

    def _glfw_key_replay(self, win, key, scancode, action, mods) -> None:
        if action == self.glfw.PRESS and key == self.glfw.KEY_ESCAPE:
            self.controls.action(self.world, Action.QUIT)

    def _glfw_fb(self, win, width, height) -> None:
        self.fb_size = (width, height)
        self.win_size = tuple(self.glfw.get_window_size(self.win))
        if self.replay is None and width > 0 and height > 0:
            self.on_resize(*self.win_size)

    # -- the loop ---------------------------------------------------------------------------
    def _seconds(self) -> float:
        """Simulated seconds for the next frame: the replayed tick, --frame-time, or the
        smoothed measured frame interval (clamped to [1/240, 1/15] s)."""
        if self.replay is not None:
            ticks = [e for e in self.replay.by_frame.get(self.next_frame, ())
                     if e["kind"] == "tick"]
            if ticks:
                return float(ticks[-1]["seconds"])
        if self.frame_time is not None:
            return self.frame_time
        dt = self._dt_ema if self._dt_ema is not None else 1 / 60
        return min(1 / 15, max(1 / 240, dt))

    def _drain(self):
        img = None
        while self.in_flight:
            _, img = self.world.read_frame()
            self.in_flight -= 1
        return img

    def _rebuild(self, **changes) -> None:
        """A new World at new settings (spp, bounces, cells, image size), same camera/scene.
        The water restarts from the scene's initial state."""
        from app.quality import scaled_size

        img = self._drain()
        if img is not None:
            self.presenter.upload(img)
        c = self.controls
        self.cells = changes.get("cells", self.cells)
        size = scaled_size(c.window_size, self.quality.scale)
        self.world.close()
        self.world = make_world(self.scene, self.rt, size=size, spp=c.spp, bounces=c.bounces,
                                cells=self.cells, caustics=c.caustics)
        self.targets, self.path = attach_display(self.world, self.ctx, self.upload_mode,
                                                 old=self.targets)
        c.image_size = tuple(self.world.size)
        c.water = water_of(self.scene, self.cells)
        c.reapply(self.world)

    def step(self, limit: int | None = None) -> bool:
        """One turn of the loop: input, hand it over, enqueue the next frame, show the oldest.
        Returns False once the window should close."""
        from app.quality import scaled_size

        g = self.glfw
        if self.replay is None:
            g.poll_events()
        else:
            g.poll_events()   # keep the window responsive; input comes from the file
            for e in self.replay.by_frame.get(self.next_frame, ()):
                self._replay(e)
        req = self.controls.apply(self.world)
        if req.fullscreen:
            self._toggle_fullscreen()
        # a new window size rebuilds the World once it has held for a frame (a drag-resize
        # does not rebuild at every step; meanwhile the image is stretched to the window)
        want = scaled_size(self.controls.window_size, self.quality.scale)
        resized = want != tuple(self.world.size) and want == self._size_seen
        self._size_seen = want
        if req.rebuild or resized:
            self._rebuild(**req.rebuild)
        more = limit is None or self.next_frame < limit
        if more and not req.quit:
            seconds = self.controls.frame_seconds(self._seconds())
            self._rec("tick", seconds=seconds)
            self.world.enqueue_frame(seconds)
            self.next_frame += 1
            self.in_flight += 1
        if self.in_flight >= 2 or (self.in_flight and (not more or req.quit)):
            _, img = self.world.read_frame(copy=False)   # the pinned buffer: uploaded now,
            self.in_flight -= 1                             # before the next enqueue reuses it
            self.presenter.upload(img)
            self.shown += 1
            self._tick_fps()
        self._draw()
        if req.screenshot:
            t = time.time()
            stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(t))
            self.save_screenshot(Path(f"lbwater-{stamp}-{int(t * 1000) % 1000:03d}.png"))
        return not (req.quit or g.window_should_close(self.win)
                    or (limit is not None and self.shown >= limit and not self.in_flight))

    def _tick_fps(self) -> None:
        t = time.perf_counter()
        if self._t_last is not None:
            dt = t - self._t_last
            self._dt_ema = dt if self._dt_ema is None else 0.9 * self._dt_ema + 0.1 * dt
        self._t_last = t

    @property
    def fps(self) -> float:
        return 0.0 if not self._dt_ema else 1.0 / self._dt_ema

    def hud_text(self) -> list[str]:
        """The HUD's lines for the shown frame (what :meth:`_draw` writes over the image)."""
        from app.hud import hud_lines

        c = self.controls
        return hud_lines(self.world.stats, fps=self.fps, path=self.path,
                         size=tuple(self.world.size), device=self.world.device_name,
                         quality=self.quality.describe(), paused=c.paused,
                         rain=c.rain_rate if c.rain_on else 0.0, spp=c.spp, bounces=c.bounces,
                         caustics=caustics_label(self.scene, self.world))

    def _draw(self, swap: bool = True) -> None:
        from app.hud import guard_lines, help_lines

        ctx, c = self.ctx, self.controls
        ctx.screen.use()
        ctx.viewport = (0, 0, *self.fb_size)
        ctx.clear(0.0, 0.0, 0.0, 1.0)
        self.presenter.draw(self.fb_size)
        now = self.now()
        blocks = []
        if c.show_hud:
            # the text is renewed HUD_REFRESH s apart (readable, and the HUD's vertices are
            # then reused between renewals: on a CPU device GL shares its cores)
            if (self._hud[0] is None or now - self._hud[0] >= HUD_REFRESH
                    or self._hud[2] is not self.world):
                self._hud = (now, self.hud_text(), self.world)
            blocks.append((self._hud[1], 8, 8))
            warn = guard_lines(self.world.stats)
            if warn:
                blocks.append((warn, -8, 8, (1.0, 0.6, 0.3, 1.0)))
        msg = c.status_message(now)
        if msg:
            blocks.append(([msg], 8, -8))
        if now < c.help_until:
            blocks.append((help_lines(HELP), -8, -8))
        if blocks:
            self.hud.draw(blocks, self.fb_size)
        if swap:
            self.glfw.swap_buffers(self.win)

    def _toggle_fullscreen(self) -> None:
        g = self.glfw
        if self.fullscreen_saved is None:
            mon = g.get_primary_monitor()
            mode = g.get_video_mode(mon) if mon else None
            if mode is None:
                self.controls.say(self.now(), "no monitor for fullscreen")
                return
            self.fullscreen_saved = (*g.get_window_pos(self.win), *g.get_window_size(self.win))
            g.set_window_monitor(self.win, mon, 0, 0, mode.size.width, mode.size.height,
                                 mode.refresh_rate)
        else:
            x, y, w, h = self.fullscreen_saved
            self.fullscreen_saved = None
            g.set_window_monitor(self.win, None, x, y, w, h, 0)

    def snapshot(self) -> np.ndarray:
        """The shown frame as drawn on the window's framebuffer, without the HUD."""
        return self.presenter.snapshot(self.fb_size)

    def snapshot_with_hud(self) -> np.ndarray:
        """The window's framebuffer as drawn (image, HUD and overlays), row 0 on top."""
        self._draw(swap=False)
        w, h = self.fb_size
        data = self.ctx.screen.read(viewport=(0, 0, w, h), components=4, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(h, w, 4)[::-1].copy()

    def save_screenshot(self, path, hud: bool = False) -> Path:
        write_png(path, self.snapshot_with_hud() if hud else self.snapshot())
        self.screenshots.append(Path(path))
        self.controls.say(self.now(), f"saved {path}")
        return Path(path)

    def run(self, frames: int | None = None) -> int:
        while self.step(frames):
            pass
        img = self._drain()
        if img is not None and frames is None:
            self.presenter.upload(img)
        return self.shown

    def event_log(self) -> EventLog:
        q = self.quality
        header = {"window": list(self._start_window), "cells": q.cells, "scale": q.scale,
                  "bounces": q.bounces, "caustics": q.caustics, "photons": q.photons,
                  "spp": self.controls.spp}
        return EventLog(header, list(self.recording or ()))

    def close(self) -> None:
        self.world.close()
        if self.targets is not None:
            self.targets.release()
        self.ctx.release()
        self.glfw.destroy_window(self.win)
        self.glfw.terminate()


def run(args) -> int:
    from app import quality as q
    from app.assemble import caustic_settings
    from app.frames import with_shading
    from app.scene import load_scene
    from kernels import get_runtime

    check_args(args)
    replay = EventLog.load(args.events) if args.events else None
    require_display()
    scene = load_scene(args.scene)
    mode = getattr(args, "caustics", None)
    scene = with_shading(scene, {"caustics": mode} if mode else None)
    caustic_settings(scene)  # a bad mode fails before the window opens
    window_size = parse_size(args.size) if args.size else (scene.render.width,
                                                           scene.render.height)
    rt = get_runtime(args.device)
    frame_seconds = args.frame_time or 1 / 60
    if replay is not None:
        h = replay.header
        window_size = tuple(h.get("window", window_size))
        ca = h.get("caustics")   # files of before 2026-12 wrote false for "off"
        quality = q.Quality(int(h["cells"]), float(h["scale"]), int(h["bounces"]), "replayed",
                            caustics={False: "off", True: "traced"}.get(ca, ca),
                            photons=h.get("photons"))
        spp = int(h.get("spp", 1))
    else:
        def quality(viewer):   # decided once the window is open: the probe shows in it
            return decide_quality(args, scene, rt, window_size, frame_seconds,
                                  present=viewer.present_probe)
        if args.quality != "auto":
            quality = decide_quality(args, scene, rt, window_size, frame_seconds)
        spp = args.spp or (scene.render.spp if scene.render.spp in (1, 2, 4) else 1)
    viewer = Viewer(scene, rt, window_size=window_size, quality=quality, spp=spp,
                    frame_time=args.frame_time, vsync=not args.no_vsync, upload=args.upload,
                    replay=replay, record=bool(args.record_events))
    print(f"lbwater window: {rt.name}; {viewer.quality.describe()}; display {viewer.path}",
          flush=True)
    try:
        t0 = time.perf_counter()
        shown = viewer.run(args.frames)
        elapsed = time.perf_counter() - t0
        if args.screenshot:
            viewer.save_screenshot(args.screenshot, hud=args.screenshot_hud)
        if args.record_events:
            viewer.event_log().write(args.record_events)
        fps = shown / max(elapsed, 1e-9)
        print(f"lbwater window: {shown} frames in {elapsed:.2f} s ({fps:.1f} FPS)", flush=True)
        if getattr(args, "report", None):
            write_report(args.report, viewer, args, shown, elapsed)
    finally:
        viewer.close()
    return 0


def write_report(path, viewer, args, shown: int, elapsed: float) -> None:
    """--report: the run's settings and frame rate as JSON (bench/window_fps.py reads it)."""
    from app.io import write_json

    q = viewer.quality
    write_json(path, {
        "date": time.strftime("%Y-%m-%d %H:%M"), "device": viewer.world.device_name,
        "gl_renderer": viewer.ctx.info["GL_RENDERER"], "display_path": viewer.path,
        "scene": str(args.scene), "window": list(viewer._start_window),
        "image": list(viewer.world.size), "quality": q.describe(), "source": q.source,
        "cells": q.cells, "scale": q.scale, "bounces": q.bounces,
        "caustics": viewer.world.caustics, "photons": q.photons, "target_fps": args.target_fps,
        "predicted_ms": None if q.predicted_ms is None else round(q.predicted_ms, 3),
        "frames": shown, "seconds": round(elapsed, 3),
        "frame_ms": round(1e3 * elapsed / max(1, shown), 3),
        "fps": round(shown / max(elapsed, 1e-9), 2),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None})
