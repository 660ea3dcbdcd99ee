"""Building a solver from a scene's water description (``app.scene.WaterSpec`` or anything with
the same fields), so ``lbm`` needs nothing from ``app``."""

from __future__ import annotations

from lbm.solver import ShallowWater


def from_water_spec(water, device=None, **options) -> ShallowWater:
    """A :class:`ShallowWater` for ``water`` (fields ``size`` (m, 2), ``cells`` (2), ``depth`` (m),
    ``boundary``, ``viscosity`` (m^2/s), ``expected_speed`` (m/s), ``drops`` and ``rain``): a lake
    at rest of that depth with the drops added and the rain set. ``options`` go to the solver
    and override the spec's."""
    nx, ny = (int(c) for c in water.cells)
    kw = dict(depth=water.depth, viscosity=water.viscosity,
              expected_speed=water.expected_speed)
    kw.update(options)
    sim = ShallowWater(nx, ny, water.size[0] / nx, boundary=water.boundary, device=device, **kw)
    for d in water.drops:
        sim.add_drop(d.x, d.y, d.radius, d.height)
    rain = water.rain
    if rain is not None and rain.rate > 0:
        sim.set_rain(rain.rate, rain.radius, rain.height, rain.seed)
    return sim
