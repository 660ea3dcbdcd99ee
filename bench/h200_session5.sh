#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-02 (fifth session)" rows: the water
# traced as a height field (raytrace.heightfield) against its LBVH. Usage:
#   bench/h200_session5.sh OUTDIR PART
# PART ab: the height field's device tests, then issue 9's baseline scene and the pool at
#   1080p (per depth) and 4K, water_accel grid against bvh, and real-time water; PART final: the
#   device tests of the walk, the renderer and the frame, then the tables of BENCHMARKS.md;
#   PART blocks: the y-range block's size (HF_BLOCK) A/B, per depth; PART cull: the walk's cell
#   test on compact heights A/B, frames in flight, the host's time per frame; PART tlas: the
#   TLAS in one launch, the host's cost of a launch (bench/launch_cost.py) and of a frame.
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
tests="tests/raytrace/test_heightfield.py tests/raytrace/test_tlas_one_launch.py
    tests/raytrace/test_render_coop.py tests/raytrace/test_render_bins.py
    tests/app/test_frame_pipeline.py"
case $part in
ab)
    timeout 240 python3 -m pytest -q -p no:cacheprovider -x tests/raytrace/test_heightfield.py \
        2>&1 | tail -3
    for acc in grid bvh; do
        lb bench frame $f $static --per-depth --water-accel $acc --out "$out/static_pd_$acc" \
            | tail -1
        lb bench frame $f --per-depth --water-accel $acc --out "$out/pool_pd_$acc" | tail -1
    done
    for acc in grid bvh; do
        lb bench frame $f $static --water-accel $acc --out "$out/static_$acc" | tail -1
        lb bench frame $k $static --water-accel $acc --out "$out/static4k_$acc" | tail -1
        lb bench frame $f $static --frame-time 0.0025 --water-accel $acc \
            --out "$out/static_rt_$acc" | tail -1
    done
    ;;
blocks)   # the y-range block's size: copies of the tree with HF_BLOCK 4 and 16 against 8
    for b in 4 16; do
        variant_tree /tmp/hfb$b "s/#define HF_BLOCK 8 /#define HF_BLOCK $b /" kernels/heightfield.h \
            "s/^HF_BLOCK = 8$/HF_BLOCK = $b/" raytrace/heightfield.py
    done
    for rep in 1 2; do
        lb bench frame $f $static --per-depth --out "$out/static_pd_b8_$rep" | tail -1
        for b in 4 16; do
            in_tree /tmp/hfb$b bench frame $f $static --per-depth --out "$out/static_pd_b${b}_$rep" \
                | tail -1
        done
    done
    lb bench frame $f $static --per-depth --water-accel bvh --out "$out/static_pd_bvh" | tail -1
    lb bench frame $f --per-depth --out "$out/pool_pd_b8" | tail -1
    in_tree /tmp/hfb4 bench frame $f --per-depth --out "$out/pool_pd_b4" | tail -1
    ;;
cull)   # the cell test on compact heights against the vertices, frames in flight, host time
    for rep in 1 2; do
        lb bench frame $f $static --per-depth --out "$out/static_pd_cull_$rep" | tail -1
        LBWATER_CL_OPTIONS=-DHF_CULL_HEIGHTS=0 lb bench frame $f $static --per-depth \
            --out "$out/static_pd_nocull_$rep" | tail -1
    done
    for n in 2 3; do
        lb bench frame $f $static --frames-in-flight $n --out "$out/static_fif$n" | tail -1
        lb bench frame $f $static --frame-time 0.0025 --frames-in-flight $n \
            --out "$out/static_rt_fif$n" | tail -1
    done
    python3 bench/host_frame.py --scene bench/scenes/pool_static_boat.toml --cells 1024 \
        --size 1920 1080 --hold-ms 0 --photons 131072 --caustic-resolution 256 \
        | tee "$out/host_frame.json"
    ;;
tlas)   # the TLAS in one launch; the host's cost of a launch and of a frame
    python3 bench/launch_cost.py | tee "$out/launch_cost.json"
    for rep in 1 2; do
        lb bench frame $f $static --per-depth --out "$out/static_pd_$rep" | tail -1
        lb bench frame $f $static --frame-time 0.0025 --out "$out/static_rt_$rep" | tail -1
    done
    python3 bench/host_frame.py --scene bench/scenes/pool_static_boat.toml --cells 1024 \
        --size 1920 1080 --hold-ms 0 --photons 131072 --caustic-resolution 256 \
        | tee "$out/host_frame.json"
    ;;
final)   # the device tests, then the tables of BENCHMARKS.md, the water's BVH beside
    timeout 300 python3 -m pytest -q -p no:cacheprovider $tests 2>&1 | tail -3
    for rep in 1 2; do
        lb bench frame $f $static --out "$out/static_$rep" | tail -1
        lb bench frame $f --out "$out/pool_$rep" | tail -1
    done
    lb bench frame $f $static --water-accel bvh --out "$out/static_bvh" | tail -1
    lb bench frame $f --water-accel bvh --out "$out/pool_bvh" | tail -1
    lb bench frame $f $static --per-depth --out "$out/static_pd" | tail -1
    lb bench frame $f --per-depth --out "$out/pool_pd" | tail -1
    lb bench frame $k $static --out "$out/static4k" | tail -1
    lb bench frame $k --out "$out/pool4k" | tail -1
    lb bench frame $k $static --water-accel bvh --out "$out/static4k_bvh" | tail -1
    lb bench frame $f $static --frame-time 0.0025 --out "$out/static_rt" | tail -1
    lb bench frame $f --frame-time 0.0025 --out "$out/pool_rt" | tail -1
    lb bench frame $f $static --frame-time 0.0025 --water-accel bvh --out "$out/static_rt_bvh" \
        | tail -1
    ;;
*) echo "unknown part $part"; exit 2 ;;
esac
