"""Benchmarks: median of repeated runs with OpenCL event times per stage, warm-up excluded,
written as JSON (and CSV) under ``--out``. Subcommands: ``lbm``, ``bvh``, ``render``, ``frame``,
``window``, ``capture`` (``lbwater bench NAME --help`` for each)."""

from __future__ import annotations

import argparse
import importlib

#: (name, module, help); each module exposes add_arguments(parser) and run(args). A module is
#: imported only when its benchmark is run or its ``--help`` is asked for.
BENCHES = [
    ("lbm", "app.bench_lbm", "LBM step: MLUPs/s and share of the measured copy bandwidth"),
    ("bvh", "app.bench_bvh", "GPU BVH build/refit/TLAS ms and ray rates vs NVIDIA Warp"),
    ("render", "app.bench_render", "renderer: the seed's scenes per stage, FPS, error vs spp"),
    ("frame", "app.bench_frame", "the whole frame loop: LBM, surface, BVH, render"),
    ("window", "app.bench_window", "the window's display path (EGL): frame + upload + draw"),
    ("capture", "app.bench_capture", "capture's overhead (H.264 encode, read-back copies) "
                                     "over the bare frame loop"),
]


def add_arguments(p, argv: list[str] | None = None) -> None:
    """``argv``: the words after ``bench``; only the benchmark named there is imported (all of
    them when None)."""
    sub = p.add_subparsers(dest="bench", metavar="BENCH", required=True)
    wanted = next((w for w in argv if not w.startswith("-")), None) if argv is not None else None
    for name, module, help_text in BENCHES:
        if argv is not None and name != wanted:
            sub.add_parser(name, help=help_text, description=help_text)
            continue
        mod = importlib.import_module(module)
        q = sub.add_parser(name, help=help_text, description=(mod.__doc__ or help_text).strip(),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        q.add_argument("--device", help="OpenCL device: gpu, cpu, pocl, P:D or part of a name")
        q.add_argument("--out", default="out/bench", help="folder for the JSON/CSV results")
        mod.add_arguments(q)
        q.set_defaults(_bench_run=mod.run)


def run(args) -> int:
    from app.io import check_output_dir

    check_output_dir(args.out, "--out")
    return args._bench_run(args)
