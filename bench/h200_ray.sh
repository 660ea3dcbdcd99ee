#!/usr/bin/env bash
# A one-GPU capture through Ray against the plain capture on the H200 (issue 15; BENCHMARKS.md
# "Ray"). Needs ray (lbwater[cluster]) and an ffmpeg with libx264. Usage: bench/h200_ray.sh OUTDIR
set -uo pipefail
out=${1:?OUTDIR}
mkdir -p "$out"
python3 -c "import ray; print('ray', ray.__version__)"
timeout 400 python3 bench/ray_overhead.py --scene scenes/timeline.toml --frames 96 --size 1280x720 \
    --workers 1 --runs 3 2>&1 | tee "$out/ray_overhead.md" | tail -8
exit 0
