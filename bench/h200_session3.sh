#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-01 (third session)" rows: the
# cooperative traversal of the tail levels (RenderSettings.coop_from, on from depth 2 on a GPU)
# and the bodies stage with its reads in flight. Two parts, each within one device call:
#   bench/h200_session3.sh OUTDIR a     device tests, 1920x1080 A/B of coop_from, per depth
#   bench/h200_session3.sh OUTDIR b     3840x2160, the bodies stage, 16 boats in the frame
# The device machine needs the OpenCL ICD and the wheels first (BENCHMARKS.md, "How the GPU rows
# were made").
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART a or b}
mkdir -p "$out"
lb() { python3 -m app.cli "$@"; }
f="--cells 1024 --size 1920 1080 --frames 40"
static="--scene bench/scenes/pool_static_boat.toml"
if [ "$part" = a ]; then
    # correctness on this device first: the cooperative walk (in the render kernels too, as a
    # GPU runs them), bodies, the frame pipeline (coop_from 2 by default here)
    timeout 200 python3 -m pytest -q -p no:cacheprovider -rs tests/raytrace/test_trace_coop.py \
        tests/raytrace/test_render_coop.py tests/raytrace/test_render_overlap.py \
        tests/lbm/test_bodies_fast.py tests/app/test_frame_pipeline.py 2>&1 | tail -4
    for rep in 1 2; do   # the tail levels: serial (off) against cooperative from depth D
        for c in off 2; do
            lb bench frame $f $static --coop-from $c --out "$out/static_coop${c}_$rep" | tail -1
            lb bench frame $f --coop-from $c --out "$out/pool_coop${c}_$rep" | tail -1
        done
    done
    lb bench frame $f $static --per-depth --out "$out/static_perdepth" | tail -1
    lb bench frame $f --per-depth --out "$out/pool_perdepth" | tail -1
else
    for rep in 1 2; do
        lb bench frame --cells 1024 --size 3840 2160 --frames 20 --out "$out/pool4k_$rep" | tail -1
    done
    lb bench frame --cells 1024 --size 3840 2160 --frames 20 --coop-from off \
        --out "$out/pool4k_off" | tail -1
    lb bench frame --cells 1024 --size 3840 2160 --frames 20 $static --out "$out/static4k" \
        | tail -1
    lb bench frame $f $static --frame-time 0.0025 --out "$out/static_water400" | tail -1
    python3 bench/bodies_stage.py --cells 1024 --boats 1 16 --frames 60 \
        --out "$out/bodies_stage" 2>&1 | tail -2
    for rep in 1 2; do
        lb bench frame $f --boats 16 --caustics off --out "$out/boats16_$rep" | tail -1
    done
fi
exit 0
