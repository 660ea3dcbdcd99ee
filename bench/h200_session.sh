#!/usr/bin/env bash
# The runs behind BENCHMARKS.md's H200 rows of 2026-12-01 (frame pipeline before/after, caustics
# against photons, boats, window, long runs), in one call on the lent GPU.
# Usage: bench/h200_session.sh OUTDIR [OLDTREE]
#   OLDTREE: a checkout of the commit before the frame pipeline (16e9a35) with scenes/models, for
#   the "before" row measured in the same run. The device machine needs the OpenCL ICD and the
#   wheels installed first (BENCHMARKS.md, "How the GPU rows were made").
set -uo pipefail
out=${1:?OUTDIR}
old=${2:-}
mkdir -p "$out"
lb() { python3 -m app.cli "$@"; }
# correctness first: kernels, BVH, renderer, solver, bodies and the frame pipeline on this device
timeout 200 python3 -m pytest -q -x -p no:cacheprovider tests/kernels tests/raytrace/test_render.py \
    tests/raytrace/test_caustics.py tests/lbm/test_bodies.py tests/lbm/test_bodies_fast.py tests/app/test_frame_pipeline.py \
    2>&1 | tail -3
f="--cells 1024 --size 1920 1080 --frames 40"
# before (16e9a35: static boat, no caustics, no bodies) and after, interleaved
for rep in 1 2; do
    if [ -n "$old" ]; then
        (cd "$old" && python3 -m app.cli bench frame $f --out "$out/before$rep" | tail -1)
    fi
    lb bench frame $f --out "$out/after$rep" | tail -1
    # the same scene as before (static boat, no caustics) on this build
    [ -n "$old" ] && lb bench frame $f --scene "$old/scenes/pool.toml" --out "$out/afterold$rep" | tail -1
done
lb bench frame $f --caustics off --out "$out/nocaustics" | tail -1
lb bench frame $f --boats 0 --caustics off --out "$out/noboats" | tail -1
lb bench frame $f --boats 16 --caustics off --out "$out/boats16" | tail -1
python3 bench/bodies_stage.py --cells 1024 --boats 1 16 --frames 60 --every-step --out "$out/bodies_stage" 2>&1 | tail -3
for n in 65536 131072 262144; do
    lb bench frame $f --photons $n --out "$out/photons$n" | tail -1
done
lb bench frame --cells 1024 --size 3840 2160 --frames 20 --out "$out/frame4k" | tail -1
lb bench window --out "$out/window" 2>&1 | tail -3
lb bench frame $f --caustics off --per-depth --out "$out/perdepth" | tail -1
exit 0
