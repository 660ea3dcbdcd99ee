"""``[[timeline]]``: what happens when in a scripted capture, and the inputs of each frame.

Each ``[[timeline]]`` entry has a ``time`` (s of simulated time) and exactly one action:

    [[timeline]]
    time = 0.5
    drop = { x = 1.2, y = 0.9, radius = 0.1, height = 0.03 }   # pool metres, like [[water.drops]]

    [[timeline]]
    time = 1.0
    rain = 25.0                  # drops per second from here on; 0 stops the rain

    [[timeline]]
    time = 2.0                   # a mouse-like drag from (x, y) along (dx, dy) m, spread evenly
    push = { x = 0.5, y = 1.5, dx = 2.0, dy = 0.0, strength = 0.4, duration = 1.0 }  # over 1 s

    [[timeline]]
    time = 0.0                   # camera keyframes: eye/target/fov interpolated smoothly
    camera = { eye = [3.9, 1.7, 4.3], target = [2.0, 0.3, 1.4], fov = 50 }

Camera keyframes are joined by cubic Hermite curves with Catmull-Rom tangents (time-weighted
finite differences, so uneven key spacing does not overshoot in time); before the first key the
first holds, after the last the last. Without camera keys the scene's ``[camera]`` holds.

Frame i of a capture at ``fps`` advances the water from ``t0 = i / fps`` to ``t1 = (i + 1) /
fps``: the drops, rain changes and the share of pushes due in ``[t0, t1)`` are applied at the
start of frame i (so a drop at time T is first seen in frame ``ceil(T * fps)``), and the camera
is the one at ``t1``, the moment the image shows.

    [[timeline]]
    time = 1.0                   # a boat (a [[boats]] name) lifted 0.4 m above the water, held
    boat = { name = "sailboat", position = [1.0, 1.5], height = 0.4, hold = true }

    [[timeline]]
    time = 2.0                   # ... and let go: it falls, splashes and floats
    boat = { name = "sailboat", action = "release" }

A ``place`` puts the boat's centre of mass over pool point ``position`` (m), upright, its keel
``height`` m above the still water (default: afloat at its rest draft), turned ``heading`` deg
(as ``[[boats]] rotation``'s y; default: the heading it has), at rest or moving at ``velocity``
(pool x, y in m/s); ``hold = true`` keeps it there, at rest, until a ``release`` (which may give
it a ``velocity``). Like a drop, a boat entry lands at the start of its frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.errors import InputError
from app.schema import Field, SourceText, validate_table

ENTRY_SCHEMA = {
    "time": Field("float", lo=0.0, hi=1e6, unit="s", doc="when, in simulated seconds"),
    "drop": Field("table", None, doc="a drop: x, y, radius, height (m)"),
    "rain": Field("float", None, lo=0.0, hi=1e5, unit="1/s", doc="rain rate from here on"),
    "push": Field("table", None, doc="a drag: x, y, dx, dy (m), strength (m/s), duration (s)"),
    "camera": Field("table", None, doc="a camera keyframe: eye, target (m), up, fov (deg)"),
    "boat": Field("table", None, doc="a boat placed or released (scenes with boats)"),
}
ACTIONS = ("drop", "rain", "push", "camera", "boat")

DROP_SCHEMA = {
    "x": Field("float", lo=-1e6, hi=1e6, unit="m", doc="centre along the pool's x"),
    "y": Field("float", lo=-1e6, hi=1e6, unit="m", doc="centre along the pool's y"),
    "radius": Field("float", 0.05, lo=0.0, lo_open=True, hi=1e3, unit="m", doc="bump radius"),
    "height": Field("float", 0.01, lo=-100.0, hi=100.0, unit="m", doc="bump height"),
}
PUSH_SCHEMA = {
    "x": Field("float", lo=-1e6, hi=1e6, unit="m", doc="drag start along the pool's x"),
    "y": Field("float", lo=-1e6, hi=1e6, unit="m", doc="drag start along the pool's y"),
    "dx": Field("float", lo=-1e6, hi=1e6, unit="m", doc="drag along x"),
    "dy": Field("float", lo=-1e6, hi=1e6, unit="m", doc="drag along y"),
    "strength": Field("float", 0.3, lo=0.0, hi=100.0, unit="m/s", doc="speed given the water"),
    "duration": Field("float", 0.0, lo=0.0, hi=1e4, unit="s",
                      doc="time the drag takes (0: all at once)"),
}
CAMERA_SCHEMA = {
    "eye": Field("vec3", lo=-1e6, hi=1e6, unit="m", doc="camera position"),
    "target": Field("vec3", lo=-1e6, hi=1e6, unit="m", doc="point looked at"),
    "up": Field("vec3", (0.0, 1.0, 0.0), lo=-1e6, hi=1e6, doc="up direction"),
    "fov": Field("float", None, lo=1.0, hi=179.0, unit="deg", doc="vertical field of view"),
}
BOAT_SCHEMA = {
    "name": Field("str", doc="the boat, as [[boats]] name (default: its file's stem) calls it"),
    "action": Field("str", "place", choices=("place", "release"),
                    doc="place it (position needed), or release a held one"),
    "position": Field("vec2", None, lo=-1e6, hi=1e6, unit="m",
                      doc="pool point (x, y) under its centre of mass (place)"),
    "height": Field("float", None, lo=-100.0, hi=1e4, unit="m",
                    doc="its keel above the still water (place; default: afloat at rest)"),
    "heading": Field("float", None, lo=-360.0, hi=360.0, unit="deg",
                     doc="turn about the vertical, as [[boats]] rotation's y (place; default: "
                         "the heading it has)"),
    "velocity": Field("vec2", None, lo=-100.0, hi=100.0, unit="m/s",
                      doc="its speed along the pool's x, y from then on (default at rest)"),
    "hold": Field("bool", False, doc="place: hold it there (at rest) until a release entry"),
}
_PLACE_ONLY = ("position", "height", "heading", "hold")


@dataclass(frozen=True)
class Drop:
    time: float
    x: float
    y: float
    radius: float
    height: float


@dataclass(frozen=True)
class Rain:
    time: float
    rate: float


@dataclass(frozen=True)
class Push:
    time: float
    x: float
    y: float
    dx: float
    dy: float
    strength: float
    duration: float


@dataclass(frozen=True)
class CameraKey:
    time: float
    eye: tuple
    target: tuple
    up: tuple
    fov: float | None


@dataclass(frozen=True)
class BoatEvent:
    time: float
    name: str
    action: str                  #: place | release
    position: tuple | None       #: pool (x, y) m
    height: float | None = None  #: keel above the still water (m); None: afloat at rest
    heading: float | None = None  #: degrees about the vertical; None: kept
    velocity: tuple | None = None  #: (vx, vy) m/s along the pool's x, y
    hold: bool = False


def parse_timeline(value, src: SourceText, base: Path) -> tuple:
    """``[[timeline]]`` tables -> a tuple of events sorted by time (stable for equal times)."""
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        raise InputError(f"{src.where('timeline')}: use [[timeline]] tables")
    out = []
    for k, t in enumerate(value):
        where = f"timeline entry {k + 1}"
        v = validate_table(t, ENTRY_SCHEMA, "timeline", src)
        given = [a for a in ACTIONS if v[a] is not None]
        if len(given) != 1:
            raise InputError(f"{src.where('timeline')}: {where} (time = {v['time']:g}) needs "
                             f"exactly one of {', '.join(ACTIONS)}; got "
                             f"{', '.join(given) or 'none'}")
        kind, time_s = given[0], v["time"]
        sec = f"timeline.{kind}"
        if kind == "rain":
            out.append(Rain(time_s, v["rain"]))
        elif kind == "drop":
            out.append(Drop(time_s, **validate_table(v["drop"], DROP_SCHEMA, sec, src)))
        elif kind == "push":
            out.append(Push(time_s, **validate_table(v["push"], PUSH_SCHEMA, sec, src)))
        elif kind == "camera":
            c = validate_table(v["camera"], CAMERA_SCHEMA, sec, src)
            if np.allclose(c["eye"], c["target"]):
                raise InputError(f"{src.where('timeline')}: {where} (time = {time_s:g}): "
                                 f"camera target equals eye {c['eye']}")
            out.append(CameraKey(time_s, c["eye"], c["target"], c["up"], c["fov"]))
        else:
            b = validate_table(v["boat"], BOAT_SCHEMA, sec, src)
            if b["action"] == "place" and b["position"] is None:
                raise InputError(f"{src.where('timeline')}: {where} (time = {time_s:g}): boat "
                                 f"{b['name']!r}: place needs a position = [x, y] (pool m)")
            extra = [k for k in _PLACE_ONLY if b["action"] == "release"
                     and b[k] not in (None, False)]
            if extra:
                raise InputError(f"{src.where('timeline')}: {where} (time = {time_s:g}): boat "
                                 f"{b['name']!r}: release takes no {extra[0]} (only velocity)")
            out.append(BoatEvent(time_s, **b))
    return tuple(sorted(out, key=lambda e: e.time))


def check_timeline(scene) -> None:
    """Entries that need the rest of the scene: points inside the pool, water for water
    actions, boats that exist. One-line InputError naming the file and the entry."""
    events = getattr(scene, "timeline", ()) or ()
    w = scene.water
    held: dict[str, bool] = {}   # boat name -> held now (events are sorted by time)
    for e in events:
        where = f"{scene.path}: [[timeline]] time = {e.time:g}"
        if isinstance(e, Drop | Rain | Push) and w is None:
            raise InputError(f"{where}: {type(e).__name__.lower()} needs a [water] section")
        if isinstance(e, Drop | Push):
            sx, sy = w.size
            pts = [(e.x, e.y)] + ([(e.x + e.dx, e.y + e.dy)] if isinstance(e, Push) else [])
            for x, y in pts:
                if not (0 <= x <= sx and 0 <= y <= sy):
                    raise InputError(f"{where}: point ({x:g}, {y:g}) m is outside the pool "
                                     f"[0, {sx:g}] x [0, {sy:g}] m")
        if isinstance(e, BoatEvent):
            boats = getattr(scene, "boats", None)
            names = [b.name for b in boats] if boats else []
            if e.name not in names:
                raise InputError(f"{where}: boat {e.name!r} is not in the scene (boats: "
                                 f"{', '.join(names) or 'none'})")
            if e.position is not None:
                x, y = e.position
                sx, sy = w.size
                if not (0 <= x <= sx and 0 <= y <= sy):
                    raise InputError(f"{where}: boat {e.name!r} position ({x:g}, {y:g}) m is "
                                     f"outside the pool [0, {sx:g}] x [0, {sy:g}] m")
            if e.action == "release" and not held.get(e.name, False):
                raise InputError(f"{where}: boat {e.name!r} is released but not held (place it "
                                 "with hold = true first)")
            held[e.name] = e.action == "place" and e.hold


@dataclass
class FrameInputs:
    """What to apply before one frame: drops (x, y, radius, height), pushes (x, y, dx, dy,
    strength), the rain rate if it changes, the camera (eye, target, up, fov) and boat events."""

    drops: list
    pushes: list
    rain: float | None
    camera: tuple
    boats: list


def _hermite(keys: list[CameraKey], t: float, attr: str) -> np.ndarray:
    """Cubic Hermite through the keys' ``attr`` at time t, Catmull-Rom tangents."""
    ts = np.array([k.time for k in keys])
    ps = np.array([np.atleast_1d(getattr(k, attr)) for k in keys], dtype=np.float64)
    if t <= ts[0]:
        return ps[0]
    if t >= ts[-1]:
        return ps[-1]
    i = int(np.searchsorted(ts, t, side="right") - 1)
    t0, t1 = ts[i], ts[i + 1]
    h = t1 - t0
    if h <= 0:
        return ps[i + 1]

    def tangent(j):   # dP/dt at key j: centred over its neighbours, one-sided at the ends
        lo, hi = max(j - 1, 0), min(j + 1, len(ts) - 1)
        dt = ts[hi] - ts[lo]
        return (ps[hi] - ps[lo]) / dt if dt > 0 else np.zeros_like(ps[j])

    s = (t - t0) / h
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * ps[i] + h10 * h * tangent(i) + h01 * ps[i + 1] + h11 * h * tangent(i + 1)


class Timeline:
    """A scene's timeline turned into per-frame inputs at ``fps`` frames per second."""

    def __init__(self, scene, fps: float):
        if not (math.isfinite(fps) and fps > 0):
            raise InputError(f"--fps {fps} must be > 0")
        check_timeline(scene)
        self.fps = float(fps)
        self.events = tuple(getattr(scene, "timeline", ()) or ())
        c = scene.camera
        self._default_camera = (tuple(c.eye), tuple(c.target), tuple(c.up), float(c.fov))
        self._keys = [e for e in self.events if isinstance(e, CameraKey)]
        for k in self._keys:   # keys without fov keep the scene's
            if k.fov is None:
                i = self._keys.index(k)
                self._keys[i] = CameraKey(k.time, k.eye, k.target, k.up, float(c.fov))

    @property
    def duration(self) -> float:
        """Time of the last event (pushes: their end), 0 without events."""
        ends = [e.time + (e.duration if isinstance(e, Push) else 0.0) for e in self.events]
        return max(ends, default=0.0)

    def camera_at(self, t: float) -> tuple:
        """(eye, target, up, fov) at time t."""
        if not self._keys:
            return self._default_camera
        eye = _hermite(self._keys, t, "eye")
        target = _hermite(self._keys, t, "target")
        up = _hermite(self._keys, t, "up")
        fov = float(np.clip(_hermite(self._keys, t, "fov")[0], 1.0, 179.0))
        if np.allclose(eye, target):   # an overshoot cannot put the eye on the target
            target = eye + np.asarray(self._keys[0].target) - np.asarray(self._keys[0].eye)
        return tuple(eye.tolist()), tuple(target.tolist()), tuple(up.tolist()), fov

    def frame_inputs(self, index: int) -> FrameInputs:
        """The inputs to apply before frame ``index`` (water from index/fps to (index+1)/fps)."""
        t0, t1 = index / self.fps, (index + 1) / self.fps
        drops, pushes, boats, rain = [], [], [], None
        for e in self.events:
            if isinstance(e, Push):
                pushes += self._push_share(e, t0, t1)
            elif not (t0 <= e.time < t1):
                continue
            elif isinstance(e, Drop):
                drops.append((e.x, e.y, e.radius, e.height))
            elif isinstance(e, Rain):
                rain = e.rate
            elif isinstance(e, BoatEvent):
                boats.append(e)
        return FrameInputs(drops, pushes, rain, self.camera_at(t1), boats)

    @staticmethod
    def _push_share(e: Push, t0: float, t1: float) -> list:
        """The part of a drag that falls in [t0, t1): one segment (x, y, dx, dy, strength)."""
        if e.duration <= 0:
            return [(e.x, e.y, e.dx, e.dy, e.strength)] if t0 <= e.time < t1 else []
        a = max(t0, e.time)
        b = min(t1, e.time + e.duration)
        if b <= a:
            return []
        fa, fb = (a - e.time) / e.duration, (b - e.time) / e.duration
        return [(e.x + fa * e.dx, e.y + fa * e.dy, (fb - fa) * e.dx, (fb - fa) * e.dy,
                 e.strength)]

    def apply(self, world, index: int) -> FrameInputs:
        """Give ``world`` (the frame API) the inputs of frame ``index``; returns them."""
        fi = self.frame_inputs(index)
        for d in fi.drops:
            world.add_drop(*d)
        for p in fi.pushes:
            world.push(*p)
        if fi.rain is not None:
            world.set_rain(fi.rain)
        for b in fi.boats:
            v = b.velocity
            if b.action == "place":
                world.place_boat(b.name, *b.position, height=b.height, heading=b.heading,
                                 velocity=v or (0.0, 0.0), hold=b.hold)
            else:
                world.release_boat(b.name, velocity=v)
        if self._keys:
            world.set_camera(*fi.camera)
        return fi
