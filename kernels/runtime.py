"""One OpenCL context and profiling queue per device, with program and kernel caches.

Programs are built from the ``.cl`` files beside this module with ``-I`` pointing here, so sources
use real ``#include "common.h"``. Build-time constants are passed as ``-D`` defines (part of the
cache key); a hash of every header is added too, so no driver cache survives a header edit.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shlex
import signal
import sys
import tempfile
import threading
import warnings
from pathlib import Path

import numpy as np
import pyopencl as cl

from kernels.device import cl_std_option, select_device
from kernels.events import EventKeeper
from kernels.timing import StageTimer

KERNEL_DIR = Path(__file__).resolve().parent


#: How scenes store their BLASes for traversal (kernels/scene.h, TRACE_WIDE): binary (GPUs) or
#: wide (CPUs, raytrace.bvh_wide).
BVH_LAYOUTS = ("binary", "wide")


def check_bvh_layout(layout: str) -> str:
    """``layout`` if it is one of :data:`BVH_LAYOUTS`, else a one-line ValueError."""
    if layout not in BVH_LAYOUTS:
        raise ValueError(f"BVH layout must be one of {', '.join(BVH_LAYOUTS)}, got {layout!r}")
    return layout


class KernelBuildError(RuntimeError):
    """A ``.cl`` program failed to compile. The first line names the file, the device and the
    file the build log was written to; the log follows on the next lines."""


#: Seconds a build may take before the one-line "building kernels" note is printed (a build from
#: the driver's cache takes a few ms to ~0.1 s; a real build of a large program ~1 s on 2 cores).
BUILD_NOTE_AFTER_S = 0.5
_build_note_shown = False


def driver_cache_dir(device: cl.Device) -> str:
    """Where ``device``'s compiled programs are cached between runs (the driver's own cache for
    PoCL and NVIDIA, which pyopencl relies on; pyopencl's binary cache otherwise)."""
    home = Path.home()
    xdg = Path(os.environ.get("XDG_CACHE_HOME") or home / ".cache")
    platform = device.platform.name.lower()
    if "portable computing language" in platform:
        return os.environ.get("POCL_CACHE_DIR") or str(xdg / "pocl" / "kcache")
    if "nvidia" in platform:
        return os.environ.get("CUDA_CACHE_PATH") or str(home / ".nv" / "ComputeCache")
    return str(xdg / "pyopencl")


@contextlib.contextmanager
def _build_guard(device: cl.Device):
    """Around a program build: print a one-line note when it is slow (not cached), and hold a
    Ctrl-C until the compiler returns; the interrupt is raised right after. Holding it takes two
    things: this thread blocks SIGINT, and the process-wide disposition is ours for the build
    (LLVM, loaded with the OpenCL compiler, installs a SIGINT handler that deletes the
    compilation's temporary files, so a Ctrl-C taken by any other thread failed the build with
    a stray '1 error generated.' line)."""
    global _build_note_shown

    def note():
        global _build_note_shown
        if not _build_note_shown:
            _build_note_shown = True
            print(f"lbwater: building kernels (first run only; cache: "
                  f"{driver_cache_dir(device)})", file=sys.stderr, flush=True)

    timer = None if _build_note_shown else threading.Timer(BUILD_NOTE_AFTER_S, note)
    if timer is not None:
        timer.daemon = True
        timer.start()
    main = threading.current_thread() is threading.main_thread()
    blocked = main and hasattr(signal, "pthread_sigmask")
    got, previous = [], None
    if main:
        previous = signal.signal(signal.SIGINT, lambda *a: got.append(True))
    if blocked:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        if timer is not None:
            timer.cancel()
        if main:
            signal.signal(signal.SIGINT, previous if previous is not None
                          else signal.default_int_handler)
        if blocked:   # one held for this thread is delivered now, to the handler put back
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        if got:       # one another thread took during the build
            signal.raise_signal(signal.SIGINT)


def _write_build_log(source: str, device_name: str, options: list[str], log: str) -> Path:
    """The build log in a file (the CLI prints only its path); returns the path."""
    fd, name = tempfile.mkstemp(prefix=f"lbwater-build-{Path(source).stem}-", suffix=".log")
    with os.fdopen(fd, "w") as fh:
        fh.write(f"{source} on {device_name}\noptions: {' '.join(options)}\n\n{log}\n")
    return Path(name)


def _source_hash() -> str:
    h = hashlib.sha1()
    for path in sorted(KERNEL_DIR.glob("*.h")) + sorted(KERNEL_DIR.glob("*.cl")):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:12]


def extra_build_options() -> list[str]:
    """Compiler options added to every build from ``LBWATER_CL_OPTIONS`` (shell words), for
    device experiments such as ``-cl-nv-verbose`` (NVIDIA: registers and spills in the build
    log, bench/kernel_resources.py) or ``-cl-nv-maxrregcount=64``; empty when unset."""
    return shlex.split(os.environ.get("LBWATER_CL_OPTIONS", ""))


def _format_define(name: str, value) -> str:
    if value is None or value is True:
        return f"-D{name}"
    if isinstance(value, float | np.floating):
        return f"-D{name}={float(value)!r}f"
    return f"-D{name}={value}"


class Runtime:
    """A device, its context and its profiling queue; builds and caches programs and kernels."""

    def __init__(self, device: cl.Device | str | None = None, *, profiling: bool = True,
                 bvh_layout: str | None = None, kernel_arg_info: bool = True,
                 defines: dict | None = None):
        """``bvh_layout``: how scenes store their BLASes for traversal, ``"binary"`` or
        ``"wide"`` (raytrace.bvh_wide); default ``LBWATER_BVH_LAYOUT`` or, unset, binary on a GPU
        and wide on a CPU. Every program is built with the matching ``TRACE_WIDE`` define unless
        its defines name one. ``kernel_arg_info``: build with ``-cl-kernel-arg-info`` so
        kernels.launch reads argument names off the device (False: from the sources, the
        fallback for devices without argument info; tests use it). ``defines``: added to every
        build (e.g. ``{"TRACE_COUNT": 1}``, the traversal work counters of kernels/traverse.h);
        a program's own defines win."""
        self.device = device if isinstance(device, cl.Device) else select_device(device)
        self.context = cl.Context([self.device])
        props = cl.command_queue_properties.PROFILING_ENABLE if profiling else 0
        self.queue = cl.CommandQueue(self.context, self.device, properties=props)
        self._queue_props = props
        self._copy_queue: cl.CommandQueue | None = None
        self.timer = StageTimer(enabled=profiling)
        self.held = EventKeeper()  # copies to/from host memory, kept until done (no wait)
        self._programs: dict[tuple, cl.Program] = {}
        self._kernels: dict[tuple, cl.Kernel] = {}
        self._kernel_args: dict[tuple, tuple] = {}
        self.kernel_arg_info = bool(kernel_arg_info)
        self._hash = _source_hash()
        layout = bvh_layout or os.environ.get("LBWATER_BVH_LAYOUT") or (
            "binary" if self.is_gpu else "wide")
        self.bvh_layout = check_bvh_layout(layout)
        self.defines = dict(defines or {})

    # -- facts ------------------------------------------------------------------------------
    @property
    def name(self) -> str:
        return self.device.name.strip()

    @property
    def is_gpu(self) -> bool:
        gpu = self.__dict__.get("_is_gpu")  # asked per launch: the device query once
        if gpu is None:
            gpu = self._is_gpu = bool(self.device.type & cl.device_type.GPU)
        return gpu

    @property
    def is_pocl(self) -> bool:
        return "portable computing language" in self.device.platform.name.lower()

    # -- builds -----------------------------------------------------------------------------
    def program(self, source: str, defines: dict | None = None) -> cl.Program:
        """The built program for ``kernels/<source>`` with ``defines``; built once per key."""
        defines = {"TRACE_WIDE": int(self.bvh_layout == "wide"), **self.defines,
                   **(defines or {})}
        key = (source, tuple(sorted(defines.items())))
        prg = self._programs.get(key)
        if prg is not None:
            return prg
        path = KERNEL_DIR / source
        if not path.is_file():
            raise KernelBuildError(f"kernel source {path} does not exist")
        options = [f"-I{KERNEL_DIR}", f"-DLBWATER_SRC_HASH=0x{self._hash}",
                   cl_std_option(self.device)]  # common.h: DEVICE_FENCE
        if self.kernel_arg_info:
            options.append("-cl-kernel-arg-info")
        if "nvidia" in self.device.platform.name.lower():
            options.append("-DLBWATER_NVIDIA=1")  # common.h: DEVICE_FENCE
        options += [_format_define(k, v) for k, v in key[1]] + extra_build_options()
        text = f'#line 1 "{path.name}"\n' + path.read_text()
        try:
            # The source is handed over as a string, so a compiler resolves `#include "x.h"`
            # against the working directory before -I: build from the kernel folder itself.
            with warnings.catch_warnings(), contextlib.chdir(KERNEL_DIR), \
                    _build_guard(self.device):
                warnings.simplefilter("ignore", cl.CompilerWarning)
                prg = cl.Program(self.context, text).build(options=options)
        except cl.RuntimeError as exc:
            log = str(exc).strip()
            log_path = _write_build_log(path.name, self.name, options, log)
            raise KernelBuildError(
                f"{path.name}: OpenCL build failed on {self.name} (build log: {log_path})\n"
                f"options: {' '.join(options[1:])}\n{log}") from None
        self._programs[key] = prg
        return prg

    def kernel(self, source: str, name: str, defines: dict | None = None) -> cl.Kernel:
        """Kernel ``name`` of ``kernels/<source>``; looked up once and reused."""
        key = (source, name, tuple(sorted((defines or {}).items())))
        k = self._kernels.get(key)
        if k is None:
            prg = self.program(source, defines)
            try:
                k = cl.Kernel(prg, name)
            except cl.Error as exc:
                raise KernelBuildError(f"{source}: no kernel named {name!r} ({exc})") from None
            self._kernels[key] = k
        return k

    def kernel_args(self, source: str, name: str, defines: dict | None,
                    kernel: cl.Kernel) -> tuple:
        """Parameters of kernel ``name`` (kernels.launch.KernelArg), read once per program: from
        the device's argument info, or parsed from the source where the device has none."""
        from kernels.launch import device_kernel_args, parse_kernel_args

        key = (source, name, tuple(sorted((defines or {}).items())))
        args = self._kernel_args.get(key)
        if args is None:
            args = device_kernel_args(kernel) if self.kernel_arg_info else None
            if args is None:
                args = parse_kernel_args(source, name)
            self._kernel_args[key] = args
        return args

    # -- launches ---------------------------------------------------------------------------
    def kernel_launcher(self, source: str, name: str, *, stage: str, defines: dict | None = None):
        """A :class:`kernels.launch.Kernel`: its own kernel object of ``kernels/<source>``,
        arguments bound by name, each launch timed as ``stage``."""
        from kernels.launch import Kernel

        return Kernel(self, source, name, stage=stage, defines=defines)

    def record(self, stage: str, event: cl.Event) -> cl.Event:
        """Time an event that did not come from a kernel launcher (a copy, a fill); with the
        timer off, hold it until done instead (:meth:`keep`)."""
        if not self.timer.enabled:
            return self.held.keep(event)
        return self.timer.record(stage, event)

    def keep(self, event: cl.Event) -> cl.Event:
        """Hold a copy's event until it completes (kernels.events: releasing a pyopencl
        NannyEvent waits for its copy); returns it."""
        return self.held.keep(event)

    @property
    def copy_queue(self) -> cl.CommandQueue:
        """A second in-order queue for device-to-host copies, so that frame N's image read-back
        overlaps frame N+1's kernels (the caller orders the two queues with events)."""
        if self._copy_queue is None:
            self._copy_queue = cl.CommandQueue(self.context, self.device,
                                               properties=self._queue_props)
        return self._copy_queue

    def finish(self) -> None:
        self.queue.finish()
        if self._copy_queue is not None:
            self._copy_queue.finish()
        self.held.clear()

    # -- buffers ----------------------------------------------------------------------------
    def buffer(self, nbytes: int, flags=cl.mem_flags.READ_WRITE) -> cl.Buffer:
        return cl.Buffer(self.context, flags, size=max(int(nbytes), 4))

    def to_device(self, array: np.ndarray, flags=cl.mem_flags.READ_WRITE) -> cl.Buffer:
        array = np.ascontiguousarray(array)
        if array.nbytes == 0:
            return self.buffer(4, flags)
        return cl.Buffer(self.context, flags | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)

    def to_host(self, buf: cl.Buffer, dtype, count: int, first: int = 0) -> np.ndarray:
        """``count`` records of ``dtype`` from record ``first`` of ``buf`` (waits for the copy)."""
        out = np.empty(count, dtype=dtype)
        if count:
            cl.enqueue_copy(self.queue, out, buf, src_offset=first * out.dtype.itemsize)
        return out


_RUNTIMES: dict[str, Runtime] = {}


def get_runtime(device: str | cl.Device | Runtime | None = None) -> Runtime:
    """The shared runtime for ``device`` (a spec, a ``cl.Device``, a Runtime or None)."""
    if isinstance(device, Runtime):
        return device
    if isinstance(device, cl.Device):
        key = f"dev:{device.int_ptr}"
    else:
        key = device or os.environ.get("LBWATER_DEVICE") or os.environ.get("PYOPENCL_CTX") or ""
    rt = _RUNTIMES.get(key)
    if rt is None:
        rt = _RUNTIMES[key] = Runtime(device)
    return rt
