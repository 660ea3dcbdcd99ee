#!/usr/bin/env bash
# The H200 runs behind BENCHMARKS.md's "NVIDIA H200, 2026-12-01 (second session)" rows: the
# window's shared display path, the frame after the read-back moved to its own queue, the host
# side was cut and the tail levels' shadow rays overlap the next trace, and the bodies stage. Usage: bench/h200_session2.sh OUTDIR
# The device machine needs the OpenCL ICD, the GL loaders and the wheels first (BENCHMARKS.md,
# "How the GPU rows were made"), and for the shared path
# VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json.
set -uo pipefail
out=${1:?OUTDIR}
mkdir -p "$out"
lb() { python3 -m app.cli "$@"; }
# correctness on this device first: the shared path, the window's GL parts, bodies, the frame
timeout 200 python3 -m pytest -q -p no:cacheprovider -rs tests/app/test_ext_share.py \
    tests/app/test_window_gl.py tests/app/test_window_bench.py tests/lbm/test_bodies_fast.py \
    tests/lbm/test_bodies.py tests/app/test_frame_pipeline.py tests/raytrace/test_render_overlap.py \
    tests/kernels 2>&1 | tail -8
python3 bench/gl_share_probe.py --sizes 1280x720 1920x1080 3840x2160 --out "$out/probe/probe.json" \
    | grep -E '_ms|exact|why' | tr -d ' '
for rep in 1 2; do
    lb bench window --sizes 1280x720 1920x1080 --out "$out/window_auto$rep" 2>&1 | tail -2
    lb bench window --sizes 1280x720 1920x1080 --upload pbo --out "$out/window_pbo$rep" 2>&1 | tail -2
done
f="--cells 1024 --size 1920 1080 --frames 40"
for rep in 1 2 3; do   # the overlapped levels (default) against the level-by-level order
    lb bench frame $f --out "$out/pool$rep" | tail -1
    lb bench frame $f --no-overlap --out "$out/pool_nooverlap$rep" | tail -1
    lb bench frame $f --scene bench/scenes/pool_static_boat.toml --out "$out/static$rep" | tail -1
done
lb bench frame $f --boats 0 --caustics off --out "$out/noboat" | tail -1
lb bench frame $f --host-copy --out "$out/pool_hostcopy" | tail -1
lb bench frame $f --per-depth --out "$out/pool_perdepth" | tail -1
for rep in 1 2; do
    lb bench frame --cells 1024 --size 3840 2160 --frames 20 --out "$out/pool4k$rep" | tail -1
    lb bench frame --cells 1024 --size 3840 2160 --frames 20 --no-overlap \
        --out "$out/pool4k_nooverlap$rep" | tail -1
done
lb bench frame --cells 1024 --size 3840 2160 --frames 20 --host-copy --out "$out/pool4k_hostcopy" \
    | tail -1
python3 bench/bodies_stage.py --cells 1024 --boats 1 16 --frames 60 --out "$out/bodies_stage" 2>&1 \
    | tail -3
lb bench frame $f --boats 16 --caustics off --out "$out/boats16" | tail -1
mkdir -p "$out/profile"
python3 bench/profile_host.py > "$out/profile/profile_host.txt" 2>&1; head -3 "$out/profile/profile_host.txt"
exit 0
