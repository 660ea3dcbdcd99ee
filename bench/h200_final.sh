#!/usr/bin/env bash
# Last H200 call of 2026-12-01 (BENCHMARKS.md): the bodies stage and the window's display path
# after their last changes, and the grid-size sweep with its charts. Usage: bench/h200_final.sh OUTDIR
set -uo pipefail
out=${1:?OUTDIR}
mkdir -p "$out"
lb() { python3 -m app.cli "$@"; }
timeout 150 python3 -m pytest -q -x -p no:cacheprovider --tb=short tests/lbm/test_bodies_fast.py \
    tests/lbm/test_bodies.py tests/app/test_window_bench.py 2>&1 | tail -15
python3 bench/bodies_stage.py --cells 1024 --boats 1 16 --frames 60 --out "$out/bodies_stage" 2>&1 | tail -3
lb bench frame --cells 1024 --size 1920 1080 --frames 40 --boats 16 --caustics off --out "$out/boats16" | tail -1
for rep in 1 2 3; do
    lb bench window --sizes 1280x720 1920x1080 --out "$out/window$rep" 2>&1 | tail -2
done
lb bench window --sizes 1280x720 1920x1080 --upload pbo --out "$out/window_pbo" 2>&1 | tail -2
lb sweep scenes/pool.toml --cells 128,256,512,1024,2048 --size 640x360,1920x1080 --bounces 5 \
    --spp 1 --frames 20 --warmup 5 -o "$out/sweep" 2>&1 | tail -3
exit 0
