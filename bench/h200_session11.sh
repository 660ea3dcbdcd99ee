#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-04 (eleventh session)" rows. Usage:
#   bench/h200_session11.sh OUTDIR PART
# PART skip: the height-field walk's span skip (HF_SKIP_SPANS) in the cooperative kernels of the
#   tail levels, which the tenth session saw slower with it: the tree (cull and skip in every
#   build) against copies whose TRACE_COOP=1 builds walk every span (coopnoskip) or cull
#   nothing either (coopwalkall). Device tests first (SKIP_TESTS=EXPR picks some of
#   test_one_crossing.py with pytest -k), then the baseline scene per depth and whole at
#   1920x1080 in turns twice, and the pool whole once each.
# PART where: where the baseline scene's shadow stage goes now, as a diagnosis only (the images
#   are wrong): copies of the tree without the opaque query (light buffer and any-hit walk),
#   without the crossings of the water, without both (the shading and the light loop alone),
#   and returning once each hit is read; per depth, the tree first and last.
# PART lb: the light buffer's query reading a cell's slots beside its record
#   (bench/patches/lb_slots_prefetch.patch: lbpre; the run in BENCHMARKS.md had it in the tree,
#   at ec8a06f) against reading them after its count (the tree), and with the shadow ray's
#   one-crossing set-up before the opaque query (bench/patches/shadow_hoist_crossing_setup.patch:
#   hoist). Device tests first
#   (test_light_buffer.py's answers and frames; the one-crossing frames), then the baseline
#   scene per depth and whole at 1920x1080 in turns twice, and the pool whole once each.
# PART fallback: a diagnosis (the images are wrong where a cell is full): the shadow kernels
#   without the any-hit walk of the BVH that the light buffer's unknown cells fall back to
#   (nofallback), against the tree, per depth in turns twice; then each one's registers and
#   spills (bench/kernel_resources.py).
# PART defer: the shadow rays whose light-buffer cell is full handed to a launch of their own
#   (bench/patches/defer_full_cells.patch, made at 976545f and reverted: RenderSettings.
#   defer_full_cells, --defer-full-cells on) against walked in place (off), both in a copy of the
#   tree with the patch: its device tests, then the baseline scene per depth and whole at
#   1920x1080 in turns twice, at 3840x2160, and the pool whole.
# PART slots: a light-buffer cell listing up to 16 triangles (LB_SLOTS 16) against 8: the
#   baseline scene per depth and whole at 1920x1080 in turns, and the pool whole. Run at
#   be8dca8, when the tree had 8 and a copy 16; the tree has 16 since 6edd337, so the copy
#   (slots16) now has 8 and the results' names are swapped.
# PART slots-pocl: the same A/B on PoCL (this machine's CPUs): the shadow rays' BVH walks
#   (bench/trace_visits.py's counters) and whole frames, small, the map of 1024 cells on.
# The patches of the lb and defer parts apply to be8dca8, not to later trees (LB_SLOTS 16, the
# light buffer's counters): run those parts from a checkout of it (git worktree add DIR be8dca8).
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
# rounds V...: the tree against the copies /tmp/V in turns: the baseline scene per depth and
# whole at 1920x1080, twice, then the pool whole once each
rounds() {
    for rep in 1 2; do
        lb bench frame $f $static --per-depth --no-overlap --out "$out/static_pd_tree_$rep" \
            | tail -1
        for v in "$@"; do
            in_tree /tmp/$v bench frame $f $static --per-depth --no-overlap \
                --out "$out/static_pd_${v}_$rep" | tail -1
        done
        lb bench frame $f $static --out "$out/static_tree_$rep" | tail -1
        for v in "$@"; do
            in_tree /tmp/$v bench frame $f $static --out "$out/static_${v}_$rep" | tail -1
        done
    done
    lb bench frame $f --out "$out/pool_tree" | tail -1
    for v in "$@"; do
        in_tree /tmp/$v bench frame $f --out "$out/pool_$v" | tail -1
    done
}
case $part in
skip)
    variant_tree /tmp/coopnoskip \
        's/^#define HF_SKIP_SPANS HF_CULL_UNREACHABLE/#define HF_SKIP_SPANS (HF_CULL_UNREACHABLE \&\& !TRACE_COOP)/' \
        kernels/traverse_heightfield.h
    variant_tree /tmp/coopwalkall \
        's/^#define HF_CULL_UNREACHABLE 1/#define HF_CULL_UNREACHABLE (!TRACE_COOP)/' \
        kernels/traverse_heightfield.h
    timeout 300 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_one_crossing.py \
        -k "${SKIP_TESTS:-not nothing}" 2>&1 | tail -3
    rounds coopnoskip coopwalkall
    ;;
where)
    # the call's second line (trace_stats);) is left as a statement of its own: (void)(...)
    noany='s/^    const int mapped = light_buffer_blocked(LIGHT_BUFFER_ARGS, instances, light, org, dir, tmax,$/    const int mapped = LB_CLEAR; (void)(/'
    nocross='s/^    if (!prm->transmissive_shadows) return (float3)(1.0f);/    return (float3)(1.0f);/'
    bare='s/^    if (h.prim < 0 || prm->n_lights == 0) return false;/    if (h.prim < 0 || prm->n_lights == 0 || h.prim >= 0) return false;/'
    variant_tree /tmp/noany "$noany" kernels/render_shadow.h
    variant_tree /tmp/nocross "$nocross" kernels/render_shadow.h
    variant_tree /tmp/notrace "$noany" kernels/render_shadow.h "$nocross" kernels/render_shadow.h
    variant_tree /tmp/bare "$bare" kernels/render_shadow.h
    g="$f $static --per-depth --no-overlap"
    lb bench frame $g --out "$out/static_tree_1" | tail -1
    for v in noany nocross notrace bare; do
        in_tree /tmp/$v bench frame $g --out "$out/static_$v" 2>&1 | tail -1
    done
    lb bench frame $g --out "$out/static_tree_2" | tail -1
    ;;
lb)
    variant_tree /tmp/lbpre
    (cd /tmp/lbpre && patch -p1 -s < "$OLDPWD/bench/patches/lb_slots_prefetch.patch")
    variant_tree /tmp/hoist
    (cd /tmp/hoist && patch -p1 -s < "$OLDPWD/bench/patches/shadow_hoist_crossing_setup.patch")
    (cd /tmp/lbpre && timeout 300 python3 -m pytest -q -p no:cacheprovider \
        tests/raytrace/test_light_buffer.py -k "answers or frames_are" 2>&1 | tail -1)
    (cd /tmp/hoist && timeout 200 python3 -m pytest -q -p no:cacheprovider \
        tests/raytrace/test_one_crossing.py -k "frames" 2>&1 | tail -1)
    rounds lbpre hoist
    ;;
fallback)
    variant_tree /tmp/nofallback \
        's/trace_any_masked(TRACE_ARGS, org, dir, 0.0f, tmax, opaque, TRACE_KIND_SHADOW)/false/' \
        kernels/render_shadow.h
    g="$f $static --per-depth --no-overlap"
    for rep in 1 2; do
        lb bench frame $g --out "$out/static_pd_tree_$rep" | tail -1
        in_tree /tmp/nofallback bench frame $g --out "$out/static_pd_nofallback_$rep" | tail -1
    done
    timeout 170 python3 bench/kernel_resources.py --scene $(echo $static | cut -d' ' -f2) \
        --out "$out/resources_tree.json" | tail -1
    (cd /tmp/nofallback && PYTHONPATH=/tmp/site:/tmp/nofallback timeout 170 python3 \
        bench/kernel_resources.py --scene bench/scenes/pool_static_boat.toml \
        --out "$out/resources_nofallback.json" | tail -1)
    ;;
defer)
    variant_tree /tmp/defer
    (cd /tmp/defer && patch -p1 -s < "$OLDPWD/bench/patches/defer_full_cells.patch")
    (cd /tmp/defer && timeout 200 python3 -m pytest -q -p no:cacheprovider \
        tests/raytrace/test_light_buffer.py -k "deferred" 2>&1 | tail -1)
    for rep in 1 2; do
        for d in on off; do
            in_tree /tmp/defer bench frame $f $static --per-depth --no-overlap \
                --defer-full-cells $d --out "$out/static_pd_defer${d}_$rep" | tail -1
        done
        for d in on off; do
            in_tree /tmp/defer bench frame $f $static --defer-full-cells $d \
                --out "$out/static_defer${d}_$rep" | tail -1
        done
    done
    for d in on off; do
        in_tree /tmp/defer bench frame $k $static --defer-full-cells $d \
            --out "$out/static4k_defer$d" | tail -1
    done
    for d in on off; do
        in_tree /tmp/defer bench frame $f --defer-full-cells $d --out "$out/pool_defer$d" | tail -1
    done
    ;;
slots)
    variant_tree /tmp/slots16 's/^#define LB_SLOTS 16$/#define LB_SLOTS 8/' kernels/light_buffer.h \
        's/^LB_SLOTS = 16 /LB_SLOTS = 8  /' raytrace/light_buffer.py
    g="$f $static --per-depth --no-overlap"
    lb bench frame $g --out "$out/static_pd_slots8" | tail -1
    in_tree /tmp/slots16 bench frame $g --out "$out/static_pd_slots16" | tail -1
    lb bench frame $f $static --out "$out/static_slots8" | tail -1
    in_tree /tmp/slots16 bench frame $f $static --out "$out/static_slots16" | tail -1
    lb bench frame $f --out "$out/pool_slots8" | tail -1
    in_tree /tmp/slots16 bench frame $f --out "$out/pool_slots16" | tail -1
    ;;
slots-pocl)
    variant_tree /tmp/slots8 's/^#define LB_SLOTS 16$/#define LB_SLOTS 8/' kernels/light_buffer.h \
        's/^LB_SLOTS = 16 /LB_SLOTS = 8  /' raytrace/light_buffer.py
    visits="--scene bench/scenes/pool_static_boat.toml --boat floating --caustics off --cells 256
            --size 480 270 --settle 0.3 --light-buffer 1024"
    python3 bench/trace_visits.py $visits --json "$out/trace_visits_slots16.json" | grep shadow
    (cd /tmp/slots8 && PYTHONPATH=/tmp/slots8 python3 bench/trace_visits.py $visits \
        --json "$out/trace_visits_slots8.json" | grep shadow)
    small="--cells 128 --size 480 270 --frames 6 --light-buffer 1024"
    for rep in 1 2; do
        lb bench frame $small $static --out "$out/pocl_static_slots16_$rep" | tail -1
        in_tree /tmp/slots8 bench frame $small $static --out "$out/pocl_static_slots8_$rep" \
            | tail -1
    done
    ;;
*)
    echo "unknown PART $part" >&2
    exit 2
    ;;
esac
