#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-04 (twelfth session)" rows. Usage:
#   bench/h200_session12.sh OUTDIR PART
# PART stack: diagnoses (copies of the tree) of what the shadow stage's two BVH walks cost, the
#   any-hit walk that full light-buffer cells fall back to and the crossings' closest hit
#   through trace_closest_only (TLAS and BLAS code beside the height field's walk): cells of up
#   to 64 or 256 triangles (s64, s256: fewer walks), the crossings through the height field's
#   walk alone (hfonly: bench/patches/shadow_crossing_hf_only.patch, the same image where the
#   crossing instance is the height field, as in the baseline scene), no fallback walk
#   (nofallback: rays of full cells unshadowed), neither walk (nostack) and neither with cells
#   of 256 (s256nostack: wrong only in the cells of more). The baseline scene per depth at
#   1920x1080, the tree first and last; then each one's registers and stack
#   (bench/kernel_resources.py).
# PART frames: whole frames of the baseline scene, the tree against nostack, levels overlapped
#   (as the frame runs) and not (--no-overlap), twice in turns; then each at 3840x2160.
# PART mapped: the shadow kernels with no BVH walk (SHADOW_MAPPED), as the tree takes them
#   (--mapped-shadows on) against those that walk (off): their device tests, the baseline scene
#   per depth and whole at 1920x1080 in turns twice, at 3840x2160, and the pool whole.
# PART boxes: the mapped kernels with a long list's triangles tested first against their
#   footprint's box (as the tree has it) against every cell's so (boxall) and the walking
#   kernels (--mapped-shadows off); per depth once, whole frames twice in turns, 3840x2160 and
#   the pool whole.
# PART noinline: the shadow stage's walks as functions the compiler does not inline (niany: the
#   any-hit walk the light buffer falls back to; niboth: and the crossings' closest hit), per
#   depth twice in turns, whole once, and their registers.
# PART check: the tree (the walks out of line): its device tests of the shadow kernels' frames,
#   then the baseline scene per depth and whole once.
# Each PART ran on the tree of the commit its results are named by (bench/results/
# h200-2026-12-04-s12/PART_COMMIT.json): stack, frames and noinline edit render_shadow.h as
# 1ea8caf has it (their seds and patches find nothing to change at 577b6b2 and later, whose
# walks are out of line), and mapped and boxes need the mapped shadow kernels
# (bench/patches/mapped_shadows.patch, applying to 1ea8caf). Run them from a checkout of that
# commit (git worktree add DIR COMMIT); check runs on today's tree.
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
# variant_slots DIR N [SED FILE ...]: variant_tree whose light-buffer cells list N triangles
variant_slots() {
    local w=$1 n=$2; shift 2
    variant_tree "$w" "s/^#define LB_SLOTS 16\$/#define LB_SLOTS $n/" kernels/light_buffer.h \
        "s/^LB_SLOTS = 16 /LB_SLOTS = $n /" raytrace/light_buffer.py "$@"
}
nofallback='s/trace_any_masked(TRACE_ARGS, org, dir, 0.0f, tmax, opaque, TRACE_KIND_SHADOW)/false/'
# with_patch DIR NAME: bench/patches/NAME.patch applied to the copy of the tree in DIR
with_patch() { (cd "$1" && patch -p1 -s < "$OLDPWD/bench/patches/$2.patch"); }
hf_only() { with_patch "$1" shadow_crossing_hf_only; }
# mapped_4k_pool: the baseline scene at 3840x2160 and the pool, each with --mapped-shadows on
# and off
mapped_4k_pool() {
    for m in on off; do
        lb bench frame $k $static --mapped-shadows $m --out "$out/static4k_$m" | tail -1
        lb bench frame $f --mapped-shadows $m --out "$out/pool_$m" | tail -1
    done
}
case $part in
stack)
    variant_slots /tmp/s64 64
    variant_slots /tmp/s256 256
    variant_tree /tmp/hfonly && hf_only /tmp/hfonly
    variant_tree /tmp/nofallback "$nofallback" kernels/render_shadow.h
    variant_tree /tmp/nostack "$nofallback" kernels/render_shadow.h && hf_only /tmp/nostack
    variant_slots /tmp/s256nostack 256 "$nofallback" kernels/render_shadow.h \
        && hf_only /tmp/s256nostack
    g="$f $static --per-depth --no-overlap"
    lb bench frame $g --out "$out/static_pd_tree_1" | tail -1
    for v in s64 s256 hfonly nofallback nostack s256nostack; do
        in_tree /tmp/$v bench frame $g --out "$out/static_pd_$v" 2>&1 | tail -1
    done
    lb bench frame $g --out "$out/static_pd_tree_2" | tail -1
    for v in tree nostack s256nostack; do
        w=$PWD; [ $v = tree ] || w=/tmp/$v
        (cd $w && PYTHONPATH=/tmp/site:$w timeout 120 python3 bench/kernel_resources.py \
            --scene bench/scenes/pool_static_boat.toml --out "$out/resources_$v.json" | tail -1)
    done
    ;;
frames)
    # whole frames at 1920x1080, as the frame runs them (levels overlapped) and with each
    # level's shadow rays a launch of their own (--no-overlap), the tree against nostack
    variant_tree /tmp/nostack "$nofallback" kernels/render_shadow.h && hf_only /tmp/nostack
    for rep in 1 2; do
        for o in "" "--no-overlap"; do
            n=${o:+_noov}
            lb bench frame $f $static $o --out "$out/static_tree${n}_$rep" | tail -1
            in_tree /tmp/nostack bench frame $f $static $o --out "$out/static_nostack${n}_$rep" \
                | tail -1
        done
    done
    in_tree /tmp/nostack bench frame $k $static --out "$out/static4k_nostack" | tail -1
    lb bench frame $k $static --out "$out/static4k_tree" | tail -1
    ;;
mapped)
    # the tree's mapped shadow kernels against those that walk (--mapped-shadows off), after
    # their device tests
    timeout 240 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_mapped_shadows.py \
        tests/raytrace/test_light_buffer.py 2>&1 | tail -2
    for rep in 1 2; do
        for m in on off; do
            lb bench frame $f $static --per-depth --no-overlap --mapped-shadows $m \
                --out "$out/static_pd_${m}_$rep" | tail -1
            lb bench frame $f $static --mapped-shadows $m --out "$out/static_${m}_$rep" | tail -1
        done
    done
    mapped_4k_pool
    ;;
boxes)
    # the mapped kernels with each long list's triangles boxed first (the tree: cells of more
    # than LB_SLOTS) against boxing every cell's (boxall: LB_BOX_FROM 0) and the walking
    # kernels (--mapped-shadows off), after the mapped device tests
    timeout 200 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_mapped_shadows.py \
        2>&1 | grep -E "^E|passed|failed" | head -20
    variant_tree /tmp/boxall 's/^#define LB_BOX_FROM LB_SLOTS$/#define LB_BOX_FROM 0/' \
        kernels/light_buffer.h
    g="$f $static --per-depth --no-overlap"
    lb bench frame $g --out "$out/static_pd_on" | tail -1
    in_tree /tmp/boxall bench frame $g --out "$out/static_pd_boxall" | tail -1
    lb bench frame $g --mapped-shadows off --out "$out/static_pd_off" | tail -1
    for rep in 1 2; do
        lb bench frame $f $static --out "$out/static_on_$rep" | tail -1
        in_tree /tmp/boxall bench frame $f $static --out "$out/static_boxall_$rep" | tail -1
        lb bench frame $f $static --mapped-shadows off --out "$out/static_off_$rep" | tail -1
    done
    mapped_4k_pool
    ;;
noinline)
    # the walks of the shadow stage as functions of their own: the any-hit walk of the rays the
    # light buffer leaves unknown (niany: bench/patches/shadow_walk_noinline.patch) and the
    # crossings' closest hit too (niboth: shadow_walks_noinline.patch), against the tree
    for v in niany niboth; do variant_tree /tmp/$v; done
    with_patch /tmp/niany shadow_walk_noinline
    with_patch /tmp/niboth shadow_walks_noinline
    g="$f $static --per-depth --no-overlap"
    for rep in 1 2; do
        lb bench frame $g --out "$out/static_pd_tree_$rep" | tail -1
        for v in niany niboth; do
            in_tree /tmp/$v bench frame $g --out "$out/static_pd_${v}_$rep" 2>&1 | tail -1
        done
    done
    lb bench frame $f $static --out "$out/static_tree" | tail -1
    for v in niany niboth; do
        in_tree /tmp/$v bench frame $f $static --out "$out/static_$v" | tail -1
        (cd /tmp/$v && PYTHONPATH=/tmp/site:/tmp/$v timeout 100 python3 bench/kernel_resources.py \
            --scene bench/scenes/pool_static_boat.toml --out "$out/resources_$v.json" | tail -1)
    done
    ;;
check)
    # the tree's shadow walks out of line: their device tests (every shadow kernel's frames),
    # then the baseline scene per depth and whole once
    timeout 170 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_render_overlap.py \
        tests/raytrace/test_light_buffer.py -k "frames or overlap" 2>&1 | tail -1
    lb bench frame $f $static --per-depth --no-overlap --out "$out/static_pd_tree" | tail -1
    lb bench frame $f $static --out "$out/static_tree" | tail -1
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
