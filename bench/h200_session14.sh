#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-04 (fourteenth session)" rows.
# Usage: bench/h200_session14.sh OUTDIR PART
# PART list: the shadow list (RenderSettings.shadow_list: every level's shadow rays written by
#   the shading to one list, traced in one launch after the last level) against the per-level
#   shadow launches, on the baseline scene at 1920x1080 per depth (--per-depth; off: with
#   --no-overlap, so that each level's shadow rays have a stage of their own) and whole, in
#   turns twice; at 3840x2160 whole; and the pool (its boat floats) whole.
# PART fallback: what the shadow list's shading pays for tracing a ray that finds no room itself
#   (out of line), on the baseline scene per depth at 1920x1080: the tree against a copy whose
#   shading leaves that walk out (nofb: an overflowing list would lose rays; none overflows
#   here), in turns twice, and the per-level stage beside them; then the tree whole at 1920x1080
#   and 3840x2160 with the list on and off.
# PART finish: what the tonemap pass pays for taking each pixel's shadow-list light: copies of
#   the tree with no fallback walk (as nofb) whose tonemap pass reads the light without zeroing
#   it (noclear: the light adds up frame after frame, a wrong image) or never reads it (notake:
#   no shadowed light at all), per depth at 1920x1080 against nofb, in turns twice.
# PART tests: the device tests of the shadow list and of the renderer's shadow stages.
# Each part ran on the tree of the commit its results are named by (bench/results/
# h200-2026-12-04-s14/PART_COMMIT.json): list at 96e8ae1, ae73871, 42869e7, 159f305 and f0f43f2;
# fallback at 3e7b93e; finish at fac209a (fallback and finish need a tree from before ae73871:
# their seds edit the walk that the shading held then); tests beside each list call.
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
case $part in
list)
    for rep in 1 2; do
        for l in on off; do
            o=""
            [ $l = off ] && o="--no-overlap"
            lb bench frame $f $static --per-depth $o --shadow-list $l \
                --out "$out/static_pd_list${l}_$rep" | tail -1
            lb bench frame $f $static --shadow-list $l --out "$out/static_list${l}_$rep" | tail -1
        done
    done
    list_4k_and_pool "$out"
    ;;
fallback)
    variant_tree /tmp/nofb 's/if (in_full || slot < lp.main_room) {/if (1) {/' \
        kernels/render_shadow_list.cl
    for rep in 1 2; do
        lb bench frame $f $static --per-depth --shadow-list on --out "$out/pd_list_$rep" | tail -1
        in_tree /tmp/nofb bench frame $f $static --per-depth --shadow-list on \
            --out "$out/pd_nofb_$rep" | tail -1
    done
    lb bench frame $f $static --per-depth --no-overlap --shadow-list off \
        --out "$out/pd_off" | tail -1
    for l in on off; do
        lb bench frame $f $static --shadow-list $l --out "$out/static_list$l" | tail -1
        lb bench frame $k $static --shadow-list $l --out "$out/static4k_list$l" | tail -1
    done
    ;;
finish)
    nofb='s/if (in_full || slot < lp.main_room) {/if (1) {/'
    variant_tree /tmp/nofb "$nofb" kernels/render_shadow_list.cl
    variant_tree /tmp/noclear "$nofb" kernels/render_shadow_list.cl \
        's/    light\[q\] = (ulong4)(0ul);//' kernels/render_shadow_list.h
    variant_tree /tmp/notake "$nofb" kernels/render_shadow_list.cl \
        's/const bool listed = gp.finish == GATHER_FINISH_SHADOW_LIST;/const bool listed = false;/' \
        kernels/render_frame.cl
    for rep in 1 2; do
        for v in nofb noclear notake; do
            in_tree /tmp/$v bench frame $f $static --per-depth --shadow-list on \
                --out "$out/pd_${v}_$rep" | tail -1
        done
    done
    ;;
tests)
    python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_shadow_list.py \
        tests/raytrace/test_render_shadow.py tests/raytrace/test_light_buffer.py 2>&1 | tail -5
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
