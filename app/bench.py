"""Benchmarks: median of repeated runs with OpenCL event times per stage, warm-up excluded,
written as JSON (and CSV) under ``--out``. Subcommands: ``lbm``, ``bvh``, ``render``, ``frame``,
``window``."""

from __future__ import annotations

import importlib

#: (name, module, help); each module exposes add_arguments(parser) and run(args).
BENCHES = [
    ("render", "app.bench_render", "renderer: the seed's scenes per stage, FPS, error vs spp"),
    ("bvh", "app.bench_bvh", "GPU BVH build/refit/TLAS ms and ray rates vs NVIDIA Warp"),
    ("lbm", "app.bench_lbm", "LBM step: MLUPs/s and share of the measured copy bandwidth"),
    ("frame", "app.bench_frame", "the whole frame loop: LBM, surface, BVH, render"),
    ("window", "app.bench_window", "the window's display path (EGL): frame + upload + draw"),
]


def add_arguments(p) -> None:
    sub = p.add_subparsers(dest="bench", metavar="BENCH", required=True)
    for name, module, help_text in BENCHES:
        mod = importlib.import_module(module)
        q = sub.add_parser(name, help=help_text, description=(mod.__doc__ or help_text).strip())
        q.add_argument("--device", help="OpenCL device: gpu, cpu, P:D or part of a name")
        q.add_argument("--out", default="out/bench", help="folder for the JSON/CSV results")
        mod.add_arguments(q)
        q.set_defaults(_bench_run=mod.run)


def run(args) -> int:
    return args._bench_run(args)
