#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-05 (fifteenth session)" rows.
# Usage: bench/h200_session15.sh OUTDIR PART
# PART steps: the shadow list's steps of this session, on the baseline scene per depth at
#   1920x1080 with the list on, in turns twice: the fourteenth session's last tree (41e2ffd),
#   32-byte list entries (2af2740), render_raygen zeroing the pixels' light instead of a fill (the
#   tree), and copies of the tree whose spill launches take at most 8192 or 2048 work-items
#   (SPILL_WORK_ITEMS), and copies whose shading lists every ray in the main part with no
#   order (noclass: no full part, no crossings first) or with no crossings first (nocross), the
#   same images in another order; then the tree with the list off (--no-overlap: a stage per level's shadow
#   rays) beside them. The older trees are `git archive COMMIT app kernels lbm raytrace` in
#   $TREES/COMMIT (default .trees, carried to the device), run beside today's bench and scenes.
# PART final: the tree whole at 1920x1080 with the list on and off in turns twice, at 3840x2160
#   and the pool (its boat floats), on and off.
# PART whole: the whole frame at 1920x1080 in turns three times: 41e2ffd with the list on, the
#   tree with the list on and off; then 41e2ffd at 3840x2160 with the list on, the tree at
#   3840x2160 and the pool on and off; then per depth, in turns twice, 41e2ffd and the tree with
#   the list on, and the tree with the list off (--no-overlap). The steps and final parts'
#   figures again, on whichever card the device machine lends (an H100 or an H200).
# PART tests: the device tests of the shadow list, the shadow stages and the raygen layout.
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
trees=${TREES:-$PWD/.trees}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
# commit_tree DIR: the archived tree in DIR, with today's bench and scenes beside it
commit_tree() { ln -sfn "$PWD/bench" "$1/bench"; ln -sfn "$PWD/scenes" "$1/scenes"; }
# per_depth_list_off OUT: the tree per depth with per-level shadow launches (--no-overlap)
per_depth_list_off() {
    lb bench frame $f $static --per-depth --no-overlap --shadow-list off --out "$1/pd_off" |
        tail -1
}
case $part in
steps)
    for c in 41e2ffd 2af2740; do commit_tree "$trees/$c"; done
    variant_tree /tmp/spill8k 's/^SPILL_WORK_ITEMS = LAUNCH_FLOOR/SPILL_WORK_ITEMS = 8192/' \
        raytrace/render.py
    variant_tree /tmp/spill2k 's/^SPILL_WORK_ITEMS = LAUNCH_FLOOR/SPILL_WORK_ITEMS = 2048/' \
        raytrace/render.py
    variant_tree /tmp/noclass '/light_buffer_full(LIGHT_BUFFER_ARGS, l, o.org) ? LIST_FULL/d' \
        kernels/render_shadow_list.cl \
        's/: o.medium >= 0 ? LIST_CROSSING : LIST_OTHER;/: LIST_OTHER;/' \
        kernels/render_shadow_list.cl
    variant_tree /tmp/nocross 's/: o.medium >= 0 ? LIST_CROSSING : LIST_OTHER;/: LIST_OTHER;/' \
        kernels/render_shadow_list.cl
    for rep in 1 2; do
        for c in 41e2ffd 2af2740; do
            in_tree "$trees/$c" bench frame $f $static --per-depth --shadow-list on \
                --out "$out/pd_$c-$rep" | tail -1
        done
        lb bench frame $f $static --per-depth --shadow-list on --out "$out/pd_tree-$rep" | tail -1
        for v in spill8k spill2k noclass nocross; do
            in_tree /tmp/$v bench frame $f $static --per-depth --shadow-list on \
                --out "$out/pd_$v-$rep" | tail -1
        done
    done
    per_depth_list_off "$out"
    ;;
final)
    for rep in 1 2; do
        for l in on off; do
            lb bench frame $f $static --shadow-list $l --out "$out/static_list${l}_$rep" | tail -1
        done
    done
    list_4k_and_pool "$out"
    ;;
whole)
    commit_tree "$trees/41e2ffd"
    for rep in 1 2 3; do
        in_tree "$trees/41e2ffd" bench frame $f $static --shadow-list on \
            --out "$out/whole_41e2ffd_$rep" | tail -1
        for l in on off; do
            lb bench frame $f $static --shadow-list $l --out "$out/whole_list${l}_$rep" | tail -1
        done
    done
    in_tree "$trees/41e2ffd" bench frame $k $static --shadow-list on --out "$out/whole4k_41e2ffd" |
        tail -1
    list_4k_and_pool "$out"
    for rep in 1 2; do
        in_tree "$trees/41e2ffd" bench frame $f $static --per-depth --shadow-list on \
            --out "$out/pd_41e2ffd-$rep" | tail -1
        lb bench frame $f $static --per-depth --shadow-list on --out "$out/pd_tree-$rep" | tail -1
    done
    per_depth_list_off "$out"
    ;;
tests)
    python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_shadow_list.py \
        tests/raytrace/test_render_shadow.py tests/raytrace/test_render_layout.py 2>&1 | tail -5
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
