#!/usr/bin/env bash
# Every benchmark behind BENCHMARKS.md, in one go, on one device; results under OUTDIR.
# Usage: bench/run_all.sh OUTDIR [DEVICE]   (DEVICE: a --device spec, default: the default device)
# The test suite runs first on the same device (its summary lands in OUTDIR/tests.txt).
set -uo pipefail
out=${1:?usage: bench/run_all.sh OUTDIR [DEVICE]}
dev=${2:-}
mkdir -p "$out"
d=()
[ -n "$dev" ] && d=(--device "$dev")
status=0
run() { echo "== $*" | tee -a "$out/log.txt"; "$@" 2>&1 | tee -a "$out/log.txt" || status=1; }
LBWATER_DEVICE="$dev" python3 -m pytest -q -p no:cacheprovider tests 2>&1 | tail -25 >"$out/tests.txt"
run python3 -m app.cli devices --json
run python3 -m app.cli bench lbm "${d[@]}" --sizes 256,512,1024,2048,4096 --steps 100 --repeats 5 \
    --out "$out/lbm"
run python3 -m app.cli bench bvh "${d[@]}" --out "$out/bvh"
run python3 bench/ab_radix_bits.py "${d[@]}"
run python3 bench/ab_embree_interleaved.py "${d[@]}"
run python3 bench/lattice_stability.py "${d[@]}" --out "$out/lattice_stability.csv"
run python3 -m app.cli bench render "${d[@]}" --check-device cpu --out "$out/render"
run python3 -m app.cli bench frame "${d[@]}" --cells 256 512 1024 2048 --out "$out/frame"
run python3 -m app.cli bench frame "${d[@]}" --cells 1024 --rebuild --out "$out/frame_rebuild"
run python3 -m app.cli render scenes/pool.toml -o "$out/pool.png" "${d[@]}"
exit $status
