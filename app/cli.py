"""``lbwater``: the command-line entry point.

Each subcommand lives in its own module exposing ``add_arguments(parser)`` and ``run(args)``;
this file only registers them and turns user-facing errors into one line and exit status 2.

Only the module of the command being run is imported (``lbwater --help`` imports none of them, and
no command module imports pyopencl at import time), so the parser is built in milliseconds and a
Ctrl-C at any moment prints one line, ``lbwater: interrupted``, and exits with status 130.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: (name, module, one-line help). A module is imported only when its command is run or its
#: own ``--help`` is asked for.
COMMANDS = [
    ("devices", "app.cmd_devices", "list OpenCL platforms and devices"),
    ("render", "app.cmd_render", "render a scene file to a PNG (ray traced)"),
    ("simulate", "app.cmd_simulate", "run a scene's water (LBM) without rendering; save .npz"),
    ("window", "app.window", "interactive window: rain, mouse ripples, orbit camera, HUD"),
    ("bench", "app.bench", "benchmarks: lbm, bvh, render, frame, window"),
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


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser; only the command named in ``argv`` gets its module's arguments (all of them
    when ``argv`` is None, e.g. for documentation tools)."""
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


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return _main(argv)
    except KeyboardInterrupt:
        print("lbwater: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def _main(argv: list[str]) -> int:
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    try:
        status = args._run(args)
    except KeyboardInterrupt:
        raise
    except Exception as exc:
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
    sys.exit(main())
