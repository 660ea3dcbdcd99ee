#!/usr/bin/env bash
# The runs behind BENCHMARKS.md's 2026-12-01 H200 rows (frame pipeline, caustics, boats, window,
# radix A/B), in one call on the lent GPU. Usage: bench/h200_session.sh OUTDIR
# (the device machine needs the OpenCL ICD and the wheels installed first; see BENCHMARKS.md).
set -uo pipefail
out=${1:?OUTDIR}
mkdir -p "$out"
lb() { python3 -m app.cli "$@"; }
# correctness first: kernels, BVH, renderer, solver and the frame pipeline on this device
timeout 420 python3 -m pytest -q -x -p no:cacheprovider tests/kernels tests/raytrace tests/lbm \
    tests/app/test_frame_pipeline.py tests/app/test_world.py \
    2>&1 | tail -4
# the whole frame: pool at 1024 cells + floating boat, 5 bounces; caustics on (the scene) and off
lb bench frame --cells 1024 --size 1920 1080 --frames 40 --out "$out/frame1080" | tail -1
lb bench frame --cells 1024 --size 1920 1080 --frames 40 --caustics off --out "$out/frame1080_nocaustics" | tail -1
lb bench frame --cells 1024 --size 3840 2160 --frames 20 --out "$out/frame4k" | tail -1
lb bench frame --cells 1024 --size 1920 1080 --frames 40 --boats 16 --caustics off --out "$out/frame_boats16" | tail -1
lb bench frame --cells 1024 --size 1920 1080 --frames 40 --boats 0 --caustics off --out "$out/frame_boats0" | tail -1
# capture's overhead (H.264 encode, read-back copies) over the bare frame loop, 1920x1080
lb bench capture --cells 1024 --size 1920 1080 --frames 120 --out "$out/capture1080" | tail -1
# the window's display path in a headless EGL context
lb bench window --out "$out/window" 2>&1 | tail -3
# sort digit widths, interleaved
python3 bench/ab_radix_bits.py > "$out/ab_radix_bits.json" 2>&1; tail -3 "$out/ab_radix_bits.json"
