"""``lbwater``: the command-line entry point.

Each subcommand lives in its own module exposing ``add_arguments(parser)`` and ``run(args)``;
this file only registers them and turns user-facing errors into one line and exit status 2.

Only the module of the command being run is imported (``lbwater --help`` imports none of them, and
no command module imports pyopencl at import time), so the parser is built in milliseconds and a
Ctrl-C at any moment prints one line, ``lbwater: interrupted``, and exits with status 130. The
console script enters through :mod:`app.entry`, whose first statements make that so before any
import; ``python -m app.cli`` installs the same handler before this module imports anything but
``sys`` (argparse and importlib are imported inside the functions).
"""

from __future__ import annotations

import sys

if __name__ == "__main__":   # python -m app.cli: Ctrl-C is one line from here on
    from app.entry import install

    install()

#: (name, module, one-line help). A module is imported only when its command is run or its
#: own ``--help`` is asked for.
COMMANDS = [
    ("devices", "app.cmd_devices", "list OpenCL platforms and devices"),
    ("render", "app.cmd_render", "render a scene file to a PNG (ray traced)"),
    ("simulate", "app.cmd_simulate", "run a scene's water (LBM) without rendering; save .npz"),
    ("window", "app.window", "interactive window: rain, mouse ripples, orbit camera, HUD"),
    ("bench", "app.bench", "benchmarks: lbm, bvh, render, frame, window, capture"),
    ("capture", "app.capture", "render a scene and its [[timeline]] to an H.264 video or PNGs"),
    ("sweep", "app.sweep", "sweep grid size, image size, bounces, spp: FPS, stages; CSV + charts"),
    ("study", "app.studies", "speed against accuracy studies: CSV + chart of error vs time"),
]

EXIT_INPUT = 2
EXIT_INTERRUPTED = 130


def _command_of(argv: list[str]) -> str | None:
    """The subcommand named in ``argv`` (the first word that is not an option), if any."""
    for word in argv:
        if not word.startswith("-"):
            return word
    return None


def build_parser(argv: list[str] | None = None):
    """The argparse parser; only the command named in ``argv`` gets its module's arguments (all
    of them when ``argv`` is None, e.g. for documentation tools)."""
    import argparse
    import importlib

    parser = argparse.ArgumentParser(
        prog="lbwater",
        description="GPU shallow-water simulation and ray-traced water rendering (OpenCL).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    wanted = None if argv is None else _command_of(argv)
    for name, module, help_text in COMMANDS:
        if argv is not None and name != wanted:
            sub.add_parser(name, help=help_text, description=help_text)
            continue
        mod = importlib.import_module(module)
        p = sub.add_parser(name, help=help_text, description=(mod.__doc__ or help_text).strip(),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        if "argv" in mod.add_arguments.__code__.co_varnames:
            mod.add_arguments(p, argv=None if argv is None else argv[argv.index(name) + 1:])
        else:
            mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def _user_errors() -> tuple[type[BaseException], ...]:
    from app.errors import LbwaterError
    from kernels import DeviceError, KernelBuildError
    return (LbwaterError, DeviceError, KernelBuildError, OSError, ValueError)


def _one_line(exc: BaseException) -> tuple[str, list[str]]:
    lines = str(exc).strip().splitlines()
    return (lines[0] if lines else type(exc).__name__), lines[1:]


_SIGINT_SEEN = False


def _raise_interrupt(signum, frame) -> None:
    global _SIGINT_SEEN
    _SIGINT_SEEN = True
    raise KeyboardInterrupt


def _take_over_ctrl_c() -> None:
    """Ctrl-C raises KeyboardInterrupt from here on (handled in :func:`main`, after cleanups)
    where app.entry's handler (one line, exit now) guarded the imports. The interrupt is also
    remembered: one raised inside a C extension's import comes out as an ImportError (numpy's
    does), which must still read as an interrupt."""
    import signal

    from app import entry

    if entry.installed():
        signal.signal(signal.SIGINT, _raise_interrupt)


def _redeliver_swallowed(previous):
    """An unraisable-exception hook: a KeyboardInterrupt raised inside a callback whose errors
    Python only reports (importlib's module-lock weakref callback during an import, a
    ``__del__``) would print a traceback and be lost; it is delivered again instead, 10 ms
    later from a timer thread (delivered from here it would land in this hook, whose errors are
    only reported too), where :func:`main` catches it."""
    def hook(unraisable):
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            import _thread
            import threading

            t = threading.Timer(0.01, _thread.interrupt_main)
            t.daemon = True
            t.start()
            return
        previous(unraisable)
    return hook


def main(argv: list[str] | None = None) -> int:
    global _SIGINT_SEEN
    _SIGINT_SEEN = False   # this command's interrupt, not an earlier call's in this process
    argv = list(sys.argv[1:] if argv is None else argv)
    previous = sys.unraisablehook
    sys.unraisablehook = _redeliver_swallowed(previous)
    try:
        # the command modules (numpy, ...) are imported under app.entry's exit-now handler: an
        # interrupt inside a C extension's import would otherwise surface as an ImportError
        parser = build_parser(argv)
        _take_over_ctrl_c()
        return _main(parser, argv)
    except KeyboardInterrupt:
        _quiet_teardown()
        print("lbwater: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BaseException:
        if _SIGINT_SEEN:   # an interrupt that came out as another exception
            _quiet_teardown()
            print("lbwater: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        raise
    finally:
        if sys.unraisablehook is _ignore_unraisable:
            import gc

            gc.collect()   # the half-built objects in cycles, still unreported
        sys.unraisablehook = previous


def _ignore_unraisable(unraisable) -> None:
    """Drops an error Python could only report (see :func:`_quiet_teardown`)."""


def _quiet_teardown() -> None:
    """After an interrupt, the objects it left half-built fail in their ``__del__`` as they go
    (pytools' compiler cache cut short inside its ``__init__``: ``Exception ignored ...
    AttributeError``); the command ends with its one line, so those reports are dropped until
    :func:`main` returns."""
    sys.unraisablehook = _ignore_unraisable


def _main(parser, argv: list[str]) -> int:
    args = parser.parse_args(argv)
    try:
        status = args._run(args)
    except KeyboardInterrupt:
        raise
    except ImportError as exc:   # no OpenCL runtime at all: pyopencl or its ICD loader missing
        if _SIGINT_SEEN:   # an interrupt inside an extension's import
            raise KeyboardInterrupt from None
        if (exc.name or "").split(".")[0] not in ("pyopencl", "pyvista", "vtk", "imageio"):
            raise
        msg, _ = _one_line(exc)
        print(f"lbwater {args.command}: error: {exc.name} cannot be imported ({msg})",
              file=sys.stderr)
        return EXIT_INPUT
    except Exception as exc:
        if _SIGINT_SEEN:
            raise KeyboardInterrupt from None
        try:
            user = isinstance(exc, _user_errors())
        except ImportError:  # no pyopencl at all: the error itself is the message
            user = isinstance(exc, OSError | ValueError)
        if not user:
            raise
        msg, rest = _one_line(exc)
        print(f"lbwater {args.command}: error: {msg}", file=sys.stderr)
        if rest and getattr(args, "verbose", False):
            print("\n".join(rest), file=sys.stderr)
        return EXIT_INPUT
    return int(status or 0)


if __name__ == "__main__":
    from app.entry import finish

    sys.exit(finish(main()))
