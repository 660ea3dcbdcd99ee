"""Atomic output: write to a temporary file beside the target, then rename.

Commands call :func:`check_output` on every output path before any work, so a path that cannot be
written fails in a moment, not after a long render; errors name the path the user gave, never the
temporary file.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

from app.errors import InputError


def _label(path, option: str) -> str:
    return f"{option} {str(path)!r}" if option else f"{str(path)!r}"


def check_output(path: str | os.PathLike, option: str = "",
                 suffixes: tuple[str, ...] = ()) -> Path:
    """``path`` as a Path if a file can be written there, else a one-line
    :class:`~app.errors.InputError` naming ``option`` (``"--save"``), the path and the reason:
    a wrong extension (``suffixes``, lower case with the dot), a folder in the way, a parent that
    is a file, or a folder that refuses new files. Missing folders are fine (they are made when
    the file is written). Nothing is left behind."""
    p = Path(path)
    label = _label(path, option)
    if suffixes and p.suffix.lower() not in suffixes:
        raise InputError(f"{label} must end in {' or '.join(suffixes)}")
    if str(path).endswith(("/", os.sep)) or p.name in ("", ".", ".."):
        raise InputError(f"{label} names a folder; give a file name")
    if p.is_dir():
        raise InputError(f"{label} is a folder; give a file name")
    _check_folder(p.absolute().parent, label, p.is_absolute())
    return p


def _check_folder(folder: Path, label: str, absolute: bool) -> None:
    """New files can be made in ``folder``, or (missing) in its nearest existing ancestor."""
    anc = folder
    while not anc.exists() and not anc.is_symlink() and anc != anc.parent:
        anc = anc.parent
    if not anc.is_dir():
        shown = anc if absolute else os.path.relpath(anc)
        raise InputError(f"{label}: {shown} is not a directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=".lbwater.", suffix=".probe", dir=anc)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise InputError(f"{label}: cannot write in {anc} ({exc.strerror or exc})") from None


def check_output_dir(path: str | os.PathLike, option: str = "") -> Path:
    """``path`` as a Path if files can be written in that folder (made when missing), else a
    one-line InputError naming ``option``, the path and the reason."""
    p = Path(path)
    label = _label(path, option)
    if p.exists() and not p.is_dir():
        raise InputError(f"{label} is a file, not a folder")
    _check_folder(p.absolute(), label, p.is_absolute())
    return p


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None):
    """Yield a temporary path in the target's folder; on success rename it onto ``path``.

    On any error the temporary file is removed and ``path`` is left as it was. An OSError in
    making, writing or renaming the file becomes an InputError naming ``path`` (not the
    temporary file).
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.",
                                   suffix=suffix or path.suffix + ".partial", dir=path.parent)
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes the file private; outputs are ordinary files
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if exc.filename in (tmp, str(path)) or exc.filename2 in (tmp, str(path)):
            raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None
        raise
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_json(path, obj) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=1) + "\n")


def write_csv(path, rows: list[dict]) -> None:
    """Rows of dicts as CSV, columns in first-seen order."""
    import csv

    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)
