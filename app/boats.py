"""A scene's ``[[boats]]`` as floating bodies: meshes loaded, poses and hulls prepared for
:class:`lbm.bodies.Boats`, errors as one-line InputErrors naming the scene and the key.

    bodies = boat_bodies(scene)                       # [(name, lbm.bodies.BoatSpec, V, F)]
    boats = lbm.bodies.Boats(sim, [b.spec for b in bodies], transform_buffer, rows,
                             origin=scene.water.origin)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.errors import InputError


@dataclass
class BoatBody:
    name: str        #: "[[boats]] #k (file name)"
    spec: object     #: lbm.bodies.BoatSpec
    vertices: np.ndarray  #: the rendered mesh (its file's frame)
    faces: np.ndarray
    world_from_mesh: np.ndarray  #: (4, 4) the starting transform (as a static mesh's)


def rotation_matrix(rotation) -> np.ndarray:
    """The 3x3 rotation of app.assets.mesh_transform: about x, then y, then z (degrees)."""
    R = np.eye(3)
    for axis, deg in zip((0, 1, 2), rotation, strict=True):
        a = math.radians(deg)
        c, s = math.cos(a), math.sin(a)
        i, j = [k for k in range(3) if k != axis]
        r = np.eye(3)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        R = r @ R
    return R


def read_obj_verbatim(path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of an OBJ file as written (no vertex merging, no cleaning: a
    hull made of separate closed parts stays closed part by part); polygons fanned."""
    V, F = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                V.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(x.split("/")[0]) for x in line.split()[1:]]
                idx = [i - 1 if i > 0 else len(V) + i for i in idx]
                F += [(idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1)]
    return np.asarray(V, np.float64), np.asarray(F, np.int64)


def boat_bodies(scene) -> list[BoatBody]:
    """Load every ``[[boats]]`` mesh (and hull) and describe it for lbm.bodies."""
    from app.assets import mesh_transform
    from app.meshes import load_mesh
    from lbm.bodies import BoatSpec, HullError, check_closed

    out = []
    for k, b in enumerate(scene.boats):
        name = f"[[boats]] #{k + 1} ({b.file.name})"
        where = f"{scene.path}: {name}"
        V, F = load_mesh(b.file)
        if b.hull is not None:   # read as written: its parts may share positions, not vertices
            Vh, Fh = (read_obj_verbatim(b.hull) if b.hull.suffix.lower() == ".obj"
                      else load_mesh(b.hull))
        else:
            Vh, Fh = V, F
        try:
            check_closed(Fh)
        except HullError as exc:
            key = "hull" if b.hull is not None else "file"
            raise InputError(f"{where}: {key}: {exc}; give a closed hull = \"...\" mesh for "
                             "buoyancy") from None
        M = mesh_transform(V, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), b.size)   # placed_from_mesh
        spec = BoatSpec(np.asarray(Vh, np.float64), np.asarray(Fh, np.int64), mass=b.mass,
                        density=b.density, position=tuple(b.position),
                        rotation=rotation_matrix(b.rotation), base=M[:3],
                        damping=tuple(b.damping), mass_height=b.mass_height, name=name)
        out.append(BoatBody(name, spec, V, F, mesh_transform(V, b.position, b.rotation,
                                                             b.size)))
    return out


def make_boats(scene, sim, bodies: list[BoatBody], transform_buffer, rows, **options):
    """:class:`lbm.bodies.Boats` for ``bodies`` on ``sim`` (``options``: Boats' keywords);
    bad boats as one-line InputErrors."""
    from lbm.bodies import Boats

    try:
        return Boats(sim, [b.spec for b in bodies], transform_buffer, rows,
                     origin=scene.water.origin, **options)
    except ValueError as exc:   # HullError is a ValueError: too heavy, too deep, bad values
        raise InputError(f"{scene.path}: {exc}") from None
