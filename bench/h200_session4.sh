#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-02" rows. Usage:
#   bench/h200_session4.sh OUTDIR PART
# PART baseline (at 823890e): kernel resources (registers, spills) and the frame per depth as it
#   stood, with the register cap and real-time water as A/Bs; PART final: the device tests of
#   the binned kernels, the shadow rays binned by cost (RenderSettings.cost_bins) against
#   unbinned per depth, and the tables of BENCHMARKS.md; PART rule: the combined launch's rule;
#   PART span: the device span of a frame against its kernels and wall, and a queue without
#   profiling; PART check: the last commit's device tests and frames; PART tail: what the
#   deeper levels' rays are; PART coopmax: the cooperative kernels' ray limit; PART binwg: the
#   binned kernels' work-group size. One device call each, 1-2 minutes. The
#   device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
case $part in
baseline)
    python3 bench/kernel_resources.py --out "$out/resources.json" 2>&1 | grep -E "render|caustics" \
        | awk '{print $1, $2, $3, $5, $7, $9}' | head -40
    lb bench frame $f $static --per-depth --out "$out/static_pd" | tail -1
    lb bench frame $f --per-depth --out "$out/pool_pd" | tail -1
    for r in 64 96; do
        LBWATER_CL_OPTIONS="-cl-nv-maxrregcount=$r" lb bench frame $f $static --per-depth \
            --out "$out/static_pd_r$r" | tail -1
    done
    lb bench frame $f $static --frame-time 0.0025 --out "$out/static_rt" | tail -1
    lb bench frame $f --frame-time 0.0025 --out "$out/pool_rt" | tail -1
    ;;
final)
    timeout 200 python3 -m pytest -q -p no:cacheprovider -rs tests/raytrace/test_render_bins.py \
        tests/raytrace/test_render_coop.py tests/raytrace/test_render_overlap.py \
        tests/raytrace/test_render_plans.py 2>&1 | tail -3
    for b in on off; do
        lb bench frame $f $static --per-depth --cost-bins $b --out "$out/static_pd_bins$b" | tail -1
        lb bench frame $f --per-depth --cost-bins $b --out "$out/pool_pd_bins$b" | tail -1
    done
    for rep in 1 2; do
        lb bench frame $f $static --out "$out/static_$rep" | tail -1
        lb bench frame $f --out "$out/pool_$rep" | tail -1
    done
    lb bench frame $k $static --out "$out/static4k" | tail -1
    lb bench frame $k --out "$out/pool4k" | tail -1
    lb bench frame $f $static --frame-time 0.0025 --out "$out/static_rt" | tail -1
    lb bench frame $f --frame-time 0.0025 --out "$out/pool_rt" | tail -1
    ;;
rule)   # a combined launch cooperative only when both its levels are few (694f4ab on)
    timeout 200 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_render_coop.py \
        tests/raytrace/test_render_bins.py 2>&1 | tail -2
    lb bench frame $f $static --per-depth --cost-bins off --out "$out/static_pd_binsoff" | tail -1
    lb bench frame $f $static --per-depth --out "$out/static_pd" | tail -1
    lb bench frame $f --per-depth --out "$out/pool_pd" | tail -1
    lb bench frame $f $static --out "$out/static" | tail -1
    lb bench frame $f --out "$out/pool" | tail -1
    ;;
span)   # where the wall time above the kernels goes: the device span, a queue without profiling
    for rep in 1 2; do
        for sc in "$static" ""; do
            n=$([ -n "$sc" ] && echo static || echo pool)
            lb bench frame $f $sc --out "$out/${n}_$rep" | tail -1
            lb bench frame $f $sc --no-profiling --out "$out/${n}_noprof_$rep" | tail -1
        done
    done
    lb bench frame $k $static --out "$out/static4k" | tail -1
    lb bench frame $k $static --no-profiling --out "$out/static4k_noprof" | tail -1
    ;;
check)  # the last commit's device tests and frames
    timeout 200 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_render_bins.py \
        tests/raytrace/test_render_coop.py tests/raytrace/test_render_overlap.py \
        tests/kernels/test_runtime.py tests/app/test_frame_pipeline.py 2>&1 | tail -2
    lb bench frame $f $static --out "$out/static" | tail -1
    lb bench frame $f --out "$out/pool" | tail -1
    lb bench frame $k $static --out "$out/static4k" | tail -1
    lb bench frame $k --out "$out/pool4k" | tail -1
    lb bench frame $f $static --frame-time 0.0025 --out "$out/static_rt" | tail -1
    ;;
tail)   # what the deeper levels' rays are (bench/tail_rays.py), pool and static
    python3 bench/tail_rays.py --out "$out/tail_pool.json" > /dev/null
    python3 bench/tail_rays.py --scene bench/scenes/pool_static_boat.toml \
        --out "$out/tail_static.json" > /dev/null
    python3 -c "
import json
for n in ('pool', 'static'):
    d = json.load(open('$out/tail_' + n + '.json'))
    print(n, d['rays_per_depth'])
    for k, v in d['levels'].items():
        print(' ', k, v['rays'], {kk: (vv['rays'], round(vv['abs_dy_median'], 2),
              vv['abs_dy_below_0.1'], vv['t_median'] and round(vv['t_median'], 2))
              for kk, vv in v['kinds'].items()})"
    ;;
coopmax)   # the cooperative kernels' ray limit (COOP_MAX_RAYS) 4096 against 8192 and 16384,
           # each from a copy of the tree with both mirrors of the limit changed
    for m in 4096 8192 16384; do
        variant_tree /tmp/coopmax$m "s/^COOP_MAX_RAYS = 4096/COOP_MAX_RAYS = $m/" \
            raytrace/query.py "s/#define TRACE_COOP_MAX_RAYS 4096/#define TRACE_COOP_MAX_RAYS $m/" \
            kernels/traverse_coop.h
        in_tree /tmp/coopmax$m bench frame $f --per-depth --out "$out/pool_coopmax$m" | tail -1
        in_tree /tmp/coopmax$m bench frame $f $static --per-depth \
            --out "$out/static_coopmax$m" | tail -1
    done
    ;;
binwg)   # the binned kernels' work-group (BIN_WG) 256 against 128 and 512, from copies
    for m in 256 128 512; do
        variant_tree /tmp/binwg$m "s/^BIN_WG = 256/BIN_WG = $m/" raytrace/render.py \
            "s/#define RENDER_BIN_WG 256 /#define RENDER_BIN_WG $m /" kernels/render_bins.h
        in_tree /tmp/binwg$m bench frame $f $static --per-depth --out "$out/static_binwg$m" \
            | tail -1
        in_tree /tmp/binwg$m bench frame $f --per-depth --out "$out/pool_binwg$m" | tail -1
    done
    ;;
*) echo "unknown part $part"; exit 2 ;;
esac
exit 0
