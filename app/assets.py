"""Assets a scene needs beyond meshes: textures, model placement, the pool's tiled geometry
and the built-in materials."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from app.errors import InputError

#: Built-in materials used when a scene names none.
WATER = dict(diffuse=(0.0, 0.0, 0.0), specular=(1.0, 1.0, 1.0), shininess=400.0, ior=1.333,
             absorption=(0.45, 0.09, 0.06))
TILES = dict(diffuse=(0.9, 0.9, 0.9), specular=(0.1, 0.1, 0.1), shininess=30.0)
STONE = dict(diffuse=(0.55, 0.5, 0.45))


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def load_texture(path: Path) -> np.ndarray:
    """An sRGB image file as linear float32 (h, w, 3|4), bottom row first (row 0 is v = 0)."""
    import imageio.v3 as iio

    try:
        img = np.asarray(iio.imread(path))
    except Exception as exc:  # imageio raises many kinds; the user needs one line
        raise InputError(f"{path}: unreadable image ({type(exc).__name__}: {exc})") from None
    if img.ndim == 2:
        img = img[..., None].repeat(3, axis=2)
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise InputError(f"{path}: image must be grey, RGB or RGBA, got shape {img.shape}")
    scale = 65535.0 if img.dtype == np.uint16 else 255.0
    c = img.astype(np.float64) / scale
    c[..., :3] = srgb_to_linear(c[..., :3])
    return np.ascontiguousarray(c[::-1], np.float32)




def mesh_transform(V: np.ndarray, position, rotation, size: float) -> np.ndarray:
    """world_from_object: bounding-box bottom centre to ``position``, largest extent ``size``
    (size 0 keeps the file's frame and only rotates and translates)."""
    M = np.eye(4)
    if size > 0:
        lo, hi = V.min(axis=0).astype(np.float64), V.max(axis=0).astype(np.float64)
        c = (lo + hi) / 2
        c[1] = lo[1]
        s = size / max(float((hi - lo).max()), 1e-30)
        M = np.diag([s, s, s, 1.0]) @ np.block([[np.eye(3), -c[:, None]], [np.zeros((1, 3)),
                                                                           np.ones((1, 1))]])
    R = np.eye(4)
    for axis, deg in zip((0, 1, 2), rotation, strict=True):
        a = math.radians(deg)
        c, s = math.cos(a), math.sin(a)
        i, j = [k for k in range(3) if k != axis]
        r = np.eye(4)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        R = r @ R
    T = np.eye(4)
    T[:3, 3] = position
    return T @ R @ M


def material_from_spec(spec, rs, textures: dict):
    from raytrace.render_scene import Material

    tex = -1
    if spec.texture is not None:
        if spec.texture not in textures:
            textures[spec.texture] = rs.add_texture(load_texture(spec.texture))
        tex = textures[spec.texture]
    return Material(diffuse=spec.diffuse, specular=spec.specular, shininess=spec.shininess,
                    reflectivity=spec.reflectivity, ior=spec.ior, absorption=spec.absorption,
                    texture=tex, uv_scale=spec.uv_scale)


def quad(p0, p1, p2, p3, tile: float, uv_axes):
    V = np.array([p0, p1, p2, p3], np.float32)
    uv = V[:, list(uv_axes)] / tile
    return V, np.array([[0, 1, 2], [0, 2, 3]], np.uint32), uv


def pool_meshes(water, pool):
    """Floor, four inner walls (meeting the water mesh's edge vertices) and the deck, each
    (V, F, uv) with normals facing the pool's inside or up."""
    ox, oy, oz = water.origin
    sx, sz = water.size
    h = water.dx / 2
    x0, x1, z0, z1 = ox + h, ox + sx - h, oz + h, oz + sz - h
    y0, y1 = oy, oy + pool.wall_height
    t = pool.tile_size
    tiles = [
        quad((x0, y0, z0), (x0, y0, z1), (x1, y0, z1), (x1, y0, z0), t, (0, 2)),  # floor, up
        quad((x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), t, (0, 1)),  # z0 wall
        quad((x1, y0, z1), (x0, y0, z1), (x0, y1, z1), (x1, y1, z1), t, (0, 1)),  # z1 wall
        quad((x0, y0, z1), (x0, y0, z0), (x0, y1, z0), (x0, y1, z1), t, (2, 1)),  # x0 wall
        quad((x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0), t, (2, 1)),  # x1 wall
    ]
    d = pool.deck
    deck = []
    if d > 0:
        X0, X1, Z0, Z1 = x0 - d, x1 + d, z0 - d, z1 + d
        deck = [
            quad((X0, y1, Z0), (X0, y1, z0), (X1, y1, z0), (X1, y1, Z0), t, (0, 2)),
            quad((X0, y1, z1), (X0, y1, Z1), (X1, y1, Z1), (X1, y1, z1), t, (0, 2)),
            quad((X0, y1, z0), (X0, y1, z1), (x0, y1, z1), (x0, y1, z0), t, (0, 2)),
            quad((x1, y1, z0), (x1, y1, z1), (X1, y1, z1), (X1, y1, z0), t, (0, 2)),
        ]

    def merge(quads):
        Vs, Fs, uvs, off = [], [], [], 0
        for V, F, uv in quads:
            Vs.append(V)
            Fs.append(F + off)
            uvs.append(uv)
            off += len(V)
        return np.concatenate(Vs), np.concatenate(Fs), np.concatenate(uvs)

    return merge(tiles), (merge(deck) if deck else None)
