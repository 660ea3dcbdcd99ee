#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-01 (third session)" rows: the
# cooperative traversal of the tail levels (on a GPU from depth 2, for levels of at most 4096
# rays) and the bodies stage with its reads in flight. Usage: bench/h200_session3.sh OUTDIR
# (One device call: about 2.5 minutes.) The device machine needs the OpenCL ICD and the wheels
# first (BENCHMARKS.md, "How the GPU rows were made").
set -uo pipefail
out=${1:?OUTDIR}
mkdir -p "$out"
lb() { python3 -m app.cli "$@"; }
f="--cells 1024 --size 1920 1080 --frames 40"
k="--cells 1024 --size 3840 2160 --frames 20"
static="--scene bench/scenes/pool_static_boat.toml"
# correctness on this device first: the cooperative walk (in the render kernels too, as a GPU
# runs them: the serial bytes, ties included), the levels' orders
timeout 150 python3 -m pytest -q -p no:cacheprovider -rs tests/raytrace/test_trace_coop.py \
    tests/raytrace/test_render_coop.py tests/raytrace/test_render_overlap.py 2>&1 | tail -3
for c in off 2; do   # the tail levels: a work-item per ray (off) against the default
    lb bench frame $f $static --coop-from $c --out "$out/static_coop$c" | tail -1
    lb bench frame $f --coop-from $c --out "$out/pool_coop$c" | tail -1
    lb bench frame $k --coop-from $c --out "$out/pool4k_coop$c" | tail -1
done
lb bench frame $f --out "$out/pool_rep" | tail -1
lb bench frame $f $static --per-depth --out "$out/static_perdepth" | tail -1
lb bench frame $f --per-depth --out "$out/pool_perdepth" | tail -1
lb bench frame $k $static --out "$out/static4k" | tail -1
python3 bench/bodies_stage.py --cells 1024 --boats 1 16 --frames 60 --out "$out/bodies_stage" \
    2>&1 | tail -2
lb bench frame $f --boats 16 --caustics off --out "$out/boats16" | tail -1
exit 0
