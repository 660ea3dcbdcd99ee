"""The one way to launch a kernel: arguments bound by name, each launch timed under its stage.

::

    k = rt.kernel_launcher("render_frame.cl", "render_gather", stage="render.gather")
    k.bind(rays=rays_buf, params=gather_record)     # by name; unknown names are an error
    k.launch(n, 64)                                 # enqueue + rt.timer.record(stage, event)

    k.set_size(n, 64)      # sizes fixed for this kernel: converted once,
    k()                    # then each launch is one bare enqueue (a BVH build is launch-bound)

Each :class:`Kernel` owns its ``cl.Kernel`` object (the program is built once per runtime and
defines; the object is not shared, so two users never overwrite each other's arguments). The
argument names come from the device (programs are built with ``-cl-kernel-arg-info``); where a
device does not report them, from the kernel's signature in its ``.cl`` source with the object-like
macros of its headers expanded (:func:`parse_kernel_args`). Buffers are re-bound only when a
different buffer is given; by-value scalars and structs only when their bytes change, so binding
every frame costs a byte comparison. Per-launch scalars of a stage travel in one by-value struct
declared in a ``kernels/*.h`` header with a NumPy mirror (as ``LbmParams`` in ``kernels/lbm.h``).
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pyopencl as cl

from kernels.runtime import KERNEL_DIR, Runtime


class KernelArgError(RuntimeError):
    """A kernel argument bound by a name the kernel lacks, with a wrong kind of value, or left
    unbound at launch; the message lists the kernel's argument names."""


#: What a parameter is: a global/constant buffer, local memory, or a value (scalar or struct).
BUFFER, LOCAL, VALUE = "buffer", "local", "value"

#: OpenCL C scalar types passed by value, with their NumPy dtypes.
SCALAR_TYPES = {
    "char": np.int8, "uchar": np.uint8, "short": np.int16, "ushort": np.uint16,
    "int": np.int32, "uint": np.uint32, "long": np.int64, "ulong": np.uint64,
    "float": np.float32, "double": np.float64, "unsigned int": np.uint32,
    "unsigned char": np.uint8, "unsigned short": np.uint16, "unsigned long": np.uint64,
    "size_t": np.uint64, "bool": np.uint8,
}
_VECTOR = re.compile(r"^(char|uchar|short|ushort|int|uint|long|ulong|float|double)(2|3|4|8|16)$")


@dataclasses.dataclass(frozen=True)
class KernelArg:
    """One kernel parameter: its name, what it is (BUFFER, LOCAL, VALUE) and its type name."""

    name: str
    kind: str
    type_name: str


# -- argument names --------------------------------------------------------------------------
_ADDRESS_KIND = {
    cl.kernel_arg_address_qualifier.GLOBAL: BUFFER,
    cl.kernel_arg_address_qualifier.CONSTANT: BUFFER,
    cl.kernel_arg_address_qualifier.LOCAL: LOCAL,
    cl.kernel_arg_address_qualifier.PRIVATE: VALUE,
}


def device_kernel_args(kernel: cl.Kernel) -> tuple[KernelArg, ...] | None:
    """The parameters as the device reports them, or None when it keeps no argument info."""
    info = cl.kernel_arg_info
    try:
        out = []
        for i in range(kernel.num_args):
            name = kernel.get_arg_info(i, info.NAME)
            kind = _ADDRESS_KIND[kernel.get_arg_info(i, info.ADDRESS_QUALIFIER)]
            type_name = kernel.get_arg_info(i, info.TYPE_NAME).strip()
            out.append(KernelArg(name, kind, type_name.rstrip("*").strip()))
        return tuple(out)
    except (cl.RuntimeError, cl.LogicError):
        return None


_COMMENTS = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)
_INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"', re.M)
_DEFINE = re.compile(r"^\s*#\s*define\s+([A-Za-z_]\w*)(?!\()[ \t]*(.*)$", re.M)
_IDENT = re.compile(r"[A-Za-z_]\w*")
_QUALIFIERS = {"__global", "global", "__constant", "constant", "__local", "local",
               "__private", "private", "const", "restrict", "__restrict", "volatile",
               "__read_only", "read_only", "__write_only", "write_only", "unsigned", "struct"}


def _macros(path: Path, seen: set, out: dict) -> None:
    """Object-like ``#define``s of ``path`` and its quoted includes (later ones win)."""
    if path in seen or not path.is_file():
        return
    seen.add(path)
    text = path.read_text().replace("\\\n", " ")
    for inc in _INCLUDE.findall(text):
        _macros(path.parent / inc, seen, out)
    for name, body in _DEFINE.findall(_COMMENTS.sub(" ", text)):
        out[name] = body.strip()


def _expand(text: str, macros: dict) -> str:
    for _ in range(16):
        new = _IDENT.sub(lambda m: macros.get(m.group(0), m.group(0)), text)
        if new == text:
            return text
        text = new
    raise KernelArgError(f"macro expansion does not terminate in {text[:80]!r}")


def parse_kernel_args(source: str | Path, name: str) -> tuple[KernelArg, ...]:
    """The parameters of ``__kernel ... name(...)`` read from a ``.cl`` file under ``kernels/``
    (the fallback where a device keeps no argument info). Object-like macros of the file and its
    includes are expanded (``SCENE_PARAMS``); a parameter's name is its last identifier."""
    path = Path(source)
    if not path.is_absolute():
        path = KERNEL_DIR / path
    macros: dict[str, str] = {}
    _macros(path, set(), macros)
    text = _COMMENTS.sub(" ", path.read_text().replace("\\\n", " "))
    m = re.search(r"\b(?:__kernel|kernel)\b[^;{}]*?\bvoid\s+" + re.escape(name) + r"\s*\(", text)
    if m is None:
        raise KernelArgError(f"{path.name}: no kernel named {name!r} to read arguments from")
    depth, i = 1, m.end()
    while depth:
        if i >= len(text):
            raise KernelArgError(f"{path.name}: unbalanced parentheses after {name}(")
        depth += {"(": 1, ")": -1}.get(text[i], 0)
        i += 1
    params = _expand(text[m.end():i - 1], macros)
    out = []
    parts = [p.strip() for p in params.split(",")]
    if parts == ["void"] or parts == [""]:
        return ()
    for p in parts:
        words = _IDENT.findall(re.sub(r"\[.*?\]", " ", p))
        if not words:
            raise KernelArgError(f"{path.name}: cannot read a parameter name in {p!r}")
        qual = set(words)
        kind = (BUFFER if qual & {"__global", "global", "__constant", "constant"} else
                LOCAL if qual & {"__local", "local"} else VALUE)
        type_words = [w for w in words[:-1] if w not in _QUALIFIERS]
        if "unsigned" in words:
            type_words = ["unsigned", *type_words]
        out.append(KernelArg(words[-1], kind, " ".join(type_words)))
    return tuple(out)


# -- the launcher ----------------------------------------------------------------------------
#: Scalar types whose values cannot change in place (bind skips converting an equal one).
_IMMUTABLE = frozenset({int, float, bool, np.int8, np.uint8, np.int16, np.uint16, np.int32,
                        np.uint32, np.int64, np.uint64, np.float32, np.float64})
_INTEGRAL = frozenset({int, bool, np.int8, np.uint8, np.int16, np.uint16, np.int32, np.uint32,
                       np.int64, np.uint64})
_NOTHING = object()


def _sizes(global_size, local_size) -> tuple[tuple, tuple | None]:
    """Global size rounded up to a multiple of the local size (kernels guard their index), at
    least 1 per dimension."""
    gs = tuple(max(int(g), 1) for g in np.atleast_1d(global_size))
    if local_size is None:
        return gs, None
    ls = tuple(int(v) for v in np.atleast_1d(local_size))
    return tuple(-(-g // w) * w for g, w in zip(gs, ls, strict=True)), ls


class Kernel:
    """One kernel of ``kernels/<source>``, its arguments bound by name, launched as ``stage``.

    Make it through :meth:`kernels.runtime.Runtime.kernel_launcher`. :meth:`bind` takes buffers
    (``cl.Buffer``), ``cl.LocalMemory`` for local parameters, and values: NumPy scalars, Python
    numbers (converted to the parameter's scalar type) or struct records (``np.void`` or a
    one-element structured array) whose size must match the struct's dtype mirror.
    """

    __slots__ = ("rt", "source", "name", "stage", "kernel", "args", "_index", "_held",
                 "_raw", "_struct", "_unbound", "global_size", "local_size", "_size_cache")

    def __init__(self, rt: Runtime, source: str, name: str, *, stage: str,
                 defines: dict | None = None):
        self.rt, self.source, self.name, self.stage = rt, source, name, str(stage)
        prg = rt.program(source, defines)
        try:
            self.kernel = cl.Kernel(prg, name)
        except cl.Error as exc:
            from kernels.runtime import KernelBuildError
            raise KernelBuildError(f"{source}: no kernel named {name!r} ({exc})") from None
        self.args = rt.kernel_args(source, name, defines, self.kernel)
        if len(self.args) != self.kernel.num_args:
            raise KernelArgError(f"{source}:{name}: read {len(self.args)} parameters, the "
                                 f"device reports {self.kernel.num_args}")
        self._index = {a.name: i for i, a in enumerate(self.args)}
        self._held: list = [None] * len(self.args)
        # the last Python/NumPy scalar bound to a value argument (immutable: the same type and
        # value give the same bytes, so no conversion), and the struct arguments
        self._raw: list = [_NOTHING] * len(self.args)
        self._struct = [a.kind == VALUE and a.type_name not in SCALAR_TYPES
                        and _VECTOR.match(a.type_name) is None for a in self.args]
        self._unbound = set(self._index)
        self.global_size: tuple | None = None
        self.local_size: tuple | None = None
        self._size_cache: dict = {}

    @property
    def arg_names(self) -> list[str]:
        return [a.name for a in self.args]

    def _unknown(self, name: str) -> KernelArgError:
        return KernelArgError(f"{self.source}:{self.name} has no argument {name!r}; its "
                              f"arguments: {', '.join(self.arg_names)}")

    def bind(self, **values) -> Kernel:
        """Bind arguments by name; a buffer is set when it is another buffer, a value when its
        bytes change. Returns self."""
        held, k = self._held, self.kernel
        for name, value in values.items():
            i = self._index.get(name)
            if i is None:
                raise self._unknown(name)
            arg = self.args[i]
            if arg.kind == BUFFER:
                if value is held[i]:
                    continue
                if not isinstance(value, cl.MemoryObjectHolder):
                    raise KernelArgError(f"{self.source}:{self.name}: argument {name!r} is a "
                                         f"buffer, got {type(value).__name__}")
                k.set_arg(i, value)
                held[i] = value
            elif arg.kind == LOCAL:
                if not isinstance(value, cl.LocalMemory):
                    raise KernelArgError(f"{self.source}:{self.name}: argument {name!r} is "
                                         f"local memory, give cl.LocalMemory(nbytes)")
                k.set_arg(i, value)
                held[i] = value
            else:
                tv = type(value)
                if tv is np.void and self._struct[i]:
                    if value.dtype.names is None:
                        data = self._value_bytes(arg, value)
                    else:
                        data = value.tobytes()  # a record may have changed in place: compare
                elif tv in _IMMUTABLE:
                    raw = self._raw[i]
                    if type(raw) is tv and raw == value and (value or tv in _INTEGRAL):
                        continue  # (an equal float's bits are equal, but for 0.0 and -0.0)
                    data = self._value_bytes(arg, value)
                    self._raw[i] = value
                else:
                    data = self._value_bytes(arg, value)
                    self._raw[i] = _NOTHING  # the last scalar no longer says what is set
                if data == held[i]:
                    continue
                k.set_arg(i, np.frombuffer(data, np.uint8))
                held[i] = data
            self._unbound.discard(name)
        return self

    def _value_bytes(self, arg: KernelArg, value) -> bytes:
        scalar = SCALAR_TYPES.get(arg.type_name)
        vec = _VECTOR.match(arg.type_name)
        if vec is not None:
            return self._vector_bytes(arg, value, np.dtype(SCALAR_TYPES[vec.group(1)]),
                                      int(vec.group(2)))
        if isinstance(value, cl.MemoryObjectHolder | cl.LocalMemory):
            raise KernelArgError(f"{self.source}:{self.name}: argument {arg.name!r} is a value "
                                 f"({arg.type_name}), got a {type(value).__name__}")
        if scalar is not None:
            want = np.dtype(scalar)
            src = np.asarray(value)
            bad = src.size != 1 or src.dtype.kind not in "biuf" or (
                want.kind in "iu" and src.dtype.kind == "f")
            if not bad:
                conv = src.reshape(()).astype(want)
                bad = want.kind in "iu" and int(conv) != int(src.reshape(()))
            if bad:
                raise KernelArgError(f"{self.source}:{self.name}: argument {arg.name!r} "
                                     f"({arg.type_name}) cannot hold {value!r}")
            return conv.tobytes()
        if not isinstance(value, np.void | np.ndarray) or value.dtype.names is None:
            raise KernelArgError(f"{self.source}:{self.name}: argument {arg.name!r} is a "
                                 f"{arg.type_name} by value: give its NumPy record, got "
                                 f"{type(value).__name__}")
        if isinstance(value, np.ndarray) and value.size != 1:
            raise KernelArgError(f"{self.source}:{self.name}: argument {arg.name!r} takes one "
                                 f"{arg.type_name} record, got {value.size}")
        return value.tobytes()

    def _vector_bytes(self, arg: KernelArg, value, base: np.dtype, n: int) -> bytes:
        src = np.asarray(value)
        slots = 4 if n == 3 else n  # a 3-vector occupies four
        if src.dtype.names is not None or src.size not in (n, slots) or (
                base.kind in "iu" and src.dtype.kind == "f"):
            raise KernelArgError(f"{self.source}:{self.name}: argument {arg.name!r} is "
                                 f"{arg.type_name}: give {n} numbers, got {value!r}")
        out = np.zeros(slots, base)
        out[: src.size] = src.reshape(-1)
        return out.tobytes()

    def set_size(self, global_size, local_size=None) -> Kernel:
        """Fix the launch sizes of :meth:`__call__` (converted and rounded once). Returns self."""
        self.global_size, self.local_size = _sizes(global_size, local_size)
        return self

    def _check_bound(self) -> None:
        if self._unbound:
            raise KernelArgError(f"{self.source}:{self.name}: arguments not bound: "
                                 f"{', '.join(a for a in self.arg_names if a in self._unbound)}")

    def __call__(self, wait_for=None) -> cl.Event:
        """Enqueue with the sizes of :meth:`set_size`; the event is recorded under the stage."""
        if self._unbound:
            self._check_bound()
        if self.global_size is None:
            raise KernelArgError(f"{self.source}:{self.name}: no launch size: call set_size() "
                                 "or launch(global_size)")
        rt = self.rt
        evt = cl.enqueue_nd_range_kernel(rt.queue, self.kernel, self.global_size,
                                         self.local_size, wait_for=wait_for)
        return rt.timer.record(self.stage, evt)

    def enqueue(self, global_size: tuple, local_size: tuple | None = None, *,
                wait_for=None) -> cl.Event:
        """Enqueue over sizes already prepared as tuples of ints, each global size a multiple of
        its local size (no conversion: the per-frame path of a driver that plans its sizes)."""
        if self._unbound:
            self._check_bound()
        rt = self.rt
        evt = cl.enqueue_nd_range_kernel(rt.queue, self.kernel, global_size, local_size,
                                         wait_for=wait_for)
        return rt.timer.record(self.stage, evt)

    def launch(self, global_size=None, local_size=None, *, wait_for=None) -> cl.Event:
        """Enqueue over ``global_size`` (rounded up to a multiple of ``local_size``; kernels
        guard their index), or the sizes of :meth:`set_size` when None. Records the event."""
        if global_size is None:
            return self(wait_for)
        if self._unbound:
            self._check_bound()
        try:
            gs, ls = self._size_cache[global_size, local_size]
        except KeyError:
            gs, ls = self._size_cache[global_size, local_size] = _sizes(global_size, local_size)
            if len(self._size_cache) > 64:  # sizes that change every launch: stay bounded
                self._size_cache.clear()
        except TypeError:  # an unhashable size (a NumPy array)
            gs, ls = _sizes(global_size, local_size)
        rt = self.rt
        evt = cl.enqueue_nd_range_kernel(rt.queue, self.kernel, gs, ls, wait_for=wait_for)
        return rt.timer.record(self.stage, evt)

