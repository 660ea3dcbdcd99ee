#!/usr/bin/env bash
# The window's two upload paths on the H200, interleaved three times (BENCHMARKS.md "Window on
# the H200"). Usage: bench/h200_window.sh OUTDIR
set -uo pipefail
out=${1:?OUTDIR}
mkdir -p "$out"
for rep in 1 2 3; do
    for up in direct pbo; do
        python3 -m app.cli bench window --sizes 1280x720 1920x1080 --upload $up \
            --out "$out/$up$rep" 2>&1 | tail -2
    done
done
