"""Triangle meshes from files: ``load_mesh(path)`` -> float32 (n,3) vertices, uint32 (m,3) tris.

Files are read with pyvista (imported only when needed: ``pv.read(path).triangulate().clean()``)
and the result is cached as ``.npz`` in a ``cache/`` folder beside the file (or, when that folder is
not writable, in the user cache folder). A cache records the SHA-1 of the file it came from, so an
edited file is re-read. Machines without pyvista (the GPU box) load the committed caches.

What is refused, each with one line naming the file and the problem: a missing, empty or
unreadable file (VTK's own first message, its log silenced), an OBJ face index that is 0, not an
integer or out of range (with the line), any face whose vertex index is out of range (PLY, STL),
NaN or infinite coordinates, a file with no triangles. What is repaired: polygons are split into
triangles, and triangles that are degenerate (two corners the same vertex, also after coincident
points are merged) are dropped; :func:`load_mesh` reports their count in ``report``.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from app.errors import InputError

#: Bump when the loader's output for the same file changes; part of every cache.
CACHE_VERSION = 1
MODELS_DIR = Path(__file__).resolve().parent.parent / "scenes" / "models"


def _sha1(path: Path) -> str:
    h = hashlib.sha1()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _cache_candidates(path: Path) -> list[Path]:
    user = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "lbwater" / "meshes"
    return [path.parent / "cache" / f"{path.name}.npz", user / f"{path.stem}-{path.suffix[1:]}.npz"]


def _read_cache(cache: Path, digest: str):
    try:
        with np.load(cache) as z:
            if str(z["sha1"]) != digest or int(z["version"]) != CACHE_VERSION:
                return None
            dropped = int(z["dropped"]) if "dropped" in z.files else None
            return z["vertices"].astype(np.float32), z["triangles"].astype(np.uint32), dropped
    except (OSError, KeyError, ValueError):
        return None


def _write_cache(path: Path, digest: str, vertices: np.ndarray, triangles: np.ndarray,
                 dropped: int = 0) -> None:
    from app.io import atomic_path

    for cache in _cache_candidates(path):
        try:
            with atomic_path(cache, suffix=".partial.npz") as tmp:
                np.savez_compressed(tmp, vertices=vertices, triangles=triangles,
                                    sha1=np.array(digest), version=np.array(CACHE_VERSION),
                                    dropped=np.array(dropped))
                os.chmod(tmp, 0o644)
            return
        except (OSError, InputError):  # a cache is optional
            continue


class _Collect(logging.Handler):
    def __init__(self):
        super().__init__()
        self.messages: list[str] = []

    def emit(self, record):
        self.messages.append(record.getMessage())


@contextlib.contextmanager
def quiet_vtk():
    """Silence VTK around a read and collect what it said: yields a list that receives its
    messages (VTK's output window goes to Python's logging through pyvista, its warnings to
    ``warnings``, and anything written straight to file descriptor 2 is captured too)."""
    messages: list[str] = []
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    collect = _Collect()
    root.handlers[:] = [collect]
    sys.stderr.flush()
    saved_fd = os.dup(2)
    with tempfile.TemporaryFile() as err, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        os.dup2(err.fileno(), 2)
        try:
            yield messages
        finally:
            sys.stderr.flush()
            os.dup2(saved_fd, 2)
            os.close(saved_fd)
            root.handlers[:] = handlers
            root.setLevel(level)
            err.seek(0)
            raw = err.read().decode("utf-8", "replace").splitlines()
            messages += collect.messages + [str(w.message) for w in caught] + raw


def _vtk_problem(messages: list[str]) -> str:
    """The first specific thing VTK said, on one line (its messages carry multi-line object
    dumps; "Algorithm vtkXReader (0x...) returned failure" says only that the reader failed)."""
    import re

    generic = ""
    for m in messages:
        m = re.sub(r"\x1b\[[0-9;]*m", "", m)            # vtkLogger's colours
        line = m.strip().splitlines()[0].strip() if m.strip() else ""
        line = re.sub(r"^.*?\b(WARN|ERR|ERROR|INFO)\|\s*", "", line)   # and its prefix
        line = re.sub(r"\s*\(0x[0-9a-f]+\)", "", line)[:200]
        if not line:
            continue
        if re.match(r"Algorithm \w+ returned failure", line) or "raised an error" in line:
            generic = generic or f"{line.split()[1]} failed"
            continue
        return line
    return generic


def check_obj_indices(path: Path) -> None:
    """One-line InputError for the first OBJ face index that is not an integer, is 0 or lies
    outside the file's vertices (VTK would read past its vertex array)."""
    n_vertices, faces = 0, []
    with open(path, "rb") as fh:
        for lineno, raw in enumerate(fh, 1):
            if raw.startswith(b"v ") or raw.startswith(b"v\t"):
                n_vertices += 1
            elif raw.startswith(b"f ") or raw.startswith(b"f\t"):
                faces.append((lineno, n_vertices, raw.split()[1:]))
    for lineno, seen, words in faces:
        for w in words:
            head = w.split(b"/")[0]
            try:
                i = int(head)
            except ValueError:
                raise InputError(f"{path}:{lineno}: face index {head.decode(errors='replace')!r}"
                                 " is not an integer") from None
            j = i - 1 if i > 0 else seen + i   # 1-based, or relative to the vertices so far
            if i == 0 or not 0 <= j < n_vertices:
                raise InputError(f"{path}:{lineno}: face index {i} is out of range "
                                 f"(the file has {n_vertices} vertices; OBJ counts from 1)")


def _check_cell_indices(path: Path, data) -> None:
    """Every cell of ``data`` (VTK PolyData) names existing points; VTK keeps out-of-range ids
    that later filters would read past the point array with."""
    from vtkmodules.util.numpy_support import vtk_to_numpy

    for cells in (data.GetPolys(), data.GetStrips(), data.GetLines(), data.GetVerts()):
        conn = vtk_to_numpy(cells.GetConnectivityArray()) if cells is not None else None
        if conn is not None and conn.size and (conn.min() < 0 or conn.max() >= data.n_points):
            raise InputError(f"{path}: a face names vertex {int(conn.max())} (0-based) but the "
                             f"file has {data.n_points} vertices")


def _read_with_pyvista(path: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """Vertices, triangles and the number of degenerate triangles dropped."""
    try:
        import pyvista as pv
    except ImportError:
        raise InputError(f"{path}: reading meshes needs pyvista (pip install pyvista), and no "
                         "up-to-date .npz cache was found beside it") from None
    if path.stat().st_size == 0:
        raise InputError(f"{path}: the file is empty")
    if path.suffix.lower() == ".obj":
        check_obj_indices(path)
    with quiet_vtk() as said:
        try:
            data = pv.read(str(path))
            error = None
        except Exception as exc:  # vtk raises many kinds; the user needs one line
            data, error = None, f"{type(exc).__name__}: {str(exc).strip().splitlines()[0]}" \
                if str(exc).strip() else type(exc).__name__
    problem = _vtk_problem(said)
    if data is None:
        raise InputError(f"{path}: unreadable mesh ({problem or error})")
    if not isinstance(data, pv.PolyData):
        with quiet_vtk():
            data = data.extract_surface()
    if data.n_cells == 0:
        raise InputError(f"{path}: no triangles in the file" + (f" ({problem})" if problem else ""))
    _check_cell_indices(path, data)
    # clean() merges coincident points; triangles that collapse become lines or points and are
    # moved out of `faces`, so what is left in `faces` is a valid triangle list.
    with quiet_vtk() as said:
        try:
            tris = data.triangulate()
            mesh = tris.clean()
        except Exception as exc:  # noqa: BLE001 (vtk raises many kinds)
            mesh, error = None, type(exc).__name__
    if mesh is None:
        raise InputError(f"{path}: cannot triangulate the mesh ({_vtk_problem(said) or error})")
    faces = np.asarray(mesh.faces)
    if faces.size == 0 and tris.GetNumberOfPolys() == 0:
        raise InputError(f"{path}: no faces in the file (points or lines only)")
    if faces.size == 0:
        raise InputError(f"{path}: no triangles in the file ({tris.GetNumberOfPolys()} faces, "
                         "all degenerate once coincident points are merged)")
    if faces.size % 4 or np.any(faces.reshape(-1, 4)[:, 0] != 3):
        raise InputError(f"{path}: polygons left after triangulation (not a surface mesh?)")
    triangles = faces.reshape(-1, 4)[:, 1:].astype(np.uint32)
    vertices = np.asarray(mesh.points, dtype=np.float32).reshape(-1, 3)
    return vertices, triangles, int(tris.GetNumberOfPolys()) - len(triangles)


_READER = None   # a one-process pool that reads mesh files with VTK, made on first use


def _ignore_sigint() -> None:
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)   # Ctrl-C is the parent's to report


def _read_isolated(path: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`_read_with_pyvista` in a separate process: VTK's readers crash (segfault) on some
    malformed files (the fuzzer found PLY files with negative face indices or a truncated
    binary body), and a crash there must be a one-line error here, not the end of the program.
    """
    global _READER
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    if _READER is None:
        import atexit

        _READER = ProcessPoolExecutor(max_workers=1, initializer=_ignore_sigint,
                                      mp_context=multiprocessing.get_context("spawn"))
        atexit.register(_READER.shutdown)   # before the interpreter tears the module down
    try:
        return _READER.submit(_read_with_pyvista, path).result()
    except BrokenProcessPool:
        _READER = None
        raise InputError(f"{path}: the mesh reader (VTK) crashed on this file: it is malformed "
                         f"or not a {path.suffix.lstrip('.').upper() or 'mesh'} file") from None


def validate_mesh(vertices: np.ndarray, triangles: np.ndarray, name: str = "mesh"
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Return C-contiguous float32 (n,3) / uint32 (m,3) copies or raise a one-line InputError
    (the checks are :func:`raytrace.bvh.check_mesh_arrays`', the BVH's own)."""
    from raytrace.bvh import check_mesh_arrays

    try:
        return check_mesh_arrays(vertices, triangles, name)
    except ValueError as exc:
        raise InputError(str(exc)) from None


def load_mesh(path: str | os.PathLike, report: dict | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """Vertices float32 (n,3) and triangles uint32 (m,3) of the mesh file ``path``.

    A bare name (``"dragon_100k.obj"``) is looked up in ``scenes/models/`` when it is not a file
    in the working folder. Results are cached (see the module docstring). ``report``, when
    given, receives ``dropped_degenerate``: the degenerate triangles dropped (None when the
    mesh came from a cache written before that count was kept).
    """
    report = {} if report is None else report
    path = Path(path)
    if not path.is_file() and not path.is_absolute() and (MODELS_DIR / path).is_file():
        path = MODELS_DIR / path
    if not path.is_file():
        raise InputError(f"{path}: mesh file not found")
    digest = _sha1(path)
    for cache in _cache_candidates(path):
        if cache.is_file():
            hit = _read_cache(cache, digest)
            if hit is not None:
                report["dropped_degenerate"] = hit[2]
                return validate_mesh(*hit[:2], name=str(path))
    vertices, triangles, dropped = _read_isolated(path)
    vertices, triangles = validate_mesh(vertices, triangles, name=str(path))
    _write_cache(path, digest, vertices, triangles, dropped)
    report["dropped_degenerate"] = dropped
    return vertices, triangles


def height_field_grid(n: int, t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The BVH benchmark's water-like height field, exactly as NVIDIA Warp's anchor script's
    grid() (``app.bench_bvh``): n x n vertices over [-1,1]^2, 2 (n-1)^2 triangles; ``t`` shifts
    the waves (a deformed grid of the same topology)."""
    x = np.linspace(-1, 1, n, dtype=np.float32)
    X, Z = np.meshgrid(x, x)
    Y = 0.03 * np.sin(9 * X + t) * np.cos(7 * Z) + 0.01 * np.sin(31 * (X + Z))
    pts = np.stack([X, Y, Z], -1).reshape(-1, 3).astype(np.float32)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1], i[:-1, 1:], i[1:, :-1], i[1:, 1:]
    tri = np.stack([np.stack([a, c, b], -1), np.stack([b, c, d], -1)], -2).reshape(-1, 3)
    return pts, tri.astype(np.uint32)


# ---- shading attributes for the renderer: vertex normals, OBJ material groups, MTL colours ----


def smooth_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (unit; zero where no triangle contributes)."""
    V = V.astype(np.float64)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    acc = np.zeros_like(V)
    for k in range(3):
        np.add.at(acc, F[:, k], n)
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    return (acc / np.where(length > 0, length, 1.0)).astype(np.float32)


def read_mtl(path: Path) -> dict:
    """{material name: {'Kd': rgb, 'Ks': rgb, 'Ns': float}} from an MTL file (missing: {})."""
    out: dict = {}
    cur = None
    if not path.is_file():
        return out
    for line in path.read_text(errors="replace").splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "newmtl" and len(parts) > 1:
            cur = out.setdefault(" ".join(parts[1:]), {})
        elif cur is not None and parts[0] in ("Kd", "Ks") and len(parts) >= 4:
            cur[parts[0]] = tuple(float(x) for x in parts[1:4])
        elif cur is not None and parts[0] == "Ns" and len(parts) >= 2:
            cur["Ns"] = float(parts[1])
    return out


def load_mesh_groups(path: Path, n_tris: int):
    """``(ids, names)``: per-triangle MTL material ids of an OBJ, aligned with
    :func:`load_mesh`'s triangles, and the material names; None when the file has no groups.
    Cached beside the file as ``cache/<name>.groups.npz`` (machines without pyvista read it)."""
    from app.io import atomic_path

    if path.suffix.lower() != ".obj":
        return None
    text = path.read_bytes()
    if b"usemtl" not in text:
        return None
    digest = hashlib.sha1(text).hexdigest()
    cache = path.parent / "cache" / f"{path.name}.groups.npz"
    if cache.is_file():
        with np.load(cache) as z:
            if str(z["sha1"]) == digest and len(z["ids"]) == n_tris:
                return z["ids"], [str(x) for x in z["names"]]
    try:
        import pyvista as pv
    except ImportError:
        raise InputError(f"{path}: material groups need pyvista or an up-to-date cache "
                         f"{cache}") from None
    with quiet_vtk():
        mesh = pv.read(str(path)).triangulate().clean()
    if "MaterialIds" not in mesh.cell_data or mesh.n_cells != n_tris:
        return None
    ids = np.asarray(mesh.cell_data["MaterialIds"], np.int32)
    names = [str(x) for x in mesh.field_data["MaterialNames"]]
    try:
        with atomic_path(cache, suffix=".partial.npz") as tmp:
            np.savez_compressed(tmp, ids=ids, names=np.array(names), sha1=np.array(digest))
    except (OSError, InputError):
        pass
    return ids, names


def mtl_path(path: Path) -> Path:
    for line in path.read_text(errors="replace").splitlines()[:50]:
        if line.startswith("mtllib"):
            cand = path.parent / line.split(maxsplit=1)[1].strip()
            if cand.is_file():
                return cand
    return path.with_suffix(".mtl")
