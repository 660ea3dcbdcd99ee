"""ParaView output: the water surface as a ``.pvd`` time series of structured grids (``.vts``),
and the boats as a second series of triangle meshes (``.vtp``) at the same times.

Each step written is one ``water_NNNNNN.vts``: a structured grid of the cell centres at the
surface height (x, bed + h, z in metres, Y up, the scene's origin added) with point data ``h``
(depth, m), ``u``, ``v`` (velocity along x and z, m/s), ``bed`` (m) and ``eta`` (bed + h, m);
``water.pvd`` lists them with their simulated times. With ``[[boats]]``, ``boats_NNNNNN.vtp``
holds every boat's rendered mesh placed by its pose at that step (world metres, one PolyData,
cell and point data ``boat``: the boat's index in ``[[boats]]``), listed by ``boats.pvd``.
pyvista is imported when the first file is written (machines without VTK still run everything
else), and VTK's own log and warning lines never reach the terminal: a failure is one
:class:`~app.errors.InputError` line.
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from app.errors import InputError
from app.io import atomic_path


def _quiet_pyvista():
    """pyvista with VTK's logger and warning window silenced (one-time)."""
    try:
        import pyvista as pv
        from vtkmodules.vtkCommonCore import vtkLogger, vtkObject
    except ImportError as exc:
        raise InputError(f"--vtk needs pyvista and VTK (pip install pyvista): {exc}") from None
    vtkObject.GlobalWarningDisplayOff()
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_OFF)
    return pv


def check_folder(folder: str | os.PathLike) -> Path:
    """The output folder, created, and writable; else one InputError naming it."""
    path = Path(folder)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--vtk {str(folder)!r}: cannot create the folder ({exc.strerror})") \
            from None
    if not path.is_dir() or not os.access(path, os.W_OK | os.X_OK):
        raise InputError(f"--vtk {str(folder)!r}: not a writable folder")
    return path


def surface_grid(fields: dict, dx: float, origin=(0.0, 0.0, 0.0)):
    """A pyvista StructuredGrid of the water surface from ``fields`` (h, u, v, bed as (ny, nx))."""
    pv = _quiet_pyvista()
    h = np.asarray(fields["h"], np.float32)
    ny, nx = h.shape
    bed = np.asarray(fields["bed"], np.float32)
    x = origin[0] + (np.arange(nx) + 0.5) * dx
    z = origin[2] + (np.arange(ny) + 0.5) * dx
    X, Z = np.meshgrid(x, z)           # (ny, nx), index [j, i]
    Y = origin[1] + bed + h
    # VTK's structured points run fastest along the first dimension: pass (nx, ny, 1) arrays
    grid = pv.StructuredGrid(X.T[..., None], Y.T[..., None], Z.T[..., None])
    for name, a in (("h", h), ("u", fields["u"]), ("v", fields["v"]), ("bed", bed),
                    ("eta", bed + h)):
        grid.point_data[name] = np.asarray(a, np.float32).ravel()   # C order (j, i) = VTK's
    return grid


def boats_polydata(meshes, transforms):
    """One pyvista PolyData of the boats: ``meshes`` [(V (n, 3), F (m, 3))] in their files'
    frames, each placed by ``transforms[k]`` (3, 4) world_from_mesh; cell and point data
    ``boat`` = k."""
    pv = _quiet_pyvista()
    pts, faces, pid, cid, off = [], [], [], [], 0
    for k, ((V, F), M) in enumerate(zip(meshes, transforms, strict=True)):
        V = np.asarray(V, np.float64)
        M = np.asarray(M, np.float64)
        pts.append(V @ M[:, :3].T + M[:, 3])
        F = np.asarray(F, np.int64)
        faces.append(np.hstack([np.full((len(F), 1), 3), F + off]))
        pid.append(np.full(len(V), k, np.int32))
        cid.append(np.full(len(F), k, np.int32))
        off += len(V)
    mesh = pv.PolyData(np.concatenate(pts), np.concatenate(faces).ravel())
    mesh.point_data["boat"] = np.concatenate(pid)
    mesh.cell_data["boat"] = np.concatenate(cid)
    return mesh


class PvdWriter:
    """Writes ``NAME_NNNNNN.vts`` (or ``.vtp``) files and keeps ``NAME.pvd`` listing them
    (rewritten atomically after each, so an interrupted run leaves a valid series)."""

    def __init__(self, folder: str | os.PathLike, name: str = "water"):
        self.folder = check_folder(folder)
        self.name = name
        self.entries: list[tuple[float, str]] = []

    @property
    def pvd_path(self) -> Path:
        return self.folder / f"{self.name}.pvd"

    def write(self, step: int, time_s: float, fields: dict, dx: float, origin=(0, 0, 0)) -> Path:
        """The water surface of ``fields`` at ``step`` (see :func:`surface_grid`)."""
        return self.write_dataset(step, time_s, surface_grid(fields, dx, origin), "vts")

    def write_dataset(self, step: int, time_s: float, data, ext: str) -> Path:
        """Any pyvista dataset as ``NAME_{step}.{ext}`` (vts: structured grid, vtp: polydata)."""
        fname = f"{self.name}_{step:06d}.{ext}"
        path = self.folder / fname
        try:
            with atomic_path(path, suffix=f".partial.{ext}") as tmp:
                data.save(str(tmp), binary=True)
        except (OSError, ValueError, RuntimeError) as exc:
            raise InputError(f"--vtk: cannot write {path}: {exc}") from None
        self.entries = [e for e in self.entries if e[1] != fname] + [(float(time_s), fname)]
        self._write_pvd()
        return path

    def _write_pvd(self) -> None:
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                 "  <Collection>"]
        lines += [f'    <DataSet timestep="{t:.9g}" group="" part="0" file={quoteattr(f)}/>'
                  for t, f in self.entries]
        lines += ["  </Collection>", "</VTKFile>", ""]
        with atomic_path(self.pvd_path) as tmp:
            tmp.write_text("\n".join(lines))


def read_series(pvd: str | os.PathLike) -> list[tuple[float, object]]:
    """(time, pyvista mesh) of every entry of a ``.pvd`` (for tests and analysis)."""
    pv = _quiet_pyvista()
    reader = pv.get_reader(str(pvd))
    out = []
    for i, t in enumerate(reader.time_values):
        reader.set_active_time_point(i)
        mesh = reader.read()
        out.append((float(t), mesh[0] if hasattr(mesh, "n_blocks") else mesh))
    return out
