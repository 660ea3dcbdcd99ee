"""The one place where capture, sweep and studies make a World (docs/frame_api.md).

:func:`open_world` is ``app.world.World`` with two conveniences the studies need: ``cells``
resizes the water grid (cells along the pool's longer side, as the World does) and ``shading``
replaces keys of the scene's ``[shading]`` (fresnel, min_contribution, ...).
"""

from __future__ import annotations

import dataclasses


def with_shading(scene, changes: dict | None):
    """``scene`` with the keys of ``changes`` replaced in its ``[shading]`` (defaults if absent)."""
    if not changes:
        return scene
    from app.scene import SHADING_SCHEMA, ShadingSpec

    cur = scene.shading
    base = dataclasses.asdict(cur) if cur is not None else {
        k: f.default for k, f in SHADING_SCHEMA.items()}
    unknown = sorted(set(changes) - set(base))
    if unknown:
        raise KeyError(f"with_shading: unknown [shading] key {unknown[0]!r}")
    base.update(changes)
    return dataclasses.replace(scene, shading=ShadingSpec(**base))


def open_world(scene, device=None, *, shading: dict | None = None, **kw):
    """``World(scene, device, **kw)`` after :func:`with_shading`; ``kw`` as the World takes."""
    from app.world import World

    return World(with_shading(scene, shading), device, **kw)
