#!/usr/bin/env bash
# The H200 runs that need ffmpeg (BENCHMARKS.md "Capture"): capture's overhead over the bare frame
# loop at 1920x1080, and the README's caustics clip. Usage: bench/h200_capture.sh OUTDIR
# (IMAGEIO_FFMPEG_EXE names an ffmpeg with libx264; the device machine has none of its own).
set -uo pipefail
out=${1:?OUTDIR}
mkdir -p "$out"
lb() { python3 -m app.cli "$@"; }
timeout 120 python3 -m pytest -q -x -p no:cacheprovider tests/app/test_capture.py tests/app/test_bench_capture.py 2>&1 | tail -3
lb bench capture --cells 1024 --size 1920 1080 --frames 120 --out "$out/capture1080" | tail -1
lb capture scenes/timeline.toml -o "$out/caustics_clip.mp4" --width 960 --height 540 --fps 30 \
    --seconds 5 --spp 4 --quality 5 --preset medium --force 2>&1 | tail -1
# the LBM step against the copy bandwidth (the exact-volume quantum's cost), and the long runs
lb bench lbm --sizes 2048,4096 --out "$out/lbm" 2>&1 | tail -2
python3 bench/long_runs.py volume --steps 100000 --out "$out/long_slip" 2>&1 | tail -1
python3 bench/long_runs.py volume --steps 100000 --boundary noslip --out "$out/long_noslip" 2>&1 | tail -1
python3 bench/long_runs.py volume --cells 1024 768 --steps 100000 --check-every 20000 --out "$out/long_big" 2>&1 | tail -1
timeout 200 python3 bench/long_runs.py frames --frames 10000 --out "$out/long_frames" 2>&1 | tail -1
