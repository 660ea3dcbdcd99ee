#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-04 (thirteenth session)" rows.
# Usage: bench/h200_session13.sh OUTDIR PART
# PART regs: the shadow kernels' occupancy. The plain shadow kernel holds 160 registers, so at
#   most 12 warps an SM run it. The baseline scene per depth at 1920x1080 (--per-depth
#   --no-overlap), the tree first and last, against builds with every kernel's registers capped
#   (LBWATER_CL_OPTIONS=-cl-nv-maxrregcount=N: only the shadow kernels hold more than 96) and
#   copies of the tree whose per-ray work-groups hold 32 or 128 work-items
#   (RenderSettings.local_size, 64 as built); then the capped builds' registers and spills
#   (bench/kernel_resources.py).
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
case $part in
regs)
    g="$f $static --per-depth --no-overlap"
    for n in 32 128; do
        variant_tree /tmp/ls$n "s/^    local_size: int = 64 /    local_size: int = $n /" \
            raytrace/render.py
    done
    lb bench frame $g --out "$out/static_pd_tree_1" | tail -1
    for n in 128 112 96 80; do
        LBWATER_CL_OPTIONS=-cl-nv-maxrregcount=$n lb bench frame $g \
            --out "$out/static_pd_cap$n" | tail -1
    done
    for n in 32 128; do
        in_tree /tmp/ls$n bench frame $g --out "$out/static_pd_ls$n" 2>&1 | tail -1
    done
    lb bench frame $g --out "$out/static_pd_tree_2" | tail -1
    for n in 128 96; do
        LBWATER_CL_OPTIONS=-cl-nv-maxrregcount=$n timeout 100 python3 bench/kernel_resources.py \
            --scene bench/scenes/pool_static_boat.toml --out "$out/resources_cap$n.json" | tail -1
    done
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
