"""Capture-overhead benchmark: in one process and on one World, the bare frame loop (what
``bench frame`` times: frames in flight, the next enqueued before the last image is read) against
the real capture path (``lbwater capture``'s: the timeline's inputs, the yuv420p planes made on
the device, frame N+1 enqueued before frame N is read and queued to the H.264 encoder's writer
thread; with ``--png`` RGBA read back, converted on the host, and a PNG per frame too), each as
wall ms per frame over ``--frames`` frames, warm-up excluded, median of ``--repeats`` runs taken
alternately (bare, capture, bare, ...). A capture run is timed from its first frame to the
encoder's file closed (the encoder started beforehand); its video is checked to decode with
every frame. The goal (issue 12): capture <= 1.15x the bare frame at 1920x1080 on the H200.

    lbwater bench capture --size 1920 1080 --frames 120 --out out/bench_capture
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

from app.capture import PRESET, PRESETS

SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"
GOAL = 1.15


def add_arguments(p) -> None:
    p.add_argument("--scene", default=str(SCENES_DIR / "pool.toml"), help="scene TOML file")
    p.add_argument("--cells", type=int,
                   help="water cells along the pool's longer side (default: the scene's)")
    p.add_argument("--size", type=int, nargs=2, default=[1920, 1080], metavar=("W", "H"),
                   help="image size (even sides; default 1920 1080)")
    p.add_argument("--frames", type=int, default=120,
                   help="timed frames per run (default 120: the flush of the encoder's last "
                        "frames, counted, weighs little)")
    p.add_argument("--warmup", type=int, default=5, help="untimed frames first (default 5)")
    p.add_argument("--repeats", type=int, default=3, help="runs of each (median; default 3)")
    p.add_argument("--fps", type=float, default=30.0,
                   help="video frame rate: 1/fps s of water per frame, both loops (default 30)")
    p.add_argument("--quality", type=float, default=8.0, help="H.264 quality 0-10 (default 8)")
    p.add_argument("--preset", choices=PRESETS, default=PRESET,
                   help=f"x264 speed preset (default {PRESET}, as capture's)")
    p.add_argument("--png", action="store_true",
                   help="also write every captured frame as a PNG (capture --frames-dir)")
    p.add_argument("--caustics", choices=("off", "traced"),
                   help="caustics mode (default: the scene's [shading] caustics)")


def _check(args) -> None:
    from app.errors import InputError

    w, h = args.size
    if not (2 <= w <= 16384 and 2 <= h <= 16384) or w % 2 or h % 2:
        raise InputError(f"--size {w} {h}: sides must be even and in [2, 16384]")
    for name, lo, hi in (("frames", 2, 10**6), ("warmup", 0, 10**6), ("repeats", 1, 100)):
        v = getattr(args, name)
        if not lo <= v <= hi:
            raise InputError(f"--{name} {v} is out of range; allowed [{lo}, {hi}]")
    if not 0.1 <= args.fps <= 1000:
        raise InputError(f"--fps {args.fps:g} is out of range; allowed [0.1, 1000]")
    if not 0 <= args.quality <= 10:
        raise InputError(f"--quality {args.quality:g} is out of range; allowed [0, 10]")


def _bare(world, n: int, dt: float) -> float:
    """s per frame of ``n`` frames with the next enqueued before the last image is read."""
    t0 = time.perf_counter()
    for i in range(n):
        world.enqueue_frame(dt)
        if i >= 1:
            world.read_frame()
    world.read_frame()
    return (time.perf_counter() - t0) / n


def _capture(world, timeline, n: int, dt: float, video_path: Path, size, args, png_dir):
    """(s per frame, s per frame in the writers) of ``n`` frames through capture's path."""
    from app import capture

    video = capture.VideoWriter(video_path, size, args.fps, args.quality,
                                preset=args.preset)   # not timed
    st = capture._Written()
    t0 = time.perf_counter()
    try:
        capture._stream(capture._local_frames(world, timeline, n, dt), n, video, png_dir, st,
                        progress=False)
    finally:
        video.close()
    wall = time.perf_counter() - t0
    return wall / n, st.write_s / n


def run(args) -> int:
    import imageio_ffmpeg

    from app.capture import find_encoder
    from app.errors import InputError
    from app.frames import open_world
    from app.io import write_csv, write_json
    from app.scene import load_scene
    from app.timeline import Timeline

    _check(args)
    scene = load_scene(args.scene)
    if scene.water is None:
        raise InputError(f"{args.scene}: bench capture needs a scene with [water]")
    timeline = Timeline(scene, args.fps)
    find_encoder()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    video_path = out / "bench_capture.mp4"
    png_dir = None
    if args.png:
        png_dir = out / "bench_capture_frames"
        png_dir.mkdir(parents=True, exist_ok=True)
    size = tuple(args.size)
    dt = 1.0 / args.fps
    with open_world(scene, args.device, width=size[0], height=size[1], cells=args.cells,
                    caustics=args.caustics) as world:
        for _ in range(args.warmup):
            world.frame(dt)
        bare, cap, write = [], [], []
        for _ in range(args.repeats):   # alternately, so drift hits both alike
            world.set_image("rgba")        # bench frame's loop: the RGBA8 image read back
            bare.append(_bare(world, args.frames, dt))
            world.set_image("rgba" if args.png else "yuv420p")   # as capture reads
            c, w = _capture(world, timeline, args.frames, dt, video_path, size, args, png_dir)
            cap.append(c)
            write.append(w)
        st = world.stats
        device = world.device_name
    n_video, _ = imageio_ffmpeg.count_frames_and_secs(str(video_path))
    if n_video != args.frames:
        raise RuntimeError(f"bench capture: {video_path} holds {n_video} frames, "
                           f"{args.frames} were written")
    # the stored (rounded) times, and every derived column from them, so a row is consistent
    frame_ms = round(statistics.median(bare) * 1e3, 3)
    capture_ms = round(statistics.median(cap) * 1e3, 3)
    ratio = capture_ms / frame_ms
    nx, ny = st.water_cells
    row = {"device": device, "date": time.strftime("%Y-%m-%d"),
           "scene": Path(args.scene).name, "cells": f"{nx}x{ny}", "width": size[0],
           "height": size[1], "frames": args.frames, "repeats": args.repeats, "fps": args.fps,
           "quality": args.quality, "png": bool(args.png), "caustics": world.caustics,
           "frame_ms": frame_ms, "capture_ms": capture_ms,
           "ratio": round(ratio, 4), "overhead_pct": round(100 * (ratio - 1), 2),
           "write_ms": round(statistics.median(write) * 1e3, 3),
           "frame_fps": round(1e3 / frame_ms, 1), "capture_fps": round(1e3 / capture_ms, 1),
           "goal_ratio": GOAL, "meets_goal": ratio <= GOAL,
           "video": str(video_path), "video_frames": int(n_video),
           "video_bytes": video_path.stat().st_size}
    write_json(out / "bench_capture.json", [row])
    write_csv(out / "bench_capture.csv", [row])
    print(f"{device}: {size[0]}x{size[1]}, {row['cells']} cells, {args.frames} frames: bare "
          f"{frame_ms:.2f} ms/frame ({row['frame_fps']} FPS), capture {capture_ms:.2f} ms/frame "
          f"({row['capture_fps']} FPS), overhead {row['overhead_pct']:+.1f}% (writers "
          f"{row['write_ms']:.2f} ms/frame); goal <= {100 * (GOAL - 1):.0f}%: "
          f"{'met' if row['meets_goal'] else 'not met'}", flush=True)
    return 0
