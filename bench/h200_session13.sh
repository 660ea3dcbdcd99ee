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
# PART lean: bench/shadow_lean_probe.py on today's tree (the eighth session's probe: each level's
#   shadow rays as the frame runs them, and as a list the shading writes, traced by a kernel that
#   holds nothing else) at 1920x1080 on the baseline scene, and on copies of the tree whose
#   shadow_transmittance leaves out the fallback walk (nofallback: full cells' rays unshadowed),
#   the crossings (nocross) or both (notrace): the images wrong on purpose, to see what a
#   list-traced stage would cost at best.
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
lean)
    nofallback='s/^    return trace_any_masked(TRACE_ARGS, org, dir, 0.0f, tmax, mask, TRACE_KIND_SHADOW);/    return false;/'
    nocross='s/^    if (!prm->transmissive_shadows) return (float3)(1.0f);/    return (float3)(1.0f);/'
    variant_tree /tmp/nofallback "$nofallback" kernels/render_shadow.h
    variant_tree /tmp/nocross "$nocross" kernels/render_shadow.h
    variant_tree /tmp/notrace "$nofallback" kernels/render_shadow.h "$nocross" kernels/render_shadow.h
    a="--scene bench/scenes/pool_static_boat.toml --cells 1024 --size 1920 1080 --repeats 20"
    timeout 150 python3 bench/shadow_lean_probe.py $a --json "$out/lean_tree.json" | tail -4
    for v in nofallback nocross notrace; do
        (cd /tmp/$v && PYTHONPATH=/tmp/site:/tmp/$v timeout 150 python3 bench/shadow_lean_probe.py \
            $a --json "$out/lean_$v.json" | tail -4)
    done
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
