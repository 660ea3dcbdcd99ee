#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-02 (eighth session)" rows: what a
# shadow stage that traced a list of rays written by the shading would cost (the probe of
# bench/shadow_lean_probe.py), and the shadow kernels' per-hit code split into shadow_site and
# light_term (bench/patches/shadow_site.patch) against the body as it was. Usage:
#   bench/h200_session8.sh OUTDIR PART
# PART lean: the device tests of the probe and the shadow rays, then the probe on issue 9's
#   baseline scene at 1920x1080 and 3840x2160 and on the pool at 1920x1080; then the baseline
#   scene per depth (--no-overlap) and whole frames, the split against the old body (the
#   patch reversed in a copy of the tree), in turns;
# PART hfblock: the height field's y-range blocks of 4 and 16 cells a side (HF_BLOCK, copies of
#   the tree) against 8, on the pool and the baseline scene, whole frames in turns and per depth.
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
probe() { LBWATER_CL_OPTIONS=-cl-nv-verbose python3 bench/shadow_lean_probe.py "$@"; }
case $part in
lean)
    timeout 300 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_shadow_lean_probe.py \
        tests/raytrace/test_render_shadow.py 2>&1 | tail -3
    probe $static --cells 1024 --size 1920 1080 --settle 60 --repeats 20 \
        --json "$out/lean_static.json"
    probe $static --cells 1024 --size 3840 2160 --settle 60 --repeats 10 \
        --json "$out/lean_static4k.json"
    probe --scene scenes/pool.toml --cells 1024 --size 1920 1080 --settle 60 --repeats 20 \
        --json "$out/lean_pool.json"
    variant_tree /tmp/old
    (cd /tmp/old && patch -p1 -s -R < "$OLDPWD/bench/patches/shadow_site.patch")
    g="$f $static --per-depth --no-overlap"
    for rep in 1 2; do
        lb bench frame $g --out "$out/static_pd_$rep" | tail -1
        in_tree /tmp/old bench frame $g --out "$out/static_pd_old_$rep" | tail -1
        lb bench frame $f $static --out "$out/static_$rep" | tail -1
        in_tree /tmp/old bench frame $f $static --out "$out/static_old_$rep" | tail -1
    done
    ;;
hfblock)
    for b in 4 16; do
        variant_tree /tmp/hf$b "s/#define HF_BLOCK 8 /#define HF_BLOCK $b /" kernels/heightfield.h \
            "s/^HF_BLOCK = 8$/HF_BLOCK = $b/" raytrace/heightfield.py
    done
    (cd /tmp/hf4 && PYTHONPATH=/tmp/site:/tmp/hf4 timeout 120 python3 -m pytest -q \
        -p no:cacheprovider tests/raytrace/test_heightfield.py 2>&1 | tail -1)
    hf() { local b=$1; shift; if [ "$b" = 8 ]; then lb "$@"; else in_tree /tmp/hf$b "$@"; fi; }
    for rep in 1 2; do
        for b in 8 4 16; do
            hf $b bench frame $f --out "$out/pool_hf${b}_$rep" | tail -1
            hf $b bench frame $f $static --out "$out/static_hf${b}_$rep" | tail -1
        done
    done
    for b in 8 4 16; do
        hf $b bench frame $f --per-depth --no-overlap --out "$out/pool_pd_hf$b" | tail -1
        hf $b bench frame $f $static --per-depth --no-overlap --out "$out/static_pd_hf$b" \
            | tail -1
    done
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
