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
# PART fine: the light buffer's fine grids (a full cell's 8 x 8 fine cells) against the tree
#   before them, in $OLD (a checkout of eadbbbb: git worktree add DIR eadbbbb; on the device, a
#   copy of its app, kernels, lbm, raytrace, bench and tests beside today's scenes; for fine
#   cells of 32 triangles, at 1ee46d6 and later, a checkout of cf5f4c2, whose fine cells hold 16): the device
#   tests of the light buffer, then the baseline scene per depth and whole at 1920x1080 in turns
#   twice, at 3840x2160, and the pool (its boat floats: a build every frame) whole and per depth.
# PART leanfine: bench/shadow_lean_probe.py (as PART lean) on the tree with fine grids against
#   $OLD, twice in turns.
# PART order: what the rays of full light-buffer cells cost a list-traced shadow stage, and
#   whether starting them first hides it: bench/shadow_lean_probe.py with and without
#   --full-first on the tree (fine grids), on $OLD (walks; its probe and light_buffer_full as
#   the tree has them), and on copies of the tree with no fallback walk (nofallback, wrong
#   images) or with the walk's code compiled in but never run (neverwalk: a condition the
#   compiler cannot see through, prm->n_lights > 1000; wrong images).
# PART ordered: bench/shadow_lean_probe.py's render_shadow_ordered(_binned) (the renderer's own
#   shadow kernels over the hits whose shadow rays start in a full light-buffer cell first,
#   flagged by render_shadow_classify) against render_shadow(_binned), twice, at 1920x1080, and
#   at 3840x2160 once; with -cl-nv-verbose for the kernels' registers.
# Each PART ran on the tree of the commit its results are named by (bench/results/
# h200-2026-12-04-s13/PART_COMMIT.json): regs and lean on eadbbbb (any tree since); fine on
# ed5c32a (fine grids by a second raster pass) and on cf5f4c2 (from a pair list); leanfine and
# order on ed5c32a, with $OLD holding eadbbbb's tree plus ed5c32a's probe
# (bench/shadow_lean_probe.py, kernels/render_shadow_lean_probe.cl) and its light_buffer_full
# (kernels/light_buffer.h) copied in, so that --full-first runs there; ordered on 6e5b647 or
# later.
# PART coop: the tail levels' cooperative kernels (a work-group per ray from --coop-from D, 2
#   on a GPU) now that fine grids leave few walks: the baseline scene per depth and whole at
#   1920x1080 with D = 2, 3, 4 and off, in turns twice, and the pool whole.
# PART alllevels: bench/shadow_lean_probe.py --full-first --all-levels: every level's shadow
#   rays (0-5) as lists traced in one launch against each level's alone and the primary trace,
#   twice (on 4ac7b0d or later).
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
fine)
    old=${OLD:?OLD: a checkout of eadbbbb}
    [ -d "$old/scenes" ] || cp -r scenes "$old"/
    timeout 200 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_light_buffer.py \
        2>&1 | tail -1
    g="$f $static --per-depth --no-overlap"
    for rep in 1 2; do
        lb bench frame $g --out "$out/static_pd_fine_$rep" | tail -1
        in_tree "$old" bench frame $g --out "$out/static_pd_old_$rep" 2>&1 | tail -1
        lb bench frame $f $static --out "$out/static_fine_$rep" | tail -1
        in_tree "$old" bench frame $f $static --out "$out/static_old_$rep" | tail -1
    done
    lb bench frame $k $static --out "$out/static4k_fine" | tail -1
    in_tree "$old" bench frame $k $static --out "$out/static4k_old" | tail -1
    lb bench frame $f --out "$out/pool_fine" | tail -1
    in_tree "$old" bench frame $f --out "$out/pool_old" | tail -1
    lb bench frame $f --per-depth --no-overlap --out "$out/pool_pd_fine" | tail -1
    in_tree "$old" bench frame $f --per-depth --no-overlap --out "$out/pool_pd_old" | tail -1
    a="--scene bench/scenes/pool_static_boat.toml --cells 1024 --size 1920 1080 --repeats 20"
    timeout 150 python3 bench/shadow_lean_probe.py $a --full-first --json "$out/lean_first.json" \
        | tail -2
    ;;
leanfine)
    old=${OLD:?OLD: a checkout of eadbbbb}
    [ -d "$old/scenes" ] || cp -r scenes "$old"/
    a="--scene bench/scenes/pool_static_boat.toml --cells 1024 --size 1920 1080 --repeats 20"
    for rep in 1 2; do
        timeout 150 python3 bench/shadow_lean_probe.py $a --json "$out/lean_fine_$rep.json" \
            | tail -2
        (cd "$old" && PYTHONPATH=/tmp/site:$old timeout 150 python3 bench/shadow_lean_probe.py \
            $a --json "$out/lean_old_$rep.json" | tail -2)
    done
    ;;
order)
    old=${OLD:?OLD: a checkout of eadbbbb}
    [ -d "$old/scenes" ] || cp -r scenes "$old"/
    nofallback='s/^    return trace_any_masked(TRACE_ARGS, org, dir, 0.0f, tmax, mask, TRACE_KIND_SHADOW);/    return false;/'
    neverwalk='s/^            \&\& shadow_any_walk(TRACE_ARGS, org, dir, tmax, opaque)))/            \&\& prm->n_lights > 1000u \&\& shadow_any_walk(TRACE_ARGS, org, dir, tmax, opaque)))/'
    variant_tree /tmp/nofallback "$nofallback" kernels/render_shadow.h
    variant_tree /tmp/neverwalk "$neverwalk" kernels/render_shadow.h
    a="--scene bench/scenes/pool_static_boat.toml --cells 1024 --size 1920 1080 --repeats 20"
    probe_in() {   # probe_in DIR NAME [ARGS]
        local w=$1 n=$2; shift 2
        (cd "$w" && PYTHONPATH=/tmp/site:$w timeout 150 python3 bench/shadow_lean_probe.py $a \
            "$@" --json "$out/lean_$n.json" | tail -2)
    }
    for rep in 1 2; do
        probe_in "$PWD" fine_$rep
        probe_in "$PWD" fine_first_$rep --full-first
        probe_in "$old" old_$rep
        probe_in "$old" old_first_$rep --full-first
    done
    probe_in /tmp/nofallback nofallback
    probe_in /tmp/nofallback nofallback_first --full-first
    probe_in /tmp/neverwalk neverwalk
    ;;
ordered)
    a="--scene bench/scenes/pool_static_boat.toml --cells 1024 --repeats 20"
    for rep in 1 2; do
        LBWATER_CL_OPTIONS=-cl-nv-verbose timeout 150 python3 bench/shadow_lean_probe.py $a \
            --size 1920 1080 --json "$out/ordered_$rep.json" | tail -2
    done
    timeout 200 python3 bench/shadow_lean_probe.py $a --size 3840 2160 \
        --json "$out/ordered_4k.json" | tail -2
    ;;
coop)
    for rep in 1 2; do
        for c in 2 3 4 off; do
            lb bench frame $f $static --per-depth --no-overlap --coop-from $c \
                --out "$out/static_pd_coop${c}_$rep" | tail -1
            lb bench frame $f $static --coop-from $c --out "$out/static_coop${c}_$rep" | tail -1
        done
    done
    for c in 2 off; do
        lb bench frame $f --coop-from $c --out "$out/pool_coop$c" | tail -1
    done
    ;;
alllevels)
    a="--scene bench/scenes/pool_static_boat.toml --cells 1024 --size 1920 1080 --repeats 20"
    for rep in 1 2; do
        timeout 250 python3 bench/shadow_lean_probe.py $a --full-first --all-levels \
            --json "$out/all_levels_$rep.json" | tail -1
    done
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
