"""Caustics: sunlight traced through the live water surface onto the pool (kernels/caustics.cl).

Per frame, on the device and with no host sync (:meth:`Caustics.enqueue`)::

    caustics.clear     zero the fixed-point flux accumulator
    caustics.photons   per directional light: a jittered grid of photons over the water (the
                       grid is seeded by the frame index, so frames stay deterministic), traced
                       with the scene's BVH (scene_closest_hit), refracted into the water with
                       Fresnel transmittance, Beer-Lambert to the first opaque hit, splatted
                       there when it is the pool (floor or a wall): an atomic integer add
    caustics.filter    tent filter (``filter`` texels) inside each face, flux / texel area =
                       irradiance (W/m^2), exponential blend with the last frame's map

The map is an atlas of the pool box's five inner faces (kernels/caustics.h). The renderer's
shadow stage reads it for pool surfaces seen through the water (:meth:`Renderer.set_caustics`):
direct light there is the map's irradiance times the diffuse colour, with no shadow ray for the
lights the map carries; above the water nothing changes.

``mode = "projected"`` (each water triangle projected onto the floor) is not implemented: the
settings reject it with a one-line error.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from kernels.errors import InputError
from raytrace.render_types import LightKind, _Choice

f4 = (np.float32, 4)

#: The caustics launches' by-value parameters (kernels/caustics.h CausticParams, 176 bytes).
CAUSTIC_PARAMS = np.dtype([
    ("box_lo", f4), ("box_hi", f4), ("texel", f4), ("emit", f4), ("light_dir", f4), ("flux", f4),
    ("light_pos", f4),
    ("nx", np.uint32), ("ny", np.uint32), ("nz", np.uint32), ("n_texels", np.uint32),
    ("grid_x", np.uint32), ("grid_z", np.uint32), ("seed", np.uint32), ("fresnel", np.uint32),
    ("pool_instance", np.int32), ("enabled", np.uint32), ("light_mask", np.uint32),
    ("filter_radius", np.uint32), ("blend", np.float32), ("emit_y", np.float32),
    ("cos_inner", np.float32), ("cos_outer", np.float32)])

STRUCTS = [("caustics.h", "CausticParams", CAUSTIC_PARAMS)]

#: Fixed-point units of one photon's largest flux (of any light and channel): a texel holds
#: 65536 such photons before its uint32 sum wraps; rounding costs < 1e-5 of a photon.
UNITS_PER_PHOTON = 65536.0

#: Photons start this far (m) above the pool's wall tops, above anything they can meet.
EMIT_HEIGHT = 10.0

FACES = ("floor", "z0", "z1", "x0", "x1")


class CausticMode(_Choice):
    OFF = 0         # shadow rays through the water (straight, 1 - Fresnel, Beer-Lambert)
    TRACED = 1      # photons traced through the water surface into a map
    PROJECTED = 2   # water triangles projected onto the floor: not implemented


@dataclasses.dataclass(frozen=True)
class CausticSettings:
    """``[shading] caustics*`` of a scene."""

    mode: str = "off"        #: off | traced | projected (not implemented)
    photons: int = 131072    #: photons per frame per directional light (a grid over the water)
    resolution: int = 256    #: texels along the pool floor's longer side (square-ish texels)
    filter: int = 1          #: tent filter radius (texels), 0: none
    blend: float = 0.5       #: weight of last frame's map (0: none; exponential history)

    def resolved(self) -> CausticSettings:
        mode = CausticMode.from_str(self.mode)
        if mode == CausticMode.PROJECTED:
            raise InputError("caustics = 'projected' is not implemented; use 'traced' or 'off'")
        for name, lo, hi in (("photons", 1, 1 << 26), ("resolution", 2, 8192),
                             ("filter", 0, 16)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or not lo <= v <= hi:
                raise InputError(f"caustic_{name} {v!r} is out of range; allowed [{lo}, {hi}]")
        if not (math.isfinite(self.blend) and 0.0 <= self.blend <= 0.99):
            raise InputError(f"caustic_blend {self.blend!r} is out of range; allowed [0, 0.99]")
        return dataclasses.replace(self, mode=str(mode))


@dataclasses.dataclass(frozen=True)
class PoolBox:
    """Where the caustics land and where the light enters.

    ``lo``/``hi``: the pool box's corners (m; floor at lo.y, wall tops at hi.y), whose inner
    faces are the receivers; ``water``: (x0, z0, x1, z1) of the water surface (m); ``level``:
    the water's rest height (m), where the photon grid lies; ``pool_instance``: the instance
    id of the floor-and-walls mesh (other instances shadow, never receive)."""

    lo: tuple
    hi: tuple
    water: tuple
    level: float
    pool_instance: int

    def check(self) -> None:
        lo, hi = np.asarray(self.lo, float), np.asarray(self.hi, float)
        if lo.shape != (3,) or hi.shape != (3,) or not (hi > lo).all():
            raise ValueError(f"pool box needs lo < hi in x, y and z, got {self.lo}, {self.hi}")
        x0, z0, x1, z1 = self.water
        if not (x1 > x0 and z1 > z0):
            raise ValueError(f"water rectangle needs x0 < x1 and z0 < z1, got {self.water}")


def grid_shape(photons: int, width: float, depth: float) -> tuple[int, int]:
    """(grid_x, grid_z): about ``photons`` cells, as square as the water's width x depth."""
    gx = max(1, round(math.sqrt(photons * width / depth)))
    return gx, max(1, round(photons / gx))


def atlas_shape(resolution: int, lo, hi) -> tuple[int, int, int]:
    """Texels (nx, ny, nz) along x, y, z: ``resolution`` along the floor's longer side."""
    size = np.asarray(hi, float) - np.asarray(lo, float)
    unit = max(size[0], size[2]) / resolution
    nx, ny, nz = (max(1, round(s / unit)) for s in size)
    return int(nx), int(ny), int(nz)


def frame_seed(seed: int, frame: int, light: int) -> int:
    """The photon jitter seed of a frame and light (the kernel hashes it with the photon)."""
    return (seed * 0x9E3779B1 + frame * 0x85EBCA6B + light * 0xC2B2AE35 + 1) & 0xFFFFFFFF


class Caustics:
    """The caustics stage of one render scene: its map, its accumulator and its launches.

    ``box``: :class:`PoolBox`; ``settings``: :class:`CausticSettings`; ``fresnel``: as the
    renderer's (exact | schlick); ``seed``: the scene's jitter seed. Photons come from the
    directional lights that shine downwards and from spot lights above the water's rest level
    (other lights keep their shadow rays)."""

    def __init__(self, rt, render_scene, box: PoolBox, settings: CausticSettings, *,
                 fresnel: str = "exact", seed: int = 0):
        from raytrace.render_types import FresnelMode

        box.check()
        self.rt, self.scene, self.box = rt, render_scene, box
        self.settings = settings.resolved()
        self.fresnel = int(FresnelMode.from_str(fresnel))
        self.seed = int(seed)
        self.nx, self.ny, self.nz = atlas_shape(self.settings.resolution, box.lo, box.hi)
        self.n_texels = self.nx * self.nz + 2 * self.nx * self.ny + 2 * self.nz * self.ny
        self.accum = rt.buffer(12 * self.n_texels)
        self.map = rt.buffer(16 * self.n_texels)
        x0, z0, x1, z1 = box.water
        self.grid = grid_shape(self.settings.photons, x1 - x0, z1 - z0)
        self.k_clear = rt.kernel_launcher("caustics.cl", "caustics_clear", stage="caustics.clear")
        self.k_photons = rt.kernel_launcher("caustics.cl", "caustics_photons",
                                            stage="caustics.photons")
        self.k_filter = rt.kernel_launcher("caustics.cl", "caustics_filter",
                                           stage="caustics.filter")
        self.k_clear.bind(accum=self.accum)
        self.k_photons.bind(accum=self.accum)
        self.k_filter.bind(accum=self.accum, map=self.map)
        self._history = False   # the map holds a last frame to blend with
        self._records_key, self._records = None, None   # enqueue's records, while valid

    @property
    def enabled(self) -> bool:
        return self.settings.mode == str(CausticMode.TRACED)

    def set_mode(self, mode: str) -> None:
        """Switch between ``off`` and ``traced`` (the map restarts without history)."""
        self.settings = dataclasses.replace(self.settings, mode=mode).resolved()
        self._history = False

    def reset_history(self) -> None:
        """The next frame's map starts afresh (no blend with an older map)."""
        self._history = False

    def lights(self) -> list[int]:
        """Indices of the lights the map carries: directional lights shining downwards, spot
        lights above the water's rest level."""
        L, level = self.scene.lights, self.box.level
        out = []
        for i in range(len(L)):
            if L[i]["color"][:3].max() <= 0:
                continue
            if int(L[i]["kind"]) == int(LightKind.DIRECTIONAL):
                if L[i]["direction"][1] < -1e-6:
                    out.append(i)
            elif L[i]["position"][1] > level + 1e-3:
                out.append(i)
        return out

    def _is_spot(self, light: int) -> bool:
        return int(self.scene.lights[light]["kind"]) == int(LightKind.SPOT)

    def _base(self) -> np.ndarray:
        b = self.box
        p = np.zeros(1, CAUSTIC_PARAMS)[0]
        p["box_lo"][:3], p["box_hi"][:3] = b.lo, b.hi
        size = np.asarray(b.hi, float) - np.asarray(b.lo, float)
        p["texel"][:3] = size / (self.nx, self.ny, self.nz)
        p["emit"] = b.water
        p["light_dir"][3] = b.level
        p["nx"], p["ny"], p["nz"], p["n_texels"] = self.nx, self.ny, self.nz, self.n_texels
        p["grid_x"], p["grid_z"] = self.grid
        p["fresnel"] = self.fresnel
        p["pool_instance"] = b.pool_instance
        p["filter_radius"] = self.settings.filter
        p["emit_y"] = max(b.hi[1], b.level) + EMIT_HEIGHT
        return p

    def _photon_flux(self, light: int) -> np.ndarray:
        """CausticParams.flux of ``light``: a directional photon's flux (W, rgb), E |d.y| times a
        grid cell's area; for a spot I times the cell's area (the kernel multiplies by the cone
        and |d.y| / dist^2)."""
        x0, z0, x1, z1 = self.box.water
        rec = self.scene.lights[light]
        cell = (x1 - x0) * (z1 - z0) / (self.grid[0] * self.grid[1])
        if self._is_spot(light):
            return np.asarray(rec["color"][:3], float) * cell
        d = np.asarray(rec["direction"][:3], float)
        d /= np.linalg.norm(d)
        return np.asarray(rec["color"][:3], float) * -d[1] * cell

    def _max_photon_flux(self, light: int) -> float:
        """The largest flux one photon of ``light`` can carry (a spot's: I cell / height^2)."""
        f = self._photon_flux(light).max()
        if self._is_spot(light):
            h = float(self.scene.lights[light]["position"][1]) - self.box.level
            f /= h * h
        return f

    def _units_per_watt(self) -> float:
        fmax = max((self._max_photon_flux(i) for i in self.lights()), default=0.0)
        return UNITS_PER_PHOTON / fmax if fmax > 0 else 1.0

    def params(self, frame: int = 0, light: int | None = None) -> np.ndarray:
        """The CausticParams record of a photon launch (``light``), or of the map (None: what
        the filter and the shader read)."""
        p = self._base()
        upw = self._units_per_watt()
        p["texel"][3] = 1.0 / upw
        p["flux"][3] = upw
        p["enabled"] = int(self.enabled)
        p["light_mask"] = sum(1 << i for i in self.lights()) if self.enabled else 0
        p["blend"] = self.settings.blend if self._history else 0.0
        if light is not None:
            rec = self.scene.lights[light]
            d = np.asarray(rec["direction"][:3], float)
            p["light_dir"][:3] = d / np.linalg.norm(d)
            p["flux"][:3] = self._photon_flux(light)
            p["seed"] = frame_seed(self.seed, frame, light)
            if self._is_spot(light):
                p["light_pos"][:3] = rec["position"][:3]
                p["light_pos"][3] = 1.0
                p["cos_inner"], p["cos_outer"] = rec["cos_inner"], rec["cos_outer"]
        return p

    def view_params(self) -> np.ndarray:
        """The record the renderer's shadow stage reads the map with."""
        p = self.params()
        p["blend"] = 0.0
        return p

    def enqueue(self, frame: int) -> None:
        """Queue the frame's map: clear, photons per light, filter + blend. No host sync; the
        scene's BVH must be up to date (after ``RenderScene.update``)."""
        if not self.enabled:
            return
        ls = 64
        cp, photons = self._frame_records()
        self.k_clear.bind(cp=cp)
        self.k_clear.launch(min(3 * self.n_texels, 1 << 20), ls)
        scene = self.scene.scene.trace_bindings()
        geom = self.scene.shade_bindings()
        n = self.grid[0] * self.grid[1]
        for light, rec in photons:
            rec["seed"] = frame_seed(self.seed, frame, light)  # = params(frame, light)
            self.k_photons.bind(**scene, **geom, cp=rec)
            self.k_photons.launch(n, ls)
        self.k_filter.bind(cp=cp)
        self.k_filter.launch(self.n_texels, ls)
        self._history = True

    def _frame_records(self) -> tuple:
        """The map's record and (light, photon record) per light, made again only when the
        settings, the history flag or the lights changed (the frame sets only the seed)."""
        key = (self.settings, self._history, self.scene.lights.tobytes())
        if key != self._records_key:
            self._records = (self.params(), [(i, self.params(0, i)) for i in self.lights()])
            self._records_key = key
        return self._records

    # -- host reads (tests, tools; each synchronises) ----------------------------------------
    def faces(self, array: np.ndarray) -> dict:
        """Split an atlas array (n_texels, ...) into its faces, each (nv, nu, ...)."""
        nx, ny, nz = self.nx, self.ny, self.nz
        dims = [(nz, nx), (ny, nx), (ny, nx), (ny, nz), (ny, nz)]
        out, off = {}, 0
        for name, (nv, nu) in zip(FACES, dims, strict=True):
            out[name] = array[off: off + nu * nv].reshape(nv, nu, *array.shape[1:])
            off += nu * nv
        return out

    def read_map(self) -> dict:
        """Irradiance (W/m^2, rgb) per face: {"floor": (nz, nx, 3), "z0": (ny, nx, 3), ...}."""
        m = self.rt.to_host(self.map, np.float32, 4 * self.n_texels).reshape(-1, 4)[:, :3]
        return self.faces(m)

    def read_flux(self) -> dict:
        """The accumulator as flux (W, rgb) per texel before the filter, per face."""
        a = self.rt.to_host(self.accum, np.uint32, 3 * self.n_texels).reshape(-1, 3)
        return self.faces(a.astype(np.float64) / self._units_per_watt())

    def texel_areas(self) -> dict:
        """Texel area (m^2) of each face."""
        size = np.asarray(self.box.hi, float) - np.asarray(self.box.lo, float)
        tx, ty, tz = size / (self.nx, self.ny, self.nz)
        return {"floor": tx * tz, "z0": tx * ty, "z1": tx * ty, "x0": tz * ty, "x1": tz * ty}
