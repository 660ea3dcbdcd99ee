"""Input for the window: an orbit camera, the drag modes and the keyboard actions, with no GL and
no glfw in sight so that tests drive it exactly as a user's events do.

The window turns glfw callbacks into calls on :class:`Controls` (``mouse_button``, ``cursor``,
``scroll``, ``action``, ``resize``); an event file replays the same calls at the same frame
indices. Once per frame the window calls :meth:`Controls.apply`, which hands the world what the
input asked for (camera, drops, pushes, rain) and returns the requests only the window can carry
out (rebuild at new settings, screenshot, fullscreen, quit).
"""

from __future__ import annotations

import dataclasses
import math
from enum import IntEnum

import numpy as np


class DragMode(IntEnum):
    """What a held mouse button does while the cursor moves."""

    NONE = 0
    RIPPLE = 1   #: left drag on the water: drops where the mouse ray meets the water
    PUSH = 2     #: Shift + left drag on the water: push the water along the drag
    ORBIT = 3    #: left drag off the water: turn the camera around its target
    PAN = 4      #: right drag: move the target in the view plane


class Button(IntEnum):
    LEFT = 0
    RIGHT = 1
    MIDDLE = 2


class Action(IntEnum):
    """Keyboard commands (the window maps keys to these; event files store their names)."""

    QUIT = 0
    TOGGLE_RAIN = 1
    RAIN_LESS = 2
    RAIN_MORE = 3
    PAUSE = 4
    STEP = 5
    DROP_BOAT = 6
    BOUNCES_UP = 7
    BOUNCES_DOWN = 8
    SPP_1 = 9
    SPP_2 = 10
    SPP_4 = 11
    GRID_UP = 12
    GRID_DOWN = 13
    SCREENSHOT = 14
    TOGGLE_CAUSTICS = 15
    TOGGLE_HELP = 16
    FULLSCREEN = 17
    TOGGLE_HUD = 18

    @classmethod
    def from_str(cls, name: str) -> Action:
        try:
            return cls[str(name).upper()]
        except KeyError:
            valid = ", ".join(m.name.lower() for m in cls)
            raise ValueError(f"unknown action {name!r}; valid: {valid}") from None


#: The help overlay's text: key, what it does.
HELP = (
    ("drag water", "ripples where the mouse ray meets the water"),
    ("Shift+drag", "push the water along the drag"),
    ("drag elsewhere", "orbit the camera"),
    ("right drag / wheel", "pan / zoom"),
    ("R  [  ]", "rain on/off, less/more rain"),
    ("Space  N", "pause, one step while paused"),
    ("B", "drop a boat above the cursor"),
    ("+  -", "more / fewer bounces"),
    ("1  2  4", "samples per pixel"),
    ("G  Shift+G", "finer / coarser water grid"),
    ("S", "screenshot (PNG)"),
    ("C", "caustics on/off"),
    ("H  F2", "this help, HUD on/off"),
    ("F  Esc", "fullscreen, quit"),
)

RAIN_RATE_DEFAULT = 20.0          #: drops per second when R turns rain on
RAIN_RATE_LIMITS = (1.0, 2000.0)
BOUNCE_LIMITS = (0, 8)
GRID_FACTOR = 1.5                 #: G multiplies the cells along the pool's longer side by this
GRID_LIMITS = (16, 4096)
PUSH_SPEED = 0.3                  #: m/s given to the water along a Shift-drag
HELP_SECONDS = 6.0                #: the help overlay shows this long at start


# ---- camera math (pure) -----------------------------------------------------------------------
def camera_basis(eye, target, up, fov: float, width: int, height: int):
    """The renderer's pinhole camera: (forward, right, up) scaled as the ray generator uses
    them (``right`` by tan(fov/2) * aspect, ``up`` by tan(fov/2)), float64."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    fwd = target - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, fwd)
    th = math.tan(math.radians(fov) / 2)
    return fwd, right * th * width / height, true_up * th


def pixel_ray(eye, target, up, fov: float, width: int, height: int, px: float, py: float):
    """The ray through image point (px, py) (pixels from the top-left corner; a pixel's centre
    is at +0.5): (origin, unit direction), as the renderer's primary ray generator makes it."""
    fwd, right, true_up = camera_basis(eye, target, up, fov, width, height)
    sx = 2.0 * px / width - 1.0
    sy = 1.0 - 2.0 * py / height
    d = fwd + sx * right + sy * true_up
    return np.asarray(eye, np.float64), d / np.linalg.norm(d)


@dataclasses.dataclass
class OrbitCamera:
    """A camera turning around ``target`` at ``distance`` (m); yaw about +Y, pitch above the
    horizon (radians), vertical field of view ``fov`` (degrees). Y is up."""

    target: tuple = (0.0, 0.0, 0.0)
    distance: float = 1.0
    yaw: float = 0.0
    pitch: float = 0.3
    fov: float = 50.0
    min_distance: float = 0.05
    max_distance: float = 1e3

    PITCH_LIMIT = math.radians(89.0)
    ORBIT_RAD_PER_PX = 0.006
    ZOOM_PER_STEP = 0.9

    @classmethod
    def from_look(cls, eye, target, fov: float = 50.0) -> OrbitCamera:
        eye, target = np.asarray(eye, np.float64), np.asarray(target, np.float64)
        d = eye - target
        dist = float(np.linalg.norm(d))
        if not dist > 0:
            raise ValueError("camera eye equals its target")
        pitch = math.asin(max(-1.0, min(1.0, d[1] / dist)))
        yaw = math.atan2(d[0], d[2])
        return cls(tuple(float(c) for c in target), dist, yaw,
                   max(-cls.PITCH_LIMIT, min(cls.PITCH_LIMIT, pitch)), float(fov),
                   min_distance=dist * 1e-3, max_distance=dist * 1e2)

    @property
    def eye(self) -> tuple:
        cp = math.cos(self.pitch)
        off = (cp * math.sin(self.yaw), math.sin(self.pitch), cp * math.cos(self.yaw))
        return tuple(t + self.distance * o for t, o in zip(self.target, off, strict=True))

    def look(self) -> tuple:
        """(eye, target, up, fov) for ``World.set_camera``."""
        return self.eye, tuple(self.target), (0.0, 1.0, 0.0), self.fov

    def orbit(self, dx_px: float, dy_px: float) -> None:
        """Turn by a cursor move of (dx, dy) pixels: right turns the view left-to-right (the
        scene seems to follow the cursor), down raises the camera."""
        self.yaw -= dx_px * self.ORBIT_RAD_PER_PX
        self.pitch = max(-self.PITCH_LIMIT,
                         min(self.PITCH_LIMIT, self.pitch + dy_px * self.ORBIT_RAD_PER_PX))

    def pan(self, dx_px: float, dy_px: float, height_px: int) -> None:
        """Move the target so the point under the cursor follows it (at the target's depth)."""
        eye = np.asarray(self.eye)
        _, right, up = camera_basis(eye, self.target, (0, 1, 0), self.fov, 1, 1)
        right /= np.linalg.norm(right)
        up /= np.linalg.norm(up)
        m_per_px = 2.0 * self.distance * math.tan(math.radians(self.fov) / 2) / max(1, height_px)
        t = np.asarray(self.target) + m_per_px * (-dx_px * right + dy_px * up)
        self.target = tuple(float(c) for c in t)

    def zoom(self, steps: float) -> None:
        """Wheel steps: positive moves closer (each step 10%)."""
        self.distance = max(self.min_distance,
                            min(self.max_distance, self.distance * self.ZOOM_PER_STEP ** steps))


# ---- the input state machine ------------------------------------------------------------------
@dataclasses.dataclass
class Requests:
    """What :meth:`Controls.apply` asks the window to do this frame."""

    rebuild: dict = dataclasses.field(default_factory=dict)  #: World keywords to change
    screenshot: bool = False
    fullscreen: bool = False
    quit: bool = False


@dataclasses.dataclass
class Water:
    """Where the water lies: pool corner ``origin`` (world m, bed level), ``size`` (x, z extent,
    m), still ``depth`` (m), and ``dx`` (m per cell): what ripples are sized by."""

    origin: tuple
    size: tuple
    depth: float
    dx: float


class Controls:
    """Mouse and keyboard state; see the module docstring. Positions are window pixels from the
    top-left corner; ``window_size`` and ``image_size`` map them onto image pixels."""

    def __init__(self, camera: OrbitCamera, water: Water | None, *, spp: int = 1,
                 bounces: int = 2, cells: int | None = None, window_size=(1, 1),
                 image_size=(1, 1), frame_time: float = 1 / 60):
        self.camera = camera
        self.water = water
        self.spp, self.bounces, self.cells = spp, bounces, cells
        self.window_size, self.image_size = tuple(window_size), tuple(image_size)
        self.frame_time = frame_time
        self.drag = DragMode.NONE
        self.shift = False
        self.cursor_pos = (0.0, 0.0)
        self._last = (0.0, 0.0)          # cursor at the last orbit/pan/drop
        self._last_pool: tuple | None = None
        self._moved = False
        self._camera_dirty = False       # the world starts with the scene's camera
        self.paused = False
        self._step = False
        self.rain_on = False
        self.rain_rate = RAIN_RATE_DEFAULT
        self._rain_dirty = False
        #: the user's caustics mode ("off" | "traced", as ``World.caustics``); None: the
        #: world's own (the scene's) setting. A rebuilt world gets it in :meth:`reapply`.
        self.caustics: str | None = None
        self.help_until = HELP_SECONDS   # seconds of wall time since the start
        self.show_hud = True
        self.message = ""
        self._requests = Requests()
        self.drops = 0                   # ripples made (for the HUD and tests)

    # -- geometry ---------------------------------------------------------------------------
    def image_point(self, x: float, y: float) -> tuple[float, float]:
        """Window pixel (x, y) -> image pixel coordinates (the image fills the window)."""
        (ww, wh), (iw, ih) = self.window_size, self.image_size
        return x * iw / max(1, ww), y * ih / max(1, wh)

    def _pick_pool(self, world, x: float, y: float):
        """Pool coordinates (m) of the water under window pixel (x, y), or None."""
        if self.water is None:
            return None
        p = world.pick(*self.image_point(x, y))
        return p.pool_xy if p is not None and p.water else None

    # -- events (the same calls live input and replay make) ---------------------------------
    def mouse_button(self, world, button: Button, pressed: bool, shift: bool = False) -> None:
        button = Button(button)
        self.shift = bool(shift)
        if not pressed:
            self.drag = DragMode.NONE
            self._last_pool = None
            return
        self._last = self.cursor_pos
        if button == Button.RIGHT:
            self.drag = DragMode.PAN
            return
        if button != Button.LEFT:
            return
        hit = self._pick_pool(world, *self.cursor_pos)
        if hit is None:
            self.drag = DragMode.ORBIT
            return
        self.drag = DragMode.PUSH if shift else DragMode.RIPPLE
        self._last_pool = hit
        if self.drag == DragMode.RIPPLE:
            self._ripple(world, hit)

    def cursor(self, world, x: float, y: float) -> None:
        dx, dy = x - self._last[0], y - self._last[1]
        self.cursor_pos = (float(x), float(y))
        if self.drag == DragMode.ORBIT:
            self.camera.orbit(dx, dy)
            self._camera_dirty = True
        elif self.drag == DragMode.PAN:
            self.camera.pan(dx, dy, self.window_size[1])
            self._camera_dirty = True
        elif self.drag in (DragMode.RIPPLE, DragMode.PUSH):
            hit = self._pick_pool(world, x, y)
            if hit is not None and self._last_pool is not None:
                x0, y0 = self._last_pool
                if self.drag == DragMode.PUSH:
                    world.push(x0, y0, hit[0] - x0, hit[1] - y0, PUSH_SPEED)
                    self._last_pool = hit
                elif math.hypot(hit[0] - x0, hit[1] - y0) >= 0.5 * self._ripple_radius():
                    self._ripple(world, hit)   # drops half a radius apart along the drag
                    self._last_pool = hit
            elif hit is not None:
                self._last_pool = hit
        self._last = self.cursor_pos

    def scroll(self, world, dy: float) -> None:
        self.camera.zoom(dy)
        self._camera_dirty = True

    def resize(self, world, width: int, height: int, image_size=None) -> None:
        """The window's framebuffer is now width x height (pixels)."""
        self.window_size = (int(width), int(height))
        if image_size is not None:
            self.image_size = tuple(image_size)

    def action(self, world, action: Action, now: float = 0.0) -> None:
        a, r = Action(action), self._requests
        if a == Action.QUIT:
            r.quit = True
        elif a == Action.TOGGLE_RAIN:
            self.rain_on = not self.rain_on
            self._rain_dirty = True
            self.say(now, f"rain {'on' if self.rain_on else 'off'}: {self.rain_rate:g} drops/s")
        elif a in (Action.RAIN_LESS, Action.RAIN_MORE):
            f = 1.5 if a == Action.RAIN_MORE else 1 / 1.5
            lo, hi = RAIN_RATE_LIMITS
            self.rain_rate = round(max(lo, min(hi, self.rain_rate * f)), 2)
            self._rain_dirty = self.rain_on
            self.say(now, f"rain rate {self.rain_rate:g} drops/s")
        elif a == Action.PAUSE:
            self.paused = not self.paused
            self.say(now, "paused (N: one step)" if self.paused else "running")
        elif a == Action.STEP:
            self._step = self.paused
        elif a == Action.DROP_BOAT:
            self._drop_boat(world, now)
        elif a in (Action.BOUNCES_UP, Action.BOUNCES_DOWN):
            lo, hi = BOUNCE_LIMITS
            b = max(lo, min(hi, self.bounces + (1 if a == Action.BOUNCES_UP else -1)))
            if b != self.bounces:
                self.bounces = r.rebuild["bounces"] = b
            self.say(now, f"bounces {self.bounces}")
        elif a in (Action.SPP_1, Action.SPP_2, Action.SPP_4):
            s = {Action.SPP_1: 1, Action.SPP_2: 2, Action.SPP_4: 4}[a]
            if s != self.spp:
                self.spp = r.rebuild["spp"] = s
            self.say(now, f"{self.spp} samples per pixel")
        elif a in (Action.GRID_UP, Action.GRID_DOWN) and self.cells is not None:
            lo, hi = GRID_LIMITS
            f = GRID_FACTOR if a == Action.GRID_UP else 1 / GRID_FACTOR
            c = max(lo, min(hi, round(self.cells * f)))
            if c != self.cells:
                self.cells = r.rebuild["cells"] = c
            self.say(now, f"water grid {self.cells} cells along the pool")
        elif a == Action.SCREENSHOT:
            r.screenshot = True
        elif a == Action.TOGGLE_CAUSTICS:
            self._toggle_caustics(world, now)
        elif a == Action.TOGGLE_HELP:
            self.help_until = 0.0 if self.help_until > now else float("inf")
        elif a == Action.TOGGLE_HUD:
            self.show_hud = not self.show_hud
        elif a == Action.FULLSCREEN:
            r.fullscreen = True

    def _toggle_caustics(self, world, now: float) -> None:
        """C: traced caustics on or off, where the world has them."""
        from app.errors import InputError

        if not hasattr(world, "set_caustics"):
            self.say(now, "caustics are not in this build")
            return
        mode = "off" if getattr(world, "caustics", "off") != "off" else "traced"
        try:
            world.set_caustics(mode)
        except InputError as exc:
            self.say(now, str(exc))
            return
        self.caustics = mode
        self.say(now, f"caustics {mode}")

    def _drop_boat(self, world, now: float) -> None:
        """B: a boat falls from above the cursor, where the world has boats (a hook)."""
        drop = getattr(world, "drop_boat", None)
        hit = self._pick_pool(world, *self.cursor_pos)
        if drop is None:
            self.say(now, "no floating boats in this build")
        elif hit is None:
            self.say(now, "point at the water to drop a boat")
        else:
            from app.errors import InputError

            try:
                drop(*hit)
            except InputError as exc:   # a scene without boats, say: the reason, no crash
                self.say(now, str(exc))
                return
            self.say(now, "boat dropped")

    def _ripple_radius(self) -> float:
        return max(3.0 * self.water.dx, 0.015 * max(self.water.size))

    def _ripple(self, world, pool_xy) -> None:
        world.add_drop(pool_xy[0], pool_xy[1], self._ripple_radius(), 0.05 * self.water.depth)
        self.drops += 1

    def say(self, now: float, text: str) -> None:
        self.message, self._message_until = text, now + 3.0

    def status_message(self, now: float) -> str:
        return self.message if now < getattr(self, "_message_until", 0.0) else ""

    # -- once per frame ---------------------------------------------------------------------
    def frame_seconds(self, seconds: float) -> float:
        """Simulated seconds for the next frame: 0 while paused, except after N."""
        if not self.paused:
            return seconds
        if self._step:
            self._step = False
            return seconds
        return 0.0

    def apply(self, world) -> Requests:
        """Hand the world the camera and rain the input asked for; return the window's jobs."""
        if self._camera_dirty:
            world.set_camera(*self.camera.look())
            self._camera_dirty = False
        if self._rain_dirty:
            world.set_rain(self.rain_rate if self.rain_on else 0.0)
            self._rain_dirty = False
        r, self._requests = self._requests, Requests()
        return r

    def reapply(self, world, camera: bool = True) -> None:
        """Give a new world the camera (unless ``camera`` is False: it has the scene's),
        rain and caustics; they reach it with the next :meth:`apply`."""
        self._camera_dirty = self._camera_dirty or camera
        self._rain_dirty = self.rain_on
        if self.caustics is not None and getattr(world, "caustics", None) != self.caustics:
            world.set_caustics(self.caustics)
