"""Frame snapshots: the few arrays a frame's image depends on once the water has stepped, so one
process can step the water (sequential in time) and others render its frames (app.cluster).

A snapshot is what :meth:`app.world.World.snapshot_frame` returns and
:meth:`app.world.World.render_snapshot` takes (bytes, docs/frame_api.md#snapshots):

    b"LBWS" version(u8) header_bytes(u32 LE) header(JSON, utf-8) zlib(payload)

The header names the frame (index, simulated time, LBM steps, what the water guard saw), the
camera (eye, target, up, fov, as ``World.camera``), the caustics mode and each array of the
payload (name, dtype, shape) in order. The arrays, raw little-endian bytes:

    eta          float32 (ny, nx)     bed + h, exactly what the surface kernel turns into vertices
    transforms   float32 (n, 3, 4)    the scene's device transform rows (boats move them)
    caustic_map  float32 (texels, 4)  the caustic map the render stage reads (caustics on only)

The header stays uncompressed so a driver reads it (:func:`peek`) without inflating the arrays.
"""

from __future__ import annotations

import dataclasses
import json
import struct
import zlib

import numpy as np

MAGIC = b"LBWS"
VERSION = 1
#: zlib level: heights are float32 mantissas that barely compress; level 1 is several times
#: faster than the default for nearly the same size.
LEVEL = 1
_HEAD = struct.Struct("<4sBI")


class SnapshotError(RuntimeError):
    """Bytes that are not a snapshot of this version, or a snapshot of another scene."""


@dataclasses.dataclass
class Snapshot:
    """A decoded snapshot: the header's fields and the payload's arrays by name."""

    frame: int
    sim_time: float
    lbm_steps: int
    guard: dict
    camera: tuple
    caustics: str
    arrays: dict


def encode(*, frame: int, sim_time: float, lbm_steps: int, guard: dict, camera: tuple,
           caustics: str, arrays: dict) -> bytes:
    """Snapshot bytes of one frame; ``arrays``: name -> little-endian NumPy array."""
    specs, parts = [], []
    for name, a in arrays.items():
        a = np.ascontiguousarray(a)
        if a.dtype.byteorder == ">":
            raise SnapshotError(f"snapshot array {name} is big-endian")
        specs.append([name, a.dtype.str, list(a.shape)])
        parts.append(a.tobytes())
    header = {"frame": int(frame), "sim_time": float(sim_time), "lbm_steps": int(lbm_steps),
              "guard": {"nan": bool(guard.get("nan", False)),
                        "acted": bool(guard.get("acted", False)),
                        "report": str(guard.get("report", "ok"))},
              "camera": [list(map(float, camera[0])), list(map(float, camera[1])),
                         list(map(float, camera[2])), float(camera[3])],
              "caustics": str(caustics), "arrays": specs}
    head = json.dumps(header, separators=(",", ":")).encode()
    return _HEAD.pack(MAGIC, VERSION, len(head)) + head + zlib.compress(b"".join(parts), LEVEL)


def _split(snap) -> tuple[dict, memoryview]:
    mv = memoryview(snap)
    if len(mv) < _HEAD.size:
        raise SnapshotError(f"not a snapshot: {len(mv)} bytes")
    magic, version, n = _HEAD.unpack_from(mv)
    if magic != MAGIC or version != VERSION:
        raise SnapshotError(f"not a version-{VERSION} snapshot (starts {bytes(mv[:5])!r})")
    try:
        header = json.loads(bytes(mv[_HEAD.size:_HEAD.size + n]))
    except ValueError as exc:
        raise SnapshotError(f"snapshot header is not JSON ({exc})") from None
    return header, mv[_HEAD.size + n:]


def peek(snap) -> dict:
    """The header of a snapshot (frame, sim_time, lbm_steps, guard, camera, caustics, arrays),
    without inflating its arrays."""
    return _split(snap)[0]


def decode(snap) -> Snapshot:
    """The snapshot's header and arrays (copies owned by the caller)."""
    header, body = _split(snap)
    try:
        raw = zlib.decompress(body)
    except zlib.error as exc:
        raise SnapshotError(f"snapshot payload does not inflate ({exc})") from None
    arrays, off = {}, 0
    for name, dtype, shape in header["arrays"]:
        dt = np.dtype(dtype)
        n = dt.itemsize * int(np.prod(shape, dtype=np.int64))
        if off + n > len(raw):
            raise SnapshotError(f"snapshot payload ends inside array {name}")
        arrays[name] = np.frombuffer(raw, dt, n // dt.itemsize, off).reshape(shape).copy()
        off += n
    if off != len(raw):
        raise SnapshotError(f"snapshot payload has {len(raw) - off} bytes past its arrays")
    eye, target, up, fov = header["camera"]
    return Snapshot(int(header["frame"]), float(header["sim_time"]), int(header["lbm_steps"]),
                    dict(header["guard"]), (tuple(eye), tuple(target), tuple(up), float(fov)),
                    str(header["caustics"]), arrays)
