"""Caustics (kernels/caustics.cl, raytrace/caustics.py): the struct's layout, the photon path
against a float64 reference, energy under flat water, photon bookkeeping, the focus of a
spherical-cap lens against thin-lens optics, and the spreading of a dip."""

import math

import numpy as np
import pytest

from kernels.layout import check_struct
from raytrace import caustics_reference as cref
from raytrace import render_reference as rref
from raytrace.caustics import (
    STRUCTS,
    Caustics,
    CausticSettings,
    PoolBox,
    atlas_shape,
    grid_shape,
)
from raytrace.render_scene import Material, RenderScene

N_WATER = 1.333


@pytest.mark.parametrize("header,struct,dtype", STRUCTS, ids=[s[1] for s in STRUCTS])
def test_struct_layout(rt, header, struct, dtype):
    check_struct(rt, header, struct, dtype)


def box_mesh(lo, hi):
    """Floor and four walls of a box (no lid), normals facing inside."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    quads = [
        [(x0, y0, z0), (x0, y0, z1), (x1, y0, z1), (x1, y0, z0)],  # floor
        [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)],  # z0
        [(x1, y0, z1), (x0, y0, z1), (x0, y1, z1), (x1, y1, z1)],  # z1
        [(x0, y0, z1), (x0, y0, z0), (x0, y1, z0), (x0, y1, z1)],  # x0
        [(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)],  # x1
    ]
    V = np.array([p for q in quads for p in q], np.float64)
    F = np.array([(4 * k, 4 * k + 1, 4 * k + 2) for k in range(5)]
                 + [(4 * k, 4 * k + 2, 4 * k + 3) for k in range(5)], np.int64)
    return V, F


def height_field(x0, z0, x1, z1, n, height, grad):
    """An n x n vertex grid over the rectangle: y = height(x, z), normals from grad(x, z)."""
    xs, zs = np.linspace(x0, x1, n), np.linspace(z0, z1, n)
    X, Z = np.meshgrid(xs, zs)
    V = np.stack([X, height(X, Z), Z], -1).reshape(-1, 3)
    gx, gz = grad(X, Z)
    N = np.stack([-gx, np.ones_like(gx), -gz], -1).reshape(-1, 3)
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    F = np.stack([np.stack([a, c, b], -1), np.stack([b, c, d], -1)], -2).reshape(-1, 3)
    return V, N, F


def pool_scene(rt, *, lo, hi, level, light_dir, color=(1.0, 1.0, 1.0), absorption=(0, 0, 0),
               height=None, grad=None, n_grid=9, boat=None, water=None, spot=None):
    """A RenderScene: a pool box and a water height field over its whole top (flat at
    ``level`` unless ``height``/``grad`` are given). Returns (scene, PoolBox)."""
    rs = RenderScene(rt)
    tiles = rs.add_material(Material(diffuse=(0.8, 0.8, 0.8)))
    water_mat = rs.add_material(Material(ior=N_WATER, absorption=absorption))
    x0, z0, x1, z1 = water or (lo[0], lo[2], hi[0], hi[2])
    if height is None:
        height = lambda X, Z: np.full_like(X, level)  # noqa: E731
        grad = lambda X, Z: (np.zeros_like(X), np.zeros_like(X))  # noqa: E731
    V, N, F = height_field(x0, z0, x1, z1, n_grid, height, grad)
    rs.add_instance(rs.add_mesh(V, F, normals=N, material=water_mat))
    Vb, Fb = box_mesh(lo, hi)
    pool = rs.add_instance(rs.add_mesh(Vb, Fb, material=tiles))
    if boat is not None:
        Vo, Fo = box_mesh(*boat)
        rs.add_instance(rs.add_mesh(Vo, Fo, material=tiles))
    if spot is None:
        rs.add_light("directional", direction=light_dir, color=color)
    else:  # dict(position=..., inner_angle=..., outer_angle=...)
        rs.add_light("spot", direction=light_dir, color=color, **spot)
    rs.update()
    return rs, PoolBox(tuple(lo), tuple(hi), (x0, z0, x1, z1), level, pool)


def run(rt, rs, box, frame=0, **settings):
    kw = {"mode": "traced", "filter": 0, "blend": 0.0} | settings
    c = Caustics(rt, rs, box, CausticSettings(**kw))
    c.enqueue(frame)
    rt.finish()
    return c


# ---- the photon path against float64 --------------------------------------------------------
@pytest.mark.parametrize("kind", ["directional", "spot"])
def test_photons_match_the_float64_reference_on_a_wavy_surface(rt, kind):
    """A wavy surface, an absorbing tinted water, an oblique sun (or a spot off to one side):
    every texel's flux (before the filter) equals the float64 reference's; photons land on the
    floor and on walls."""
    lo, hi = (0.0, 0.0, 0.0), (1.0, 0.8, 0.7)

    def h(X, Z):
        return 0.5 + 0.04 * np.sin(2 * math.pi * X / 0.5) * np.cos(2 * math.pi * Z / 0.7)

    def g(X, Z):
        k1, k2 = 2 * math.pi / 0.5, 2 * math.pi / 0.7
        return (0.04 * k1 * np.cos(k1 * X) * np.cos(k2 * Z),
                -0.04 * k2 * np.sin(k1 * X) * np.sin(k2 * Z))

    rs, box = pool_scene(rt, lo=lo, hi=hi, level=0.5, light_dir=(0.5, -1.0, 0.3),
                         color=(2.0, 1.5, 1.0), absorption=(0.45, 0.09, 0.06), height=h,
                         grad=g, n_grid=7,
                         spot=None if kind == "directional" else dict(
                             position=(0.1, 1.3, 0.2), inner_angle=25, outer_angle=40))
    c = run(rt, rs, box, frame=3, photons=300, resolution=12)
    got = np.concatenate([v.reshape(-1, 3) for v in c.read_flux().values()])
    cp = c.params(3, 0)
    r = cref.trace_photons(rs.tables(), cp)
    want = cref.texel_flux(rs.tables(), cp)
    landed = r["texel"] >= 0
    assert landed.sum() > 200
    on_walls = (r["texel"] >= c.nx * c.nz).sum()
    assert on_walls > 5, "the oblique sun lights some wall"
    # per-photon rounding of the fixed point: half a unit each
    unit = float(cp["texel"][3])
    tol = 2e-4 * want.max() + np.bincount(r["texel"][landed], minlength=c.n_texels)[:, None] \
        * unit
    assert np.all(np.abs(got - want) <= tol), np.abs(got - want).max()


def test_photon_origins_are_a_jittered_grid_that_changes_with_the_frame(rt):
    rs, box = pool_scene(rt, lo=(0, 0, 0), hi=(1, 1, 1), level=0.5, light_dir=(0, -1, 0))
    c = Caustics(rt, rs, box, CausticSettings(mode="traced", photons=64, resolution=8))
    a, _ = cref.photon_origins(c.params(0, 0))
    b, _ = cref.photon_origins(c.params(1, 0))
    assert np.all(np.floor(a[:, 0] * 8) == np.arange(64) % 8)  # one per cell
    assert not np.allclose(a, b)


# ---- energy and bookkeeping --------------------------------------------------------------------
def flat_expectation(light_dir, depth, sigma, fresnel="exact"):
    d = np.asarray(light_dir, float)
    d /= np.linalg.norm(d)
    cosi = -d[1]
    F = rref.fresnel(0 if fresnel == "exact" else 1, cosi, 1 / N_WATER)
    t, _ = rref.refract(d[None], np.array([[0.0, 1.0, 0.0]]), 1 / N_WATER)
    path = depth / -t[0, 1]
    return cosi * (1 - F) * np.exp(-np.asarray(sigma) * path), t[0]


@pytest.mark.parametrize("fresnel", ["exact", "schlick"])
def test_flat_water_floor_irradiance_is_sun_times_fresnel_times_beer(rt, fresnel):
    lo, hi, level = (0.0, 0.0, 0.0), (1.2, 0.4, 1.0), 0.4  # wall tops at the water: no shadow
    light = (0.6, -1.0, 0.3)
    sigma = (0.45, 0.09, 0.06)
    rs, box = pool_scene(rt, lo=lo, hi=hi, level=level, light_dir=light, absorption=sigma)
    c = Caustics(rt, rs, box, CausticSettings(mode="traced", photons=120 * 100, resolution=48,
                                              filter=1, blend=0.0), fresnel=fresnel)
    c.enqueue(0)
    E = c.read_map()["floor"]  # (nz, nx, 3)
    want, t = flat_expectation(light, level, sigma, fresnel)
    # away from the walls: the lit strip is shifted by depth * tan(theta_t) along t
    shift = level * t[[0, 2]] / -t[1]
    xs = (np.arange(c.nx) + 0.5) * 1.2 / c.nx
    zs = (np.arange(c.nz) + 0.5) * 1.0 / c.nz
    X, Z = np.meshgrid(xs, zs)
    m = 3 * 1.2 / c.nx
    inner = ((X > shift[0] + m) & (X < 1.2 - m) & (Z > shift[1] + m) & (Z < 1.0 - m))
    assert inner.sum() > 500
    mean = E[inner].mean(0)
    assert np.allclose(mean, want, rtol=0.02), (mean, want)
    # the unlit strip along the walls the light comes from
    dark = X < shift[0] - m
    assert dark.sum() > 0 and E[dark].max() < 1e-3 * want.max()


def test_total_flux_is_flux_through_the_surface_times_transmittance(rt):
    """Every photon enters the flat water and lands on the floor or a wall: their sum is
    E |d.y| A (1 - F) to 1%; with absorption, each photon's Beer-Lambert is its own path's."""
    lo, hi, level = (0.0, 0.0, 0.0), (1.0, 0.5, 0.8), 0.5
    light = (0.8, -1.0, -0.4)
    rs, box = pool_scene(rt, lo=lo, hi=hi, level=level, light_dir=light, color=(3, 2, 1))
    c = run(rt, rs, box, photons=20000, resolution=32)
    flux = c.read_flux()
    total = sum(v.sum(axis=(0, 1)) for v in flux.values())
    maps = c.read_map()
    areas = c.texel_areas()
    from_map = sum(maps[k].sum(axis=(0, 1)) * areas[k] for k in maps)
    d = np.asarray(light, float) / np.linalg.norm(light)
    F = rref.fresnel(0, -d[1], 1 / N_WATER)
    want = np.array([3, 2, 1]) * -d[1] * 1.0 * 0.8 * (1 - F)
    assert np.allclose(total, want, rtol=0.01), (total, want)
    assert np.allclose(from_map, want, rtol=0.01), "the map is flux / texel area"
    walls = sum(flux[k].sum() for k in ("z0", "z1", "x0", "x1"))
    assert walls > 0.05 * total.sum(), "the oblique light reaches the walls"


def test_a_boat_in_the_water_shadows_the_floor(rt):
    lo, hi, level = (0.0, 0.0, 0.0), (1.0, 0.6, 1.0), 0.4
    boat = ((0.35, 0.3, 0.35), (0.65, 0.5, 0.65))
    rs, box = pool_scene(rt, lo=lo, hi=hi, level=level, light_dir=(0, -1, 0), boat=boat)
    c = run(rt, rs, box, photons=4096, resolution=20)
    E = c.read_map()["floor"][..., 0]
    assert E[10, 10] == 0.0 and E[2, 2] > 0.5


def test_a_spot_over_flat_water_lights_the_floor_as_from_its_virtual_source(rt):
    """A spot h1 above flat water, the floor h2 below it: paraxially the refracted rays diverge
    from a virtual source n h1 above the water, so below the spot the floor's irradiance is
    I (1 - F(0)) / (h1 + h2 / n)^2 (thin-beam optics), within 2%."""
    h1, h2 = 0.5, 0.4
    lo, hi = (-0.6, -h2, -0.6), (0.6, 0.0, 0.6)
    rs, box = pool_scene(rt, lo=lo, hi=hi, level=0.0, light_dir=(0, -1, 0), color=(2, 2, 2),
                         spot=dict(position=(0.0, h1, 0.0), inner_angle=70, outer_angle=80))
    c = run(rt, rs, box, photons=160_000, resolution=120, filter=2)
    E = c.read_map()["floor"][..., 0]
    centre = E[58:62, 58:62].mean()
    F0 = ((N_WATER - 1) / (N_WATER + 1)) ** 2
    want = 2.0 * (1 - F0) / (h1 + h2 / N_WATER) ** 2
    assert abs(centre - want) < 0.02 * want, (centre, want)
    assert E[5, 60] < 0.8 * centre, "falls off away from the axis"


# ---- focus ---------------------------------------------------------------------------------------
def rms_radius(E, cx, cz, size):
    nz, nx = E.shape
    xs = (np.arange(nx) + 0.5) * size[0] / nx - cx
    zs = (np.arange(nz) + 0.5) * size[1] / nz - cz
    X, Z = np.meshgrid(xs, zs)
    return math.sqrt(float((E * (X**2 + Z**2)).sum() / E.sum()))


def cap_surface(R, level, sign):
    """A spherical cap of radius R (sign +1: bump, a converging lens; -1: a dip) over the
    whole pool, centred at (0.5, 0.5): its apex at ``level``."""
    def h(X, Z):
        r2 = (X - 0.5) ** 2 + (Z - 0.5) ** 2
        return level + sign * (np.sqrt(R * R - r2) - R)

    def g(X, Z):
        s = np.sqrt(R * R - (X - 0.5) ** 2 - (Z - 0.5) ** 2)
        return -sign * (X - 0.5) / s, -sign * (Z - 0.5) / s
    return h, g


def test_a_spherical_cap_focuses_at_the_single_surface_focal_length(rt):
    """Light refracted into water by a spherical surface of radius R focuses at
    f = n R / (n - 1) below it (the image-side focal length of one refracting surface, measured
    in water; R / (n - 1) is a thin lens in air). Paraxially the beam's radius shrinks as
    1 - z/f: the RMS radius of the floor's irradiance at two floor depths gives f to 10%."""
    R = 3.0                                # aperture 1 m: a corner ray at r / R = 0.24
    f_want = N_WATER * R / (N_WATER - 1)   # 12.0 m
    h, g = cap_surface(R, 0.0, +1)
    rms = []
    depths = (0.25 * f_want, 0.5 * f_want)
    for z in depths:
        lo, hi = (0.0, -z, 0.0), (1.0, 0.3, 1.0)
        rs, box = pool_scene(rt, lo=lo, hi=hi, level=0.0, light_dir=(0, -1, 0), height=h,
                             grad=g, n_grid=33)
        c = run(rt, rs, box, photons=40000, resolution=128)
        assert sum(c.read_flux()[k].sum() for k in ("z0", "z1", "x0", "x1")) == 0
        rms.append(rms_radius(c.read_map()["floor"][..., 0], 0.5, 0.5, (1.0, 1.0)))
    # rms(z) = rms0 (1 - z / f): two depths give rms0 and f
    (z1, z2), (r1, r2) = depths, rms
    f = (r1 * z2 - r2 * z1) / (r1 - r2)
    assert r2 < r1, "a bump converges the light"
    assert abs(f - f_want) < 0.1 * f_want, (f, f_want)


def test_a_dip_spreads_the_light(rt):
    R = 0.75
    h, g = cap_surface(R, 0.0, -1)
    peaks, rms = [], []
    for z in (0.3, 0.6):
        lo, hi = (-1.0, -z, -1.0), (2.0, 0.3, 2.0)
        # only the dip's square carries water: photons enter there
        rs, box = pool_scene(rt, lo=lo, hi=hi, level=0.0, light_dir=(0, -1, 0), height=h,
                             grad=g, n_grid=33, water=(0.0, 0.0, 1.0, 1.0))
        c = run(rt, rs, box, photons=20000, resolution=96)
        E = c.read_map()["floor"][..., 0]
        peaks.append(E.max())
        rms.append(rms_radius(E, 1.5, 1.5, (3.0, 3.0)))
    assert rms[1] > rms[0] * 1.1 and peaks[1] < peaks[0]


# ---- settings ---------------------------------------------------------------------------------
def test_settings_reject_projected_and_bad_values():
    from app.errors import InputError

    with pytest.raises(InputError, match="projected.*not implemented"):
        CausticSettings(mode="projected").resolved()
    with pytest.raises(InputError, match="valid: off, traced, projected"):
        CausticSettings(mode="mirror").resolved()
    with pytest.raises(InputError, match="caustic_photons"):
        CausticSettings(photons=0).resolved()
    with pytest.raises(InputError, match="caustic_blend"):
        CausticSettings(blend=1.0).resolved()
    assert grid_shape(100, 2.0, 1.0) == (14, 7)
    assert atlas_shape(10, (0, 0, 0), (2.0, 0.5, 1.0)) == (10, 2, 5)
