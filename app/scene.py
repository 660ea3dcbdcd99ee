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
    "viscosity": Field("float", 1e-4, lo=0.0, lo_open=True, hi=1e3, unit="m^2/s",
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


#: Top-level sections beyond the core: name -> parser(value, SourceText, base_dir) -> the typed
#: value stored in the :class:`Scene` field of that name (lights, materials, meshes, sky, ...).
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
    sections = {name: parser(data[name], src, path.parent)
                for name, parser in SECTIONS.items() if name in data}
    return Scene(path=path, name=meta["name"] or path.stem, description=meta["description"],
                 render=render, camera=camera, water=water, **sections)


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


# ---- renderer sections: [shading], [sky], [[lights]], [materials.NAME], [[meshes]], [pool] ------
# Registered in SECTIONS; parsed values land in the Scene field of the section's name.

SHADING_SCHEMA = {
    "pattern": Field("str", "auto", choices=("auto", "center", "rgss", "jittered"),
                     doc="samples in a pixel: auto = center for 1 spp, rgss for 4, else jittered"),
    "order": Field("str", "tiles", choices=("tiles", "rows"), doc="primary ray order"),
    "fresnel": Field("str", "exact", choices=("exact", "schlick"), doc="Fresnel reflectance"),
    "tonemap": Field("str", "aces", choices=("clamp", "reinhard", "aces"), doc="tonemap curve"),
    "exposure": Field("float", 1.0, lo=0.0, lo_open=True, hi=1e4, doc="radiance multiplier"),
    "min_contribution": Field("float", 1e-3, lo=0.0, hi=0.5,
                              doc="secondary rays below this share of a pixel are cut"),
    "ambient": Field("vec3", (0.05, 0.05, 0.05), lo=0.0, hi=1e3, doc="ambient light, rgb"),
    "seed": Field("int", 0, lo=0, hi=2**32 - 1, doc="jitter seed"),
    "caustics": Field("str", "off", choices=("off", "traced", "projected"),
                      doc="sunlight through the water onto the pool: off (shadow rays through "
                          "the water), traced (photons); projected is not implemented"),
    "caustic_photons": Field("int", 131072, lo=1, hi=2**26,
                             doc="photons per frame per directional light, over the water"),
    "caustic_resolution": Field("int", 256, lo=2, hi=8192,
                                doc="caustic map texels along the pool floor's longer side"),
    "caustic_filter": Field("int", 1, lo=0, hi=16, doc="tent filter radius (texels)"),
    "caustic_blend": Field("float", 0.5, lo=0.0, hi=0.99,
                           doc="weight of the last frame's caustic map (temporal smoothing)"),
}

SKY_SCHEMA = {
    "kind": Field("str", "procedural", choices=("procedural", "cubemap"),
                  doc="procedural gradient with sun, or six cubemap images"),
    "zenith": Field("vec3", (0.25, 0.45, 0.85), lo=0.0, hi=1e4, doc="colour overhead, rgb"),
    "horizon": Field("vec3", (0.75, 0.85, 0.95), lo=0.0, hi=1e4, doc="colour at the horizon"),
    "ground": Field("vec3", (0.35, 0.33, 0.3), lo=0.0, hi=1e4, doc="colour below the horizon"),
    "sun_direction": Field("vec3", (0.4, 0.8, 0.45), lo=-1e6, hi=1e6,
                           doc="towards the sun (need not be unit)"),
    "sun_color": Field("vec3", (30.0, 28.0, 24.0), lo=0.0, hi=1e6, doc="sun disk radiance"),
    "sun_radius": Field("float", 0.6, lo=0.0, hi=45.0, unit="deg", doc="sun angular radius"),
    "sun_glow": Field("float", 0.02, lo=0.0, hi=100.0, doc="halo strength around the sun"),
    "cubemap": Field("table", None, doc="six image paths: px nx py ny pz nz"),
}

LIGHT_SCHEMA = {
    "kind": Field("str", "directional", choices=("directional", "spot"), doc="light kind"),
    "direction": Field("vec3", (-0.4, -0.8, -0.45), lo=-1e6, hi=1e6,
                       doc="direction the light travels"),
    "color": Field("vec3", (1.0, 1.0, 1.0), lo=0.0, hi=1e6,
                   doc="irradiance (directional) or intensity (spot, falls off as 1/d^2)"),
    "position": Field("vec3", (0.0, 0.0, 0.0), lo=-1e6, hi=1e6, unit="m", doc="spot position"),
    "inner_angle": Field("float", 20.0, lo=0.0, hi=180.0, unit="deg", doc="spot full cone"),
    "outer_angle": Field("float", 30.0, lo=0.0, hi=180.0, unit="deg", doc="spot edge"),
}

MATERIAL_SCHEMA = {
    "diffuse": Field("vec3", (0.8, 0.8, 0.8), lo=0.0, hi=1.0, doc="albedo, linear rgb"),
    "specular": Field("vec3", (0.0, 0.0, 0.0), lo=0.0, hi=10.0, doc="Phong specular colour"),
    "shininess": Field("float", 32.0, lo=0.0, hi=1e4, doc="Phong exponent"),
    "reflectivity": Field("float", 0.0, lo=0.0, hi=1.0, doc="opaque mirror fraction"),
    "ior": Field("float", 0.0, lo=0.0, hi=4.0, doc="index of refraction; 0 = opaque"),
    "absorption": Field("vec3", (0.0, 0.0, 0.0), lo=0.0, hi=1e4, unit="1/m",
                        doc="Beer-Lambert coefficient inside a dielectric"),
    "texture": Field("path", None, doc="image multiplying diffuse (sRGB PNG/JPEG)"),
    "uv_scale": Field("vec2", (1.0, 1.0), lo=-1e6, hi=1e6, doc="texture repeats per uv unit"),
}

MESH_SCHEMA = {
    "file": Field("str", doc="OBJ/PLY/STL file (relative to the scene, or in scenes/models)"),
    "material": Field("str", "", doc="material name for the whole mesh ('' : MTL colours)"),
    "materials": Field("table", None, doc="MTL material name -> scene material name"),
    "position": Field("vec3", (0.0, 0.0, 0.0), lo=-1e6, hi=1e6, unit="m",
                      doc="where the bottom centre of the bounding box goes (with size)"),
    "rotation": Field("vec3", (0.0, 0.0, 0.0), lo=-360.0, hi=360.0, unit="deg",
                      doc="rotation about x, then y, then z"),
    "size": Field("float", 0.0, lo=0.0, hi=1e6, unit="m",
                  doc="scale the largest extent to this; 0 keeps the file's units and origin"),
    "smooth": Field("bool", True, doc="interpolate area-weighted vertex normals"),
}

BOAT_SCHEMA = {
    "name": Field("str", "", doc="what [[timeline]] boat entries call it ('' : the file's stem, "
                                 "numbered where several boats share a file)"),
    "file": Field("str", doc="OBJ/PLY/STL file rendered (relative to the scene, or scenes/models)"),
    "hull": Field("str", "", doc="closed mesh for buoyancy, in the file's frame ('' : file, "
                                 "which must then be closed)"),
    "mass": Field("float", 0.0, lo=0.0, hi=1e9, unit="kg", doc="mass (or give density)"),
    "density": Field("float", 0.0, lo=0.0, hi=1e5, unit="kg/m^3",
                     doc="mass per m^3 of the hull's volume (or give mass)"),
    "mass_height": Field("float", -1.0, lo=-1.0, hi=1e4, unit="m",
                         doc="centre of mass above the hull's lowest point (ballast); "
                             "-1: the uniform solid's centroid"),
    "material": Field("str", "", doc="material name for the whole mesh ('' : MTL colours)"),
    "materials": Field("table", None, doc="MTL material name -> scene material name"),
    "position": Field("vec3", (0.0, 0.0, 0.0), lo=-1e6, hi=1e6, unit="m",
                      doc="where the bottom centre of the bounding box starts (with size)"),
    "rotation": Field("vec3", (0.0, 0.0, 0.0), lo=-360.0, hi=360.0, unit="deg",
                      doc="rotation about x, then y, then z, at the start"),
    "size": Field("float", 0.0, lo=0.0, hi=1e6, unit="m",
                  doc="scale the largest extent to this; 0 keeps the file's units and origin"),
    "smooth": Field("bool", True, doc="interpolate area-weighted vertex normals"),
    "damping": Field("vec3", (2.0, 1.0, 2.0), lo=0.0, hi=1e3, unit="1/s",
                     doc="heave, drift (towards the water's velocity), rotation: larger "
                         "settles faster"),
}

POOL_SCHEMA = {
    "wall_height": Field("float", 0.7, lo=0.0, lo_open=True, hi=1e4, unit="m",
                         doc="wall top above the bed"),
    "deck": Field("float", 1.0, lo=0.0, hi=1e4, unit="m", doc="width of the deck around it"),
    "floor_texture": Field("path", None, doc="tile image on floor and walls"),
    "tile_size": Field("float", 0.5, lo=0.0, lo_open=True, hi=1e4, unit="m",
                       doc="one texture repeat"),
    "floor_material": Field("str", "", doc="material of floor and walls ('' : tiles)"),
    "deck_material": Field("str", "", doc="material of the deck ('' : stone)"),
    "water_material": Field("str", "", doc="material of the water ('' : water, IOR 1.333)"),
    "steps": Field("int", 30, lo=0, hi=100000, doc="LBM steps before a still render"),
}

CUBEMAP_FACES = ("px", "nx", "py", "ny", "pz", "nz")


@dataclass(frozen=True)
class ShadingSpec:
    pattern: str
    order: str
    fresnel: str
    tonemap: str
    exposure: float
    min_contribution: float
    ambient: tuple
    seed: int
    caustics: str = "off"
    caustic_photons: int = 131072
    caustic_resolution: int = 256
    caustic_filter: int = 1
    caustic_blend: float = 0.5


@dataclass(frozen=True)
class SkySpec:
    kind: str
    zenith: tuple
    horizon: tuple
    ground: tuple
    sun_direction: tuple
    sun_color: tuple
    sun_radius: float
    sun_glow: float
    cubemap: tuple  # six paths or ()


@dataclass(frozen=True)
class LightSpec:
    kind: str
    direction: tuple
    color: tuple
    position: tuple
    inner_angle: float
    outer_angle: float


@dataclass(frozen=True)
class MaterialSpec:
    diffuse: tuple
    specular: tuple
    shininess: float
    reflectivity: float
    ior: float
    absorption: tuple
    texture: Path | None
    uv_scale: tuple


@dataclass(frozen=True)
class MeshSpec:
    file: Path
    material: str
    materials: dict
    position: tuple
    rotation: tuple
    size: float
    smooth: bool


@dataclass(frozen=True)
class BoatSpec:
    """A ``[[boats]]`` table: a floating rigid body (lbm.bodies) rendered as a mesh."""

    name: str
    file: Path
    hull: Path | None
    mass: float | None
    density: float | None
    mass_height: float | None
    material: str
    materials: dict
    position: tuple
    rotation: tuple
    size: float
    smooth: bool
    damping: tuple


@dataclass(frozen=True)
class PoolSpec:
    wall_height: float
    deck: float
    floor_texture: Path | None
    tile_size: float
    floor_material: str
    deck_material: str
    water_material: str
    steps: int


@dataclass(frozen=True)
class Scene:
    """A validated scene: one typed field per section (None or empty when absent).

    A component that adds a section adds its parser to :data:`SECTIONS` under the section name
    and a field of the same name here."""

    path: Path
    name: str
    description: str
    render: RenderSpec
    camera: CameraSpec
    water: WaterSpec | None
    shading: ShadingSpec | None = None
    sky: SkySpec | None = None
    lights: tuple[LightSpec, ...] = ()
    materials: dict[str, MaterialSpec] = field(default_factory=dict)
    meshes: tuple[MeshSpec, ...] = ()
    pool: PoolSpec | None = None
    timeline: tuple = ()   # [[timeline]] events sorted by time (app.timeline)
    boats: tuple[BoatSpec, ...] = ()


def _shading(value, src: SourceText, base: Path) -> ShadingSpec:
    return ShadingSpec(**validate_table(value, SHADING_SCHEMA, "shading", src, base))


def _sky(value, src: SourceText, base: Path) -> SkySpec:
    v = validate_table(value, SKY_SCHEMA, "sky", src, base)
    if not any(v["sun_direction"]):
        raise InputError(f"{src.where('sky', 'sun_direction')}: sun_direction must not be zero")
    faces: tuple = ()
    if v["kind"] == "cubemap":
        if v["cubemap"] is None:
            raise InputError(f"{src.where('sky', 'kind')}: kind = 'cubemap' needs "
                             f"cubemap = {{{', '.join(f + ' = ...' for f in CUBEMAP_FACES)}}}")
        schema = {f: Field("path", doc=f"cubemap face {f}") for f in CUBEMAP_FACES}
        c = validate_table(v["cubemap"], schema, "sky.cubemap", src, base)
        faces = tuple(c[f] for f in CUBEMAP_FACES)
    v["cubemap"] = faces
    return SkySpec(**v)


def _lights(value, src: SourceText, base: Path) -> tuple:
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        raise InputError(f"{src.where('lights')}: use [[lights]] tables")
    if len(value) > 8:
        raise InputError(f"{src.where('lights')}: {len(value)} lights; at most 8")
    out = []
    for t in value:
        v = validate_table(t, LIGHT_SCHEMA, "lights", src, base)
        if not any(v["direction"]):
            raise InputError(f"{src.where('lights', 'direction')}: direction must not be zero")
        if v["inner_angle"] > v["outer_angle"]:
            raise InputError(f"{src.where('lights', 'inner_angle')}: inner_angle "
                             f"{v['inner_angle']:g} exceeds outer_angle {v['outer_angle']:g}")
        out.append(LightSpec(**v))
    return tuple(out)


def _materials(value, src: SourceText, base: Path) -> dict:
    if not isinstance(value, dict) or not all(isinstance(t, dict) for t in value.values()):
        raise InputError(f"{src.where('materials')}: use [materials.NAME] tables")
    out = {}
    for name, t in value.items():
        v = validate_table(t, MATERIAL_SCHEMA, f"materials.{name}", src, base)
        if 0.0 < v["ior"] < 1.0:
            raise InputError(f"{src.where(f'materials.{name}', 'ior')}: ior = {v['ior']:g}; "
                             "use 0 (opaque) or a value in [1, 4]")
        out[name] = MaterialSpec(**v)
    return out


def _find_model(name: str, base: Path, where: str) -> Path:
    p = Path(name)
    for cand in ([p] if p.is_absolute() else
                 [base / p, Path(__file__).resolve().parent.parent / "scenes" / "models" / p]):
        if cand.is_file():
            return cand
    raise InputError(f"{where}: file = {name!r}: not found beside the scene or in scenes/models")


def _meshes(value, src: SourceText, base: Path) -> tuple:
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        raise InputError(f"{src.where('meshes')}: use [[meshes]] tables")
    out = []
    for t in value:
        v = validate_table(t, MESH_SCHEMA, "meshes", src, base)
        v["file"] = _find_model(v["file"], base, src.where("meshes", "file"))
        mats = v["materials"] or {}
        if not all(isinstance(x, str) for x in mats.values()):
            raise InputError(f"{src.where('meshes', 'materials')}: values must be material names")
        v["materials"] = dict(mats)
        out.append(MeshSpec(**v))
    return tuple(out)


def _boats(value, src: SourceText, base: Path) -> tuple:
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        raise InputError(f"{src.where('boats')}: use [[boats]] tables")
    if len(value) > 16:
        raise InputError(f"{src.where('boats')}: {len(value)} boats; at most 16")
    out = []
    for t in value:
        v = validate_table(t, BOAT_SCHEMA, "boats", src, base)
        v["file"] = _find_model(v["file"], base, src.where("boats", "file"))
        v["hull"] = _find_model(v["hull"], base, src.where("boats", "hull")) if v["hull"] else None
        if (v["mass"] > 0) == (v["density"] > 0):
            raise InputError(f"{src.where('boats', 'mass')}: give exactly one of mass (kg) or "
                             "density (kg/m^3), > 0")
        v["mass"] = v["mass"] or None
        v["density"] = v["density"] or None
        if v["mass_height"] != -1.0 and v["mass_height"] < 0:
            raise InputError(f"{src.where('boats', 'mass_height')}: mass_height = "
                             f"{v['mass_height']:g}; use -1 (centroid) or a height >= 0 m")
        v["mass_height"] = None if v["mass_height"] == -1.0 else v["mass_height"]
        mats = v["materials"] or {}
        if not all(isinstance(x, str) for x in mats.values()):
            raise InputError(f"{src.where('boats', 'materials')}: values must be material names")
        v["materials"] = dict(mats)
        out.append(v)
    stems = [v["file"].stem for v in out]
    names = []
    for k, v in enumerate(out):
        name = v["name"] or (stems[k] if stems.count(stems[k]) == 1 else f"{stems[k]}_{k + 1}")
        if name in names:
            raise InputError(f"{src.where('boats', 'name')}: two boats are named {name!r}; "
                             "give each a different name")
        names.append(name)
        v["name"] = name
    return tuple(BoatSpec(**v) for v in out)


def _pool(value, src: SourceText, base: Path) -> PoolSpec:
    return PoolSpec(**validate_table(value, POOL_SCHEMA, "pool", src, base))


SECTIONS.update({"shading": _shading, "sky": _sky, "lights": _lights, "materials": _materials,
                 "meshes": _meshes, "pool": _pool, "boats": _boats})


def check_material_names(scene: Scene) -> None:
    """Every material a mesh or the pool names exists (one-line InputError naming it)."""
    known = set(scene.materials)
    where = f"{scene.path}"
    uses = []
    for section, items in (("meshes", scene.meshes), ("boats", scene.boats)):
        for m in items:
            uses += [(section, "material", m.material)] if m.material else []
            uses += [(section, "materials", x) for x in m.materials.values()]
    pool = scene.pool
    if pool is not None:
        uses += [("pool", k, getattr(pool, k)) for k in
                 ("floor_material", "deck_material", "water_material") if getattr(pool, k)]
    for section, key, name in uses:
        if name not in known:
            raise InputError(f"{where}: [{section}] {key} names material {name!r}; defined: "
                             f"{', '.join(sorted(known)) or 'none'}")
    if scene.boats and scene.water is None:
        raise InputError(f"{where}: [[boats]] need a [water] section to float on")
    if pool is not None and scene.water is None:
        raise InputError(f"{where}: [pool] needs a [water] section (the pool's size and depth)")


# ---- [[timeline]]: scripted drops, rain, pushes and camera keys (app.timeline) -------------------
def _timeline(value, src: SourceText, base: Path) -> tuple:
    from app.timeline import parse_timeline

    return parse_timeline(value, src, base)


SECTIONS["timeline"] = _timeline
