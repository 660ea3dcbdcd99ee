#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-02 (ninth session)" rows: the light
# buffer (raytrace/light_buffer.py: each directional light's map of the opaque triangles'
# shadows, the shadow rays' any-hit query without a BVH walk) against none. Usage:
#   bench/h200_session9.sh OUTDIR PART
# PART lb: the device tests of the light buffer and the shadow rays, then issue 9's baseline
#   scene per depth (--no-overlap) and whole frames at 1920x1080, and the pool (a floating boat:
#   the map rebuilt from the live transform rows each frame) at 1920x1080, --light-buffer 1024
#   and 0 in turns, twice;
# PART size: the baseline scene at 3840x2160 with 1024 and 0, and at 1920x1080 with maps of 512
#   and 2048 cells (whole frames and per depth); the pool per depth with 1024 and 0.
# PART coophf: the cooperative walk of the height field (bench/patches/coop_heightfield.patch,
#   tried and left out) against the walk of one lane: its device tests, then the pool and the
#   baseline scene at 1920x1080, whole frames in turns twice and per depth. Run at b79f116 and
#   284b46e, where the patch was in the tree and the copy had it reversed; from the tree as it
#   is now, the copy gets it applied: "coophf" and "old" name the same two walks.
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
case $part in
lb)
    timeout 300 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_light_buffer.py \
        tests/raytrace/test_render_shadow.py 2>&1 | tail -3
    g="$f $static --per-depth --no-overlap"
    for rep in 1 2; do
        for c in 1024 0; do
            lb bench frame $g --light-buffer $c --out "$out/static_pd_lb${c}_$rep" | tail -1
            lb bench frame $f $static --light-buffer $c --out "$out/static_lb${c}_$rep" | tail -1
            lb bench frame $f --light-buffer $c --out "$out/pool_lb${c}_$rep" | tail -1
        done
    done
    ;;
size)
    for c in 1024 0; do
        lb bench frame $k $static --light-buffer $c --out "$out/static4k_lb$c" | tail -1
    done
    for c in 512 2048; do
        lb bench frame $f $static --light-buffer $c --out "$out/static_lb$c" | tail -1
        lb bench frame $f $static --per-depth --no-overlap --light-buffer $c \
            --out "$out/static_pd_lb$c" | tail -1
    done
    for c in 1024 0; do
        lb bench frame $f --per-depth --no-overlap --light-buffer $c --out "$out/pool_pd_lb$c" \
            | tail -1
    done
    ;;
coophf)
    variant_tree /tmp/coop
    (cd /tmp/coop && patch -p1 -s < "$OLDPWD/bench/patches/coop_heightfield.patch")
    (cd /tmp/coop && PYTHONPATH=/tmp/site:/tmp/coop timeout 400 python3 -m pytest -q \
        -p no:cacheprovider tests/raytrace/test_heightfield.py tests/raytrace/test_trace_coop.py \
        tests/raytrace/test_render_coop.py 2>&1 | tail -3)
    for rep in 1 2; do
        in_tree /tmp/coop bench frame $f --out "$out/pool_coophf_$rep" | tail -1
        lb bench frame $f --out "$out/pool_old_$rep" | tail -1
        in_tree /tmp/coop bench frame $f $static --out "$out/static_coophf_$rep" | tail -1
        lb bench frame $f $static --out "$out/static_old_$rep" | tail -1
    done
    in_tree /tmp/coop bench frame $f --per-depth --no-overlap --out "$out/pool_pd_coophf" \
        | tail -1
    lb bench frame $f --per-depth --no-overlap --out "$out/pool_pd_old" | tail -1
    in_tree /tmp/coop bench frame $f $static --per-depth --no-overlap \
        --out "$out/static_pd_coophf" | tail -1
    lb bench frame $f $static --per-depth --no-overlap --out "$out/static_pd_old" | tail -1
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
