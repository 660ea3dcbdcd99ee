#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-02 (sixth session)" rows: two LBM
# steps per launch (lbm_step2) against one, its tile's shape, and the frame tables. Usage:
#   bench/h200_session6.sh OUTDIR PART
# PART lbm: the LBM's device tests (lbm_step2 against lbm_step bit for bit, the reference), then
#   bench lbm with one and two steps per launch, and lbm_step2's tile A/B (copies of the tree
#   with STEP2_TILE changed); PART frame: the frame's device tests, then issue 9's baseline scene
#   and the pool at 1080p (per depth too) and 4K, real-time water, the water's BVH, each with one
#   step per launch beside (a copy of the tree whose default is 1); PART final: the device tests
#   of the session's changes, then the tables of BENCHMARKS.md at the final defaults, the
#   water's BVH beside the height field, the TLAS's five launches beside its one (a copy of the
#   tree), the host's cost of a launch and of a frame; PART readq: where the time between frames
#   goes: the image read on the main queue (no cross-queue wait) and, as a diagnosis only (the
#   next frame may overwrite the image being read), without the render's wait for the last read;
#   PART reads: one read each of the counts and the guard record per frame, the counts on the
#   copy queue, against the four reads on the main queue before (a copy of the tree); PART
#   guardq: the guard record's copy (made by the frame's last check) read on the copy queue
#   against the record read on the main queue (a copy of the tree); PART shadows: every level's
#   shadow rays in launches of their own (--no-overlap), per depth, beside the primary trace;
#   PART shadowparts: where level 1's shadow time goes, as a diagnosis only (the images are
#   wrong): copies of the tree without the any-hit query, without the crossings, with one
#   crossing at most.
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
one_step() { variant_tree /tmp/spl1 \
    "s/return 2 if self.rt.is_gpu and fits else 1/return 1/" lbm/solver.py; }
case $part in
lbm)
    timeout 240 python3 -m pytest -q -p no:cacheprovider tests/lbm/test_step2.py \
        tests/lbm/test_kernels.py tests/lbm/test_exact_volume.py tests/lbm/test_bodies_fast.py \
        2>&1 | tail -3
    lb bench lbm --sizes 1024,2048 --steps-per-launch 1,2 --out "$out/lbm" 2>&1 | grep -v "^$"
    for t in "32, 4" "64, 4" "16, 16"; do
        w=/tmp/tile${t//[, ]/}
        variant_tree "$w" "s/^STEP2_TILE = (32, 8)$/STEP2_TILE = ($t)/" lbm/solver.py
        in_tree "$w" bench lbm --sizes 1024 --steps-per-launch 2 --out "$out/tile${t//[, ]/x}" \
            2>&1 | grep "x2:"
    done
    ;;
frame)
    timeout 300 python3 -m pytest -q -p no:cacheprovider tests/lbm/test_step2.py \
        tests/raytrace/test_heightfield.py tests/app/test_frame_pipeline.py 2>&1 | tail -3
    one_step
    for rep in 1 2; do
        lb bench frame $f $static --out "$out/static_$rep" | tail -1
        in_tree /tmp/spl1 bench frame $f $static --out "$out/static_spl1_$rep" | tail -1
        lb bench frame $f --out "$out/pool_$rep" | tail -1
        in_tree /tmp/spl1 bench frame $f --out "$out/pool_spl1_$rep" | tail -1
    done
    lb bench frame $f $static --per-depth --out "$out/static_pd" | tail -1
    in_tree /tmp/spl1 bench frame $f $static --per-depth --out "$out/static_pd_spl1" | tail -1
    lb bench frame $f --per-depth --out "$out/pool_pd" | tail -1
    lb bench frame $k $static --out "$out/static4k" | tail -1
    in_tree /tmp/spl1 bench frame $k $static --out "$out/static4k_spl1" | tail -1
    lb bench frame $k --out "$out/pool4k" | tail -1
    lb bench frame $f $static --frame-time 0.0025 --out "$out/static_rt" | tail -1
    lb bench frame $f --frame-time 0.0025 --out "$out/pool_rt" | tail -1
    lb bench frame $f $static --water-accel bvh --out "$out/static_bvh" | tail -1
    lb bench frame $f $static --no-profiling --out "$out/static_noprof" | tail -1
    ;;
final)
    timeout 300 python3 -m pytest -q -p no:cacheprovider tests/lbm/test_step2.py \
        tests/raytrace/test_heightfield.py tests/raytrace/test_tlas_one_launch.py \
        tests/raytrace/test_render_coop.py tests/raytrace/test_render_bins.py \
        tests/app/test_frame_pipeline.py 2>&1 | tail -3
    variant_tree /tmp/tlas5 "s/self.tlas_one_launch = TLAS_ONE_LAUNCH/self.tlas_one_launch = 0/" \
        raytrace/scene.py
    for rep in 1 2; do
        lb bench frame $f $static --out "$out/static_$rep" | tail -1
        lb bench frame $f --out "$out/pool_$rep" | tail -1
    done
    for acc in grid bvh; do
        lb bench frame $f $static --per-depth --water-accel $acc --out "$out/static_pd_$acc" \
            | tail -1
        lb bench frame $f --per-depth --water-accel $acc --out "$out/pool_pd_$acc" | tail -1
        lb bench frame $k $static --water-accel $acc --out "$out/static4k_$acc" | tail -1
        lb bench frame $f $static --frame-time 0.0025 --water-accel $acc \
            --out "$out/static_rt_$acc" | tail -1
    done
    lb bench frame $k --out "$out/pool4k" | tail -1
    lb bench frame $f --frame-time 0.0025 --out "$out/pool_rt" | tail -1
    lb bench frame $f $static --no-profiling --out "$out/static_noprof" | tail -1
    in_tree /tmp/tlas5 bench frame $f $static --per-depth --out "$out/static_pd_tlas5" | tail -1
    python3 bench/launch_cost.py | tee "$out/launch_cost.json"
    python3 bench/host_frame.py --scene bench/scenes/pool_static_boat.toml --cells 1024 \
        --size 1920 1080 --hold-ms 0 --photons 131072 --caustic-resolution 256 \
        | tee "$out/host_frame.json"
    ;;
readq)
    variant_tree /tmp/mainq \
        's/slot.image = rings\["image"\].enqueue_read(copy, src, wait_for=\[done\])/slot.image = rings["image"].enqueue_read(q, src)/' \
        app/world.py
    variant_tree /tmp/nowait "s/        if w._image_read is not None:   # the last/        if False:   # the last/" \
        app/world.py
    for rep in 1 2; do
        lb bench frame $f $static --out "$out/static_$rep" | tail -1
        in_tree /tmp/mainq bench frame $f $static --out "$out/static_mainq_$rep" | tail -1
        in_tree /tmp/nowait bench frame $f $static --out "$out/static_nowait_$rep" | tail -1
    done
    ;;
reads)
    variant_tree /tmp/reads4 \
        "s/self.sim.read_guard_each_check = False/self.sim.read_guard_each_check = True/; s/read_stats=False)   # _Readback reads them/read_stats=True)/; s/rings\[\"counts\"\].enqueue_read(copy, r.stats, wait_for=\[done\])/rings[\"counts\"].enqueue_read(q, r.stats)/" \
        app/world.py
    grep -c "read_guard_each_check = True\|read_stats=True)\|enqueue_read(q, r.stats)" /tmp/reads4/app/world.py
    for rep in 1 2 3; do
        lb bench frame $f $static --out "$out/static_$rep" | tail -1
        in_tree /tmp/reads4 bench frame $f $static --out "$out/static_reads4_$rep" | tail -1
    done
    lb bench frame $f --out "$out/pool" | tail -1
    in_tree /tmp/reads4 bench frame $f --out "$out/pool_reads4" | tail -1
    ;;
guardq)
    variant_tree /tmp/guardq \
        "s/slot.guard = rings\[\"guard\"\].enqueue_read(copy, slot.guard_copy, wait_for=\[done\])/slot.guard = rings[\"guard\"].enqueue_read(q, slot.guard_copy)/" \
        app/world.py
    for rep in 1 2 3; do
        lb bench frame $f $static --out "$out/static_$rep" | tail -1
        in_tree /tmp/guardq bench frame $f $static --out "$out/static_guardq_$rep" | tail -1
    done
    ;;
shadows)
    lb bench frame $f $static --per-depth --no-overlap --out "$out/static_pd_nooverlap" | tail -1
    lb bench frame $f --per-depth --no-overlap --out "$out/pool_pd_nooverlap" | tail -1
    ;;
shadowparts)
    variant_tree /tmp/noany "s/    if (trace_any_masked(TRACE_ARGS, org, dir, 0.0f, tmax, opaque, TRACE_KIND_SHADOW))/    if (false \&\& trace_any_masked(TRACE_ARGS, org, dir, 0.0f, tmax, opaque, TRACE_KIND_SHADOW))/" \
        kernels/render_shadow.h
    variant_tree /tmp/nocross "s/    if (!prm->transmissive_shadows) return (float3)(1.0f);/    return (float3)(1.0f);/" \
        kernels/render_shadow.h
    variant_tree /tmp/onecross "s/#define RENDER_MAX_SHADOW_CROSSINGS 4/#define RENDER_MAX_SHADOW_CROSSINGS 1/" \
        kernels/render_types.h
    g="$f $static --per-depth --no-overlap"
    lb bench frame $g --out "$out/static" | tail -1
    for v in noany nocross onecross; do
        in_tree /tmp/$v bench frame $g --out "$out/static_$v" 2>&1 | tail -1
    done
    ;;
*) echo "unknown part $part"; exit 2 ;;
esac
exit 0
