#!/usr/bin/env bash
# The PoCL rows of BENCHMARKS.md's "NVIDIA H200, 2026-12-05 (fifteenth session)": the baseline
# scene at 320x180 (128 cells) with the shadow list on, the fourteenth session's last tree
# (41e2ffd, archived in .trees/41e2ffd as bench/h200_session15.sh says) against the tree, and
# the tree with the list off, in turns twice.
# Usage: bench/pocl_session15.sh OUTDIR   (then bench/collect_results.py OUTDIR OUT.json)
set -uo pipefail
out=$(realpath -m "${1:?OUTDIR}")
mkdir -p "$out"
old=$PWD/.trees/41e2ffd
static="--scene bench/scenes/pool_static_boat.toml"
p="--cells 128 --size 320 180 --frames 10"
ln -sfn "$PWD/bench" "$old/bench"
ln -sfn "$PWD/scenes" "$old/scenes"
for rep in 1 2; do
    (cd "$old" && PYTHONPATH=$old python3 -m app.cli bench frame $p $static --shadow-list on \
        --out "$out/old_on_$rep" | tail -1)
    python3 -m app.cli bench frame $p $static --shadow-list on --out "$out/tree_on_$rep" | tail -1
    python3 -m app.cli bench frame $p $static --shadow-list off --out "$out/tree_off_$rep" | tail -1
done
rm "$old/bench" "$old/scenes"
