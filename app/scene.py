"""Scene files: TOML (tomllib) loaded into validated, immutable specs in SI units.

A scene has these sections (each key documented in its schema below, units in brackets):

``[scene]``  name and description.
``[render]`` image size, samples per pixel, bounces.
``[camera]`` eye, target, up, vertical field of view.
``[water]``  the pool's shallow-water grid: size, cells, still depth, walls, viscosity, rain, drops.

Other components add their sections to :data:`SECTIONS` (lights, materials, meshes, sky, ...).
Every error is one line naming the file, the line where it can be found, the section, the key, the
value and the rule (see :mod:`app.schema`).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from app.errors import InputError
from app.schema import Field, SourceText, validate_table

SCENE_SCHEMA = {
    "name": Field("str", "", doc="a short title"),
    "description": Field("str", "", doc="free text"),
}

RENDER_SCHEMA = {
    "width": Field("int", 1280, lo=1, hi=16384, unit="px", doc="image width"),
    "height": Field("int", 720, lo=1, hi=16384, unit="px", doc="image height"),
    "spp": Field("int", 1, lo=1, hi=4096, doc="samples (rays) per pixel"),
    "bounces": Field("int", 5, lo=0, hi=32, doc="maximum reflection/refraction depth"),
}

CAMERA_SCHEMA = {
    "eye": Field("vec3", (0.0, 2.0, -3.0), unit="m", doc="camera position"),
    "target": Field("vec3", (0.0, 0.0, 0.0), unit="m", doc="point looked at"),
    "up": Field("vec3", (0.0, 1.0, 0.0), doc="up direction (Y is up)"),
    "fov": Field("float", 60.0, lo=1.0, hi=179.0, unit="deg", doc="vertical field of view"),
}

RAIN_SCHEMA = {
    "rate": Field("float", 0.0, lo=0.0, hi=1e5, unit="1/s", doc="drops per second"),
    "radius": Field("float", 0.03, lo=0.0, lo_open=True, hi=100.0, unit="m", doc="drop radius"),
    "height": Field("float", 0.005, lo=-10.0, hi=10.0, unit="m", doc="drop height"),
    "seed": Field("int", 1, lo=0, hi=2**63 - 1, doc="random seed (deterministic rain)"),
}

DROP_SCHEMA = {
    "x": Field("float", lo=-1e6, hi=1e6, unit="m", doc="centre along the pool's x"),
    "y": Field("float", lo=-1e6, hi=1e6, unit="m", doc="centre along the pool's y (world z)"),
    "radius": Field("float", 0.05, lo=0.0, lo_open=True, hi=1e3, unit="m", doc="bump radius"),
    "height": Field("float", 0.01, lo=-100.0, hi=100.0, unit="m", doc="bump height"),
}

WATER_SCHEMA = {
    "size": Field("vec2", (2.0, 2.0), lo=0.0, lo_open=True, hi=1e6, unit="m",
                  doc="pool interior along x and y (world x and z)"),
    "cells": Field("ivec2", (256, 256), lo=2, hi=16384, doc="grid cells along x and y"),
    "depth": Field("float", 0.3, lo=0.0, lo_open=True, hi=1e4, unit="m", doc="still depth"),
    "boundary": Field("str", "slip", choices=("slip", "noslip"),
                      doc="walls: slip (specular) or noslip (bounce-back)"),
    "viscosity": Field("float", 1e-4, lo=0.0, hi=1e3, unit="m^2/s",
                       doc="kinematic (eddy) viscosity: larger makes waves fade faster"),
    "expected_speed": Field("float", 0.5, lo=0.0, lo_open=True, hi=1e3, unit="m/s",
                            doc="largest flow speed expected, used to choose the time step"),
    "origin": Field("vec3", (0.0, 0.0, 0.0), lo=-1e6, hi=1e6, unit="m",
                    doc="world position of the pool's corner at bed level"),
    "rain": Field("table", None, doc="rain, see [water.rain]"),
    "drops": Field("tables", (), doc="initial drops, [[water.drops]]"),
}


@dataclass(frozen=True)
class RainSpec:
    rate: float
    radius: float
    height: float
    seed: int


@dataclass(frozen=True)
class DropSpec:
    x: float
    y: float
    radius: float
    height: float


@dataclass(frozen=True)
class WaterSpec:
    """The pool's water grid in SI units; ``dx`` is the cell size (square cells)."""

    size: tuple[float, float]
    cells: tuple[int, int]
    depth: float
    boundary: str
    viscosity: float
    expected_speed: float
    origin: tuple[float, float, float]
    rain: RainSpec | None
    drops: tuple[DropSpec, ...]

    @property
    def dx(self) -> float:
        return self.size[0] / self.cells[0]


@dataclass(frozen=True)
class RenderSpec:
    width: int
    height: int
    spp: int
    bounces: int


@dataclass(frozen=True)
class CameraSpec:
    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float]
    fov: float


@dataclass(frozen=True)
class Scene:
    """A validated scene. ``extra`` holds sections added by other components, by name."""

    path: Path
    name: str
    description: str
    render: RenderSpec
    camera: CameraSpec
    water: WaterSpec | None
    extra: dict = field(default_factory=dict)


def _water(table: dict, src: SourceText) -> WaterSpec:
    v = validate_table(table, WATER_SCHEMA, "water", src)
    nx, ny = v["cells"]
    sx, sy = v["size"]
    if abs(sx / nx - sy / ny) > 1e-6 * max(sx / nx, sy / ny):
        raise InputError(f"{src.where('water', 'cells')}: cells {nx}x{ny} over size "
                         f"{sx:g}x{sy:g} m give non-square cells ({sx / nx:g} m vs "
                         f"{sy / ny:g} m); make size/cells equal on both axes")
    rain = None
    if v["rain"] is not None:
        rain = RainSpec(**validate_table(v["rain"], RAIN_SCHEMA, "water.rain", src))
    drops = []
    for d in v["drops"]:
        drop = DropSpec(**validate_table(d, DROP_SCHEMA, "water.drops", src))
        if not (0 <= drop.x <= sx and 0 <= drop.y <= sy):
            raise InputError(f"{src.where('water.drops', 'x')}: drop at ({drop.x:g}, {drop.y:g}) m "
                             f"is outside the pool [0, {sx:g}] x [0, {sy:g}] m")
        drops.append(drop)
    return WaterSpec(size=(sx, sy), cells=(nx, ny), depth=v["depth"], boundary=v["boundary"],
                     viscosity=v["viscosity"], expected_speed=v["expected_speed"],
                     origin=v["origin"], rain=rain, drops=tuple(drops))


#: Extra top-level sections: name -> parser(value, SourceText, base_dir) -> parsed object.
#: Components register theirs here (for example lights, materials, meshes, sky).
SECTIONS: dict = {}

_CORE = ("scene", "render", "camera", "water")


def parse_scene(text: str, path: Path) -> Scene:
    """Validate TOML ``text`` as a scene; ``path`` names it in errors and anchors relative paths."""
    src = SourceText(path, text)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    valid = sorted(_CORE + tuple(SECTIONS))
    for key in data:
        if key not in valid:
            line = src.line_of(key)
            loc = f"{path}:{line}" if line else str(path)
            raise InputError(f"{loc}: unknown section or key {key!r}; valid: {', '.join(valid)}")
    meta = validate_table(data.get("scene", {}), SCENE_SCHEMA, "scene", src)
    render = RenderSpec(**validate_table(data.get("render", {}), RENDER_SCHEMA, "render", src))
    camera = CameraSpec(**validate_table(data.get("camera", {}), CAMERA_SCHEMA, "camera", src))
    if camera.eye == camera.target:
        raise InputError(f"{src.where('camera', 'target')}: target equals eye {camera.eye}")
    water = _water(data["water"], src) if "water" in data else None
    extra = {name: parser(data[name], src, path.parent)
             for name, parser in SECTIONS.items() if name in data}
    return Scene(path=path, name=meta["name"] or path.stem, description=meta["description"],
                 render=render, camera=camera, water=water, extra=extra)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; errors name the file, line, key and rule."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: scene file does not exist")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read scene file ({exc})") from None
    return parse_scene(text, path)
