"""Hypothesis strategies and the properties the fuzzers check, shared by the short CI profile
(tests/app/test_fuzz.py) and the long run (bench/fuzz_inputs.py).

Properties:

* scene files: ``lbwater render SCENE -o out.png`` either stops with exit status 2 and one line
  ``lbwater render: error: ...`` on stderr (no traceback, no file written), or the scene passes
  validation and reaches the World (patched to stop there: no device work);
* mesh files (OBJ, PLY, STL): ``app.meshes.load_mesh`` returns valid arrays (finite float32
  vertices, uint32 triangles indexing them) or raises a one-line InputError naming the file;
* Python API: ``lbm.ShallowWater`` and ``raytrace.intersect`` either work (finite results) or
  raise a one-line ValueError/TypeError; never another exception, never a device fault.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import math
import re
import struct
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

# ---- TOML text from Python values ----------------------------------------------------------
_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def toml_key(k: str) -> str:
    return k if _BARE.match(k) else json.dumps(k, ensure_ascii=False)


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        r = repr(v)
        return r if any(c in r for c in ".e") else r + ".0"
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(type(v))


def toml_document(sections: list[tuple[str, bool, dict]], top: dict) -> str:
    """``top`` keys first, then ``[name]`` (or ``[[name]]`` when the flag is set) tables."""
    lines = [f"{toml_key(k)} = {toml_value(v)}" for k, v in top.items()]
    for name, array, table in sections:
        head = ".".join(toml_key(p) for p in name.split("."))
        lines.append(f"[[{head}]]" if array else f"[{head}]")
        lines += [f"{toml_key(k)} = {toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


# ---- scene strategies -------------------------------------------------------------------------
def _schemas() -> dict[str, dict]:
    from app import scene as sc

    return {"scene": sc.SCENE_SCHEMA, "render": sc.RENDER_SCHEMA, "camera": sc.CAMERA_SCHEMA,
            "water": sc.WATER_SCHEMA, "water.rain": sc.RAIN_SCHEMA,
            "water.drops": sc.DROP_SCHEMA, "shading": sc.SHADING_SCHEMA, "sky": sc.SKY_SCHEMA,
            "lights": sc.LIGHT_SCHEMA, "materials.m": sc.MATERIAL_SCHEMA,
            "meshes": sc.MESH_SCHEMA, "pool": sc.POOL_SCHEMA}


ARRAY_SECTIONS = {"lights", "meshes", "water.drops"}

_special_strings = st.sampled_from([
    "", "nan", "NaN", "inf", "-inf", "1e999", "0x10", "true", "slip", "noslip", "exact",
    "cubemap", "procedural", "spot", "directional", "bunny_5k.obj", "mirror_box.obj",
    "missing.obj", "/etc/passwd", "../../x.obj", "/", ".", "scenes/textures/pool_tiles.png",
    "pool_tiles.png", "m", "\x00", "ü" * 3, "a" * 300])
_numbers = st.one_of(
    st.integers(-3, 40), st.integers(), st.sampled_from([0, 1, 2, 3, 16384, 16385, 2**31,
                                                         2**63 - 1, -(2**63)]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-10, 10), st.sampled_from([0.0, -0.0, 1e-300, 1e300, 0.5, 1.333]))
_scalars = st.one_of(_numbers, st.booleans(), _special_strings, st.text(max_size=12))


@functools.cache
def values(depth: int = 3):
    """Any TOML value: scalars, vectors (often of the right length), nested tables and lists."""
    vec = st.lists(_numbers, min_size=0, max_size=5)
    if depth <= 0:
        return st.one_of(_scalars, vec)
    inner = values(depth - 1)
    return st.one_of(_scalars, _scalars, vec, vec,
                     st.lists(inner, max_size=3),
                     st.dictionaries(st.text(min_size=1, max_size=6), inner, max_size=3))


@functools.cache
def _section_strategies(name: str):
    """(keys strategy, {key: value strategy}) of section ``name`` (built once: building
    strategies inside a draw dominates the run time)."""
    schema = _schemas().get(name, {})
    if not schema:
        return st.just([]), {}
    per_key = {}
    for k, field in schema.items():
        good = _good_value(field)
        per_key[k] = st.one_of(good, good, values(2)) if good is not None else values(2)
    keys = st.lists(st.sampled_from(sorted(schema)), max_size=len(schema), unique=True)
    return keys, per_key


_unknown_key = st.text(min_size=1, max_size=8)


@st.composite
def tables(draw, name: str):
    """A table of section ``name`` with some of its keys (good or bad values) and sometimes
    unknown ones."""
    keys, per_key = _section_strategies(name)
    out = {k: draw(per_key[k]) for k in draw(keys)}
    if draw(st.integers(0, 9)) == 0:
        out[draw(_unknown_key)] = draw(values(1))
    return out


@functools.cache
def _good_value(field):
    """Values of the field's kind near and across its range (None: no such strategy)."""
    lo = -1e6 if field.lo is None else field.lo
    hi = 1e6 if field.hi is None else field.hi
    if field.choices:
        return st.sampled_from(field.choices)
    if field.kind == "int":
        return st.integers(int(max(lo, -2**63)) - 2, int(min(hi, 2**63)) + 2)
    if field.kind == "float":
        return st.one_of(st.floats(lo, hi), st.sampled_from([lo, hi, lo - 1, hi * 2]))
    m = re.fullmatch(r"(i?)vec(\d)", field.kind)
    if m:
        n = int(m.group(2))
        elem = (st.integers(int(lo) - 1, int(min(hi, 1e9)) + 1) if m.group(1)
                else st.floats(lo, hi))
        return st.lists(elem, min_size=n, max_size=n)
    if field.kind == "bool":
        return st.booleans()
    return None


_SECTION_NAMES = st.lists(st.sampled_from(sorted(_schemas())), max_size=6, unique=True)
_TOP = st.dictionaries(st.sampled_from(["render", "water", "x", "scene"]), values(2), max_size=1)


@st.composite
def scene_texts(draw) -> str | bytes:
    """A scene file's content: a TOML document built from the schemas with good, bad and
    unknown keys and values, sometimes truncated, spliced with junk, empty or not UTF-8."""
    kind = draw(st.integers(0, 19))
    if kind == 0:
        return b""
    if kind == 1:
        return draw(st.binary(max_size=200))
    names = draw(_SECTION_NAMES)
    sections = []
    for name in names:
        array = name in ARRAY_SECTIONS and draw(st.booleans())
        for _ in range(draw(st.integers(1, 2)) if array else 1):
            sections.append((name, array, draw(tables(name))))
    if draw(st.integers(0, 7)) == 0:
        sections.append((draw(_unknown_key), False, draw(tables(""))))
    top = draw(_TOP) if draw(st.integers(0, 9)) == 0 else {}
    text = toml_document(sections, top)
    if kind == 2:
        text = text[:draw(st.integers(0, len(text)))]
    elif kind == 3:
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(st.text(max_size=10)) + text[at:]
    elif kind == 4:
        return text.encode() + b"\xff\xfe"
    elif kind == 5:  # deep nesting
        depth = draw(st.integers(10, 200))
        text += "deep = " + "[" * depth + "1" + "]" * depth + "\n"
    return text


RENDER_ARGS = st.lists(st.sampled_from([
    ["--width", "16"], ["--height", "0"], ["--spp", "4097"], ["--bounces", "-1"],
    ["--width", "nan"], ["--spp", "2"], ["--bounces", "3"]]), max_size=2)


class ReachedWorld(Exception):
    """Validation passed; the patched World stops here (no device work)."""


def check_scene_cli(content: str | bytes, extra: list[str], workdir: Path,
                    name: str = "scene.toml") -> str:
    """Run ``lbwater render`` on ``content`` in-process; assert the contract; return the
    outcome: "error" (one line, status 2) or "valid" (reached the World)."""
    import app.world
    from app.cli import main

    scene = workdir / name
    if isinstance(content, bytes):
        scene.write_bytes(content)
    else:
        scene.write_text(content, encoding="utf-8", errors="surrogatepass")
    out = workdir / "out.png"

    def stop(*a, **k):
        raise ReachedWorld

    saved = app.world.World
    app.world.World = stop
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                status = main(["render", str(scene), "-o", str(out), *extra])
            except ReachedWorld:
                return "valid"
            except SystemExit as exc:  # argparse: a bad option value
                status = exc.code
    finally:
        app.world.World = saved
    text = err.getvalue()
    assert status == 2, (status, text)
    lines = text.strip().splitlines()
    # one line; argparse's own errors (a bad option value) come after its usage block
    assert len(lines) == 1 or lines[0].startswith("usage: lbwater render"), text
    assert "Traceback" not in text and lines[-1].startswith("lbwater render: error: "), text
    assert not out.exists() and not list(workdir.glob("*.partial*"))
    return "error"


# ---- mesh strategies --------------------------------------------------------------------------
_coord = st.one_of(st.floats(-10, 10), st.floats(-10, 10), st.floats(),
                   st.sampled_from(["nan", "inf", "-inf", "1e400", "x", "", "0x1p3"]))


def _num_text(x) -> str:
    return x if isinstance(x, str) else repr(float(x))


_good_coords = st.lists(st.floats(-10, 10), min_size=3, max_size=3)
_bad_coords = st.lists(_coord, min_size=2, max_size=4)
_bad_index = st.one_of(st.integers(), st.sampled_from(["a", "1/2/3", "1//1", "", "-0", "0"]))


@st.composite
def obj_texts(draw) -> bytes:
    """OBJ text: mostly well-formed vertices and faces (so some files load), with bad
    coordinates, indices out of range, polygons, junk lines and truncation mixed in."""
    def often(good, bad):   # a bad value one time in eight
        return draw(bad) if draw(st.integers(0, 7)) == 0 else draw(good)

    nv = draw(st.integers(0, 8))
    lines = []
    for _ in range(nv):
        cs = often(_good_coords, _bad_coords)
        lines.append("v " + " ".join(_num_text(c) for c in cs))
    for _ in range(draw(st.integers(0, 6))):
        k = often(st.just(3), st.integers(1, 6))
        idx = [often(st.integers(1, max(nv, 1)), st.one_of(st.integers(-nv - 2, nv + 2),
                                                              _bad_index)) for _ in range(k)]
        lines.append("f " + " ".join(str(i) for i in idx))
    for _ in range(draw(st.integers(0, 2))):
        lines.insert(draw(st.integers(0, len(lines))),
                     draw(st.sampled_from(["# c", "vn 0 0 1", "vt 0 0", "g x", "usemtl m",
                                           "l 1 2", "s off", "o x", "garbage"])))
    data = ("\n".join(lines) + "\n").encode("utf-8", "surrogatepass")
    if draw(st.integers(0, 7)) == 0:
        data = data[:draw(st.integers(0, len(data)))]
    return data


@st.composite
def ply_texts(draw) -> bytes:
    nv, nf = draw(st.integers(0, 6)), draw(st.integers(0, 4))
    say_v = draw(st.one_of(st.just(nv), st.just(nv), st.integers(-1, 10)))
    say_f = draw(st.one_of(st.just(nf), st.just(nf), st.integers(-1, 10)))
    head = ["ply", draw(st.sampled_from(["format ascii 1.0", "format ascii 1.0",
                                         "format ascii 1.0", "format binary_little_endian 1.0",
                                         "format junk"])),
            f"element vertex {say_v}", "property float x", "property float y",
            "property float z", f"element face {say_f}",
            "property list uchar int vertex_indices", "end_header"]
    body = []
    def often(good, bad):   # a bad value one time in eight
        return draw(bad) if draw(st.integers(0, 7)) == 0 else draw(good)

    for _ in range(nv):
        body.append(" ".join(_num_text(c) for c in often(_good_coords, _bad_coords)))
    for _ in range(nf):
        k = often(st.just(3), st.integers(0, 5))
        idx = [often(st.integers(0, max(nv - 1, 0)), st.integers(-2, nv + 2))
               for _ in range(k)]
        body.append(" ".join(str(i) for i in [draw(st.one_of(st.just(k), st.integers(0, 9)))]
                             + idx))
    data = ("\n".join(head + body) + "\n").encode()
    if draw(st.integers(0, 4)) == 0:
        data = data[:draw(st.integers(0, len(data)))]
    return data


@st.composite
def stl_bytes(draw) -> bytes:
    if draw(st.booleans()):
        facets = []
        for _ in range(draw(st.integers(0, 4))):
            vs = [" ".join(_num_text(c) for c in draw(st.lists(_coord, min_size=3, max_size=3)))
                  for _ in range(draw(st.integers(2, 4)))]
            facets.append("facet normal 0 0 1\nouter loop\n"
                          + "".join(f"vertex {v}\n" for v in vs) + "endloop\nendfacet\n")
        data = ("solid s\n" + "".join(facets) + "endsolid s\n").encode()
    else:
        n = draw(st.integers(0, 4))
        say = draw(st.one_of(st.just(n), st.integers(0, 2**32 - 1)))
        tris = b"".join(struct.pack("<12fH", *draw(st.lists(
            st.floats(width=32), min_size=12, max_size=12)), 0) for _ in range(n))
        data = b"\0" * 80 + struct.pack("<I", say) + tris
    if draw(st.integers(0, 4)) == 0:
        data = data[:draw(st.integers(0, len(data)))]
    return data


mesh_files = st.one_of(
    st.tuples(st.just(".obj"), obj_texts()), st.tuples(st.just(".ply"), ply_texts()),
    st.tuples(st.just(".stl"), stl_bytes()),
    st.tuples(st.sampled_from([".obj", ".ply", ".stl"]), st.binary(max_size=300)))


def check_mesh_file(suffix: str, data: bytes, workdir: Path) -> str:
    """``load_mesh`` on the file: valid arrays, or a one-line InputError naming it."""
    from app.errors import InputError
    from app.meshes import load_mesh

    path = workdir / f"fuzz{suffix}"
    path.write_bytes(data)
    report: dict = {}
    try:
        V, F = load_mesh(path, report)
    except InputError as exc:
        msg = str(exc)
        assert "\n" not in msg and str(path) in msg, msg
        return "error"
    assert V.dtype == np.float32 and V.ndim == 2 and V.shape[1] == 3 and np.isfinite(V).all()
    assert F.dtype == np.uint32 and F.ndim == 2 and F.shape[1] == 3 and len(F) > 0
    assert int(F.max()) < len(V)
    assert report["dropped_degenerate"] >= 0
    return "valid"


# ---- Python API ---------------------------------------------------------------------------
_shapes = st.sampled_from([(4, 3), (0, 3), (4, 2), (4,), (2, 2, 3), (4, 4), (1, 3)])
_dtypes = st.sampled_from([np.float32, np.float64, np.int32, np.float16, np.uint8, object,
                           np.complex64, bool])


@st.composite
def arrays_for_rays(draw):
    """(origins, directions, tmin, tmax) with wrong shapes, dtypes, NaN, zero directions and
    non-contiguous views mixed in."""
    n = draw(st.integers(0, 6))

    def arr(default_shape):
        good = st.just(default_shape)
        shape = draw(st.one_of(good, good, good, _shapes))
        dtype = draw(st.one_of(st.just(np.float32), st.just(np.float64), _dtypes))
        vals = draw(st.lists(st.one_of(st.floats(-2, 2), st.floats(-2, 2), st.floats(),
                                       st.just(0.0)),
                             min_size=int(np.prod(shape)), max_size=int(np.prod(shape))))
        with np.errstate(all="ignore"):
            a = np.array(vals, dtype=np.float64).reshape(shape)
            try:
                a = a.astype(dtype)
            except (ValueError, TypeError, OverflowError):
                pass
        if draw(st.booleans()) and a.ndim == 2:   # a non-contiguous view of the same values
            a = np.repeat(a, 2, axis=0)[::2]
        return a

    o, d = arr((n, 3)), arr((n, 3))
    tmin = draw(st.one_of(st.just(0.0), st.floats(), st.sampled_from([-1.0, 1e30])))
    tmax = draw(st.one_of(st.just(np.inf), st.floats(), st.just(0.0)))
    return o, d, tmin, tmax


def check_intersect(o, d, tmin, tmax, rt) -> str:
    """``raytrace.intersect`` against a unit quad: results or a one-line ValueError/TypeError;
    every hit it reports is a real hit (t finite, within [tmin, tmax))."""
    from raytrace import intersect

    V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    F = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    try:
        r = intersect(V, F, o, d, tmin=tmin, tmax=tmax, device=rt)
    except (ValueError, TypeError) as exc:
        assert "\n" not in str(exc).strip(), str(exc)
        return "error"
    hit = r["hit"]
    assert np.isfinite(r["t"][hit]).all() and (r["prim"][hit] >= 0).all()
    assert (r["prim"][~hit] == -1).all()
    return "valid"


@st.composite
def solver_calls(draw):
    """Constructor arguments and a few calls for ``lbm.ShallowWater``."""
    def often(good, bad):   # a bad value one time in ten
        return draw(bad) if draw(st.integers(0, 9)) == 0 else draw(good)

    nx = often(st.integers(3, 12), st.sampled_from([0, 2, -1, 3.5, "8", None, True, 70000]))
    ny = often(st.integers(3, 12), st.sampled_from([0, 2, 8.0, None]))
    dx = often(st.floats(0.001, 1), st.one_of(st.floats(), st.sampled_from([0, -1, "0.1"])))
    boundary = often(st.sampled_from(["slip", "noslip"]),
                     st.sampled_from(["SLIP", "periodic", 3, None]))
    keys = st.sampled_from(["depth", "viscosity", "gravity", "drag", "expected_speed",
                            "bogus"])
    vals = st.one_of(st.floats(), st.floats(0.01, 2), st.just(None), st.just("1"))
    opts = {} if draw(st.integers(0, 2)) else draw(st.dictionaries(keys, vals, max_size=2))
    calls = draw(st.lists(st.one_of(
        st.tuples(st.just("add_drop"), st.lists(st.one_of(st.floats(), st.floats(-1, 1)),
                                                min_size=4, max_size=4)),
        st.tuples(st.just("push"), st.lists(st.one_of(st.floats(), st.floats(-1, 1)),
                                            min_size=5, max_size=5)),
        st.tuples(st.just("step"), st.lists(st.sampled_from([0, 1, 3, -1, 2.5]), min_size=1,
                                            max_size=1)),
        st.tuples(st.just("set_state"), st.lists(st.sampled_from(
            ["ok", "nan", "zero", "shape", "noncontig", "int", "negative"]), min_size=1,
            max_size=1))), max_size=4))
    return nx, ny, dx, boundary, opts, calls


def _state(kind: str, ny: int, nx: int):
    h = np.full((ny, nx), 0.1)
    if kind == "nan":
        h[0, 0] = np.nan
    elif kind == "zero":
        h[0, 0] = 0.0
    elif kind == "negative":
        h[-1, -1] = -0.1
    elif kind == "shape":
        h = np.full((nx + 1, ny), 0.1)
    elif kind == "noncontig":
        h = np.full((ny, 2 * nx), 0.1)[:, ::2]
    elif kind == "int":
        h = np.ones((ny, nx), np.int64)
    return h


def check_solver(nx, ny, dx, boundary, opts, calls, rt) -> str:
    """Every call either works or raises a one-line ValueError/TypeError; the water's volume
    stays finite and positive whatever was accepted."""
    import lbm

    def one_line(exc):
        assert "\n" not in str(exc).strip(), str(exc)

    try:
        sim = lbm.ShallowWater(nx, ny, dx, boundary, device=rt, **opts)
    except (ValueError, TypeError) as exc:
        one_line(exc)
        return "error"
    errors = 0
    for name, args in calls:
        try:
            if name == "set_state":
                sim.set_state(_state(args[0], sim.ny, sim.nx))
            else:
                getattr(sim, name)(*args)
        except (ValueError, TypeError) as exc:
            one_line(exc)
            errors += 1
    sim.step(2)
    s = sim.stats()
    assert np.isfinite(s["mass"]) and s["mass"] > 0, s
    return "valid" if not errors else "partly"


@contextlib.contextmanager
def workdir():
    with tempfile.TemporaryDirectory(prefix="lbwater-fuzz-") as d:
        yield Path(d)
