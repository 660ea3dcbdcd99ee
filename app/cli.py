"""``lbwater``: the command-line entry point.

Each subcommand lives in its own module exposing ``add_arguments(parser)`` and ``run(args)``;
this file only registers them and turns user-facing errors into one line and exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: (name, module, one-line help). Modules are imported when the parser is built; keep their
#: imports light (no pyvista, no OpenCL context at import time).
COMMANDS = [
    ("devices", "app.cmd_devices", "list OpenCL platforms and devices"),
    ("render", "app.cmd_render", "render a scene file to a PNG (ray traced)"),
    ("simulate", "app.cmd_simulate", "run a scene's water (LBM) without rendering; save .npz"),
    ("window", "app.window", "interactive window: rain, mouse ripples, orbit camera, HUD"),
    ("bench", "app.bench", "benchmarks: lbm, bvh, render"),
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lbwater",
        description="GPU shallow-water simulation and ray-traced water rendering (OpenCL).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module, help_text in COMMANDS:
        mod = importlib.import_module(module)
        p = sub.add_parser(name, help=help_text, description=(mod.__doc__ or help_text).strip())
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def _user_errors() -> tuple[type[BaseException], ...]:
    from app.errors import LbwaterError
    from kernels import DeviceError, KernelBuildError
    return (LbwaterError, DeviceError, KernelBuildError, OSError, ValueError)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        status = args._run(args)
    except KeyboardInterrupt:
        print("lbwater: interrupted", file=sys.stderr)
        return 130
    except _user_errors() as exc:
        first = str(exc).strip().splitlines()
        msg = first[0] if first else type(exc).__name__
        print(f"lbwater {args.command}: error: {msg}", file=sys.stderr)
        if len(first) > 1 and getattr(args, "verbose", False):
            print("\n".join(first[1:]), file=sys.stderr)
        return 2
    return int(status or 0)


if __name__ == "__main__":
    sys.exit(main())
