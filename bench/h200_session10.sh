#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-02 (tenth session)" rows: one
# crossing (RenderSettings.one_crossing: a shadow ray that climbs faster than the water's
# steepest slope crosses it at most once, so the walks that can find nothing are left out)
# against every walk. Usage:
#   bench/h200_session10.sh OUTDIR PART
# PART oc: the device tests of the height field and the shadow rays, then issue 9's baseline
#   scene per depth (--no-overlap) and whole frames at 1920x1080, and the pool (floating boat,
#   caustics) at 1920x1080, --one-crossing on and off in turns, twice;
# PART size: the baseline scene at 3840x2160 and the pool per depth, on and off.
# PART cull: every walk of the height field culls the rays that cannot meet the surface
#   (hf_unreachable; HF_CULL_UNREACHABLE 1) against a copy of the tree built with it 0: the
#   device tests of test_one_crossing.py (test_heightfield.py too at ba368f1; CULL_TESTS=EXPR
#   picks some with pytest -k), then the baseline scene per depth and whole, the pool whole, in turns twice,
#   the pool per depth and the baseline scene at 3840x2160.
# PART cull-pocl: the same A/B on PoCL (this machine's CPUs), small sizes.
# PART tune: the kernel choices tuned before the light buffer and one crossing, again: the
#   baseline scene and the pool at 1920x1080 with the defaults (first and last) and with
#   --cost-bins off, --overlap-from 0 and 2, --coop-from 1 and 3.
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
case $part in
oc)
    timeout 400 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_one_crossing.py \
        tests/raytrace/test_heightfield.py tests/raytrace/test_render_shadow.py 2>&1 | tail -3
    for rep in 1 2; do
        for oc in on off; do
            lb bench frame $f $static --per-depth --no-overlap --one-crossing $oc \
                --out "$out/static_pd_oc${oc}_$rep" | tail -1
            lb bench frame $f $static --one-crossing $oc --out "$out/static_oc${oc}_$rep" | tail -1
            lb bench frame $f --one-crossing $oc --out "$out/pool_oc${oc}_$rep" | tail -1
        done
    done
    ;;
size)
    for oc in on off; do
        lb bench frame $k $static --one-crossing $oc --out "$out/static4k_oc$oc" | tail -1
        lb bench frame $f --per-depth --no-overlap --one-crossing $oc --out "$out/pool_pd_oc$oc" \
            | tail -1
    done
    ;;
cull)
    variant_tree /tmp/walkall \
        's/^#define HF_CULL_UNREACHABLE 1/#define HF_CULL_UNREACHABLE 0/' \
        kernels/traverse_heightfield.h
    timeout 300 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_one_crossing.py \
        -k "${CULL_TESTS:-not nothing}" 2>&1 | tail -3
    for rep in 1 2; do
        lb bench frame $f $static --per-depth --no-overlap --out "$out/static_pd_cull_$rep" \
            | tail -1
        in_tree /tmp/walkall bench frame $f $static --per-depth --no-overlap \
            --out "$out/static_pd_walkall_$rep" | tail -1
        lb bench frame $f $static --out "$out/static_cull_$rep" | tail -1
        in_tree /tmp/walkall bench frame $f $static --out "$out/static_walkall_$rep" | tail -1
        lb bench frame $f --out "$out/pool_cull_$rep" | tail -1
        in_tree /tmp/walkall bench frame $f --out "$out/pool_walkall_$rep" | tail -1
    done
    lb bench frame $f --per-depth --no-overlap --out "$out/pool_pd_cull" | tail -1
    in_tree /tmp/walkall bench frame $f --per-depth --no-overlap --out "$out/pool_pd_walkall" \
        | tail -1
    lb bench frame $k $static --out "$out/static4k_cull" | tail -1
    in_tree /tmp/walkall bench frame $k $static --out "$out/static4k_walkall" | tail -1
    ;;
cull-pocl)
    # the same A/B on a CPU (PoCL), small: 128 cells, 480x270, 6 frames
    variant_tree /tmp/walkall \
        's/^#define HF_CULL_UNREACHABLE 1/#define HF_CULL_UNREACHABLE 0/' \
        kernels/traverse_heightfield.h
    small="--cells 128 --size 480 270 --frames 6"
    for rep in 1 2; do
        lb bench frame $small $static --out "$out/pocl_static_cull_$rep" | tail -1
        in_tree /tmp/walkall bench frame $small $static --out "$out/pocl_static_walkall_$rep" \
            | tail -1
        lb bench frame $small --out "$out/pocl_pool_cull_$rep" | tail -1
        in_tree /tmp/walkall bench frame $small --out "$out/pocl_pool_walkall_$rep" | tail -1
    done
    ;;
tune)
    for scene in static pool; do
        sc=""
        [ $scene = static ] && sc=$static
        lb bench frame $f $sc --out "$out/${scene}_default_1" | tail -1
        for v in "--cost-bins off" "--overlap-from 0" "--overlap-from 2" "--coop-from 1" \
                 "--coop-from 3"; do
            lb bench frame $f $sc $v --out "$out/${scene}_$(echo $v | tr -d ' -')" | tail -1
        done
        lb bench frame $f $sc --out "$out/${scene}_default_2" | tail -1
    done
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
