#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-01 (third session)" rows: the
# cooperative traversal of the tail levels (RenderSettings.coop_from) and the bodies stage with
# its reads in flight. Usage: bench/h200_session3.sh OUTDIR
# The device machine needs the OpenCL ICD and the wheels first (BENCHMARKS.md, "How the GPU rows
# were made").
set -uo pipefail
out=${1:?OUTDIR}
mkdir -p "$out"
lb() { python3 -m app.cli "$@"; }
# correctness on this device first: the cooperative walk and renderer, bodies, the frame
timeout 240 python3 -m pytest -q -p no:cacheprovider -rs tests/raytrace/test_traverse_coop.py \
    tests/raytrace/test_render_coop.py tests/raytrace/test_render_overlap.py \
    tests/lbm/test_bodies_fast.py tests/app/test_frame_pipeline.py 2>&1 | tail -6
f="--cells 1024 --size 1920 1080 --frames 40"
static="--scene bench/scenes/pool_static_boat.toml"
for rep in 1 2; do   # the tail levels' traversal: serial (off) against cooperative from depth D
    for c in off 1 2 3; do
        lb bench frame $f $static --coop-from $c --out "$out/static_coop${c}_$rep" | tail -1
    done
    lb bench frame $f --coop-from off --out "$out/pool_coopoff_$rep" | tail -1
    lb bench frame $f --out "$out/pool_$rep" | tail -1
done
lb bench frame $f $static --per-depth --coop-from off --out "$out/static_perdepth_off" | tail -1
lb bench frame $f $static --per-depth --out "$out/static_perdepth" | tail -1
lb bench frame $f $static --frame-time 0.0025 --out "$out/static_realtime400" | tail -1
for rep in 1 2; do
    lb bench frame --cells 1024 --size 3840 2160 --frames 20 --out "$out/pool4k_$rep" | tail -1
    lb bench frame --cells 1024 --size 3840 2160 --frames 20 $static --out "$out/static4k_$rep" \
        | tail -1
done
lb bench frame --cells 1024 --size 3840 2160 --frames 20 --coop-from off --out "$out/pool4k_off" \
    | tail -1
python3 bench/bodies_stage.py --cells 1024 --boats 1 16 --frames 60 --out "$out/bodies_stage" 2>&1 \
    | tail -2
python3 bench/bodies_stage.py --cells 1024 --boats 16 --work-group 256 512 1024 --frames 60 \
    --out "$out/bodies_wg" 2>&1 | tail -3
for rep in 1 2; do
    lb bench frame $f --boats 16 --caustics off --out "$out/boats16_$rep" | tail -1
done
exit 0
