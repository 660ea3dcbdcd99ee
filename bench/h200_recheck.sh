#!/usr/bin/env bash
# Second H200 call of 2026-12-01 (BENCHMARKS.md): the window's display path three times, auto
# quality, and the frame after the merges of the day, per depth with caustics on.
# Usage: bench/h200_recheck.sh OUTDIR
set -uo pipefail
out=${1:?OUTDIR}
mkdir -p "$out"
lb() { python3 -m app.cli "$@"; }
timeout 120 python3 -m pytest -q -x -p no:cacheprovider --tb=short tests/kernels/test_video_yuv.py \
    tests/raytrace/test_render_shadow.py tests/lbm/test_bodies_fast.py 2>&1 | tail -25
for rep in 1 2 3; do
    lb bench window --sizes 1280x720 1920x1080 --out "$out/window$rep" 2>&1 | tail -2
done
lb bench window --quality auto --sizes 1280x720 1920x1080 --out "$out/window_auto" 2>&1 | tail -2
f="--cells 1024 --size 1920 1080 --frames 40"
lb bench frame $f --out "$out/pool1" | tail -1
lb bench frame $f --per-depth --out "$out/pool_perdepth" | tail -1
lb bench frame $f --out "$out/pool2" | tail -1
lb bench frame --cells 1024 --size 3840 2160 --frames 20 --out "$out/pool4k" | tail -1
exit 0
