#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-02 (seventh session)" rows: the
# shadow rays' crossings of the scene's one dielectric instance (the water) walked alone
# (RenderSettings.direct_crossings) against through the TLAS walk. Usage:
#   bench/h200_session7.sh OUTDIR PART
# PART crossings: the device tests of the change, then issue 9's baseline scene per depth with
#   every level's shadow rays in launches of their own (--no-overlap), the default frame at
#   1080p and 4K, and the pool at 1080p, each with --direct-crossings on and off in turns;
#   PART shadowbase: where the shadow stage's time goes, as a diagnosis only (the images are
#   wrong): copies of the tree without the any-hit query, without the crossings, without both,
#   and with each shadow ray returning after its hit is read; PART deck: the pool's floor,
#   walls and deck as one mesh (bench/patches/pool_one_mesh.patch) against the deck as an
#   instance of its own, per depth and whole frames, in turns; PART layout: the wide BLAS layout
#   against the binary one (LBWATER_BVH_LAYOUT), per depth and whole frames.
# The device machine needs the OpenCL ICD and the wheels first (bench/h200_session3.sh says how).
set -uo pipefail
out=${1:?OUTDIR}
part=${2:?PART}
mkdir -p "$out"
source "$(dirname "$0")/h200_lib.sh"
case $part in
crossings)
    timeout 300 python3 -m pytest -q -p no:cacheprovider tests/raytrace/test_render_shadow.py \
        tests/raytrace/test_heightfield.py tests/raytrace/test_render_coop.py \
        tests/raytrace/test_render_bins.py 2>&1 | tail -3
    for rep in 1 2; do
        for dc in on off; do
            lb bench frame $f $static --per-depth --no-overlap --direct-crossings $dc \
                --out "$out/static_pd_${dc}_$rep" | tail -1
            lb bench frame $f $static --direct-crossings $dc --out "$out/static_${dc}_$rep" \
                | tail -1
            lb bench frame $f --direct-crossings $dc --out "$out/pool_${dc}_$rep" | tail -1
        done
    done
    for dc in on off; do
        lb bench frame $k $static --direct-crossings $dc --out "$out/static4k_$dc" | tail -1
    done
    ;;
shadowbase)
    # a diagnosis only (the images are wrong): copies of the tree without the any-hit query,
    # without the crossings, without both (the shading and light loop alone), and returning
    # after each hit's read (the launches and the reads alone)
    noany="s/    if (trace_any_masked(TRACE_ARGS, org, dir, 0.0f, tmax, opaque, TRACE_KIND_SHADOW))/    if (false \&\& trace_any_masked(TRACE_ARGS, org, dir, 0.0f, tmax, opaque, TRACE_KIND_SHADOW))/"
    nocross="s/    if (!prm->transmissive_shadows) return (float3)(1.0f);/    return (float3)(1.0f);/"
    bare="s/    if (h.prim < 0 || prm->n_lights == 0) return;/    if (h.prim < 0 || prm->n_lights == 0 || h.prim >= 0) return;/"
    variant_tree /tmp/noany "$noany" kernels/render_shadow.h
    variant_tree /tmp/nocross "$nocross" kernels/render_shadow.h
    variant_tree /tmp/notrace "$noany" kernels/render_shadow.h "$nocross" kernels/render_shadow.h
    variant_tree /tmp/bare "$bare" kernels/render_shadow.h
    g="$f $static --per-depth --no-overlap"
    lb bench frame $g --out "$out/static" | tail -1
    for v in noany nocross notrace bare; do
        in_tree /tmp/$v bench frame $g --out "$out/static_$v" 2>&1 | tail -1
    done
    ;;
deck)
    # the pool's floor, walls and deck as one mesh (bench/patches/pool_one_mesh.patch applied
    # to a copy of the tree) against the deck as an instance of its own (the tree), in turns
    variant_tree /tmp/deck1
    (cd /tmp/deck1 && patch -p1 -s < "$OLDPWD/bench/patches/pool_one_mesh.patch")
    (cd /tmp/deck1 && timeout 200 python3 -m pytest -q -p no:cacheprovider \
        tests/app/test_scene_render.py tests/raytrace/test_render_shadow.py 2>&1 | tail -1)
    g="$f $static --per-depth --no-overlap"
    for rep in 1 2; do
        in_tree /tmp/deck1 bench frame $g --out "$out/static_pd_onemesh_$rep" | tail -1
        lb bench frame $g --out "$out/static_pd_$rep" | tail -1
        in_tree /tmp/deck1 bench frame $f $static --out "$out/static_onemesh_$rep" | tail -1
        lb bench frame $f $static --out "$out/static_$rep" | tail -1
        in_tree /tmp/deck1 bench frame $f --out "$out/pool_onemesh_$rep" | tail -1
        lb bench frame $f --out "$out/pool_$rep" | tail -1
    done
    in_tree /tmp/deck1 bench frame $k $static --out "$out/static4k_onemesh" | tail -1
    lb bench frame $k $static --out "$out/static4k" | tail -1
    in_tree /tmp/deck1 bench frame $k --out "$out/pool4k_onemesh" | tail -1
    lb bench frame $k --out "$out/pool4k" | tail -1
    ;;
layout)
    # the wide BLAS layout (8-wide nodes, 4-triangle blocks: the CPU's) against the binary one
    # (the GPU's), now that the water is a height field and the BLAS hold only static meshes
    g="$f $static --per-depth --no-overlap"
    for lay in binary wide; do
        LBWATER_BVH_LAYOUT=$lay lb bench frame $g --out "$out/static_pd_$lay" | tail -1
        LBWATER_BVH_LAYOUT=$lay lb bench frame $f $static --out "$out/static_$lay" | tail -1
        LBWATER_BVH_LAYOUT=$lay lb bench frame $f --out "$out/pool_$lay" | tail -1
    done
    ;;
*) echo "unknown part $part"; exit 2 ;;
esac
exit 0
