"""Render a scene (and its ``[[timeline]]``) to an H.264 video or a PNG sequence, deterministically.

    lbwater capture scenes/timeline.toml -o out/pool.mp4 --seconds 6 --fps 30
    lbwater capture scenes/pool.toml --frames-dir out/frames --frames 90 --width 640 --height 360

Every frame advances the water by exactly 1/fps s of simulated time, so the same scene, seed and
device give the same bytes. Frames stream to the encoder (ffmpeg from imageio-ffmpeg: H.264,
yuv420p, fragmented MP4) while the next frame renders: the device converts the frame to yuv420p
planes (kernels/video_yuv.cl), frame N+1 is enqueued before frame N is read, and a writer thread
feeds ffmpeg (x264 ``--preset``, a fixed thread count) while the loop goes on.
The video is written to ``NAME.partial.mp4`` beside the output and renamed at the end;
Ctrl-C or a crash closes the encoder properly and leaves that partial video playable, and says
where it is (stopped before its first frame, it is removed). An existing output is kept unless
``--force``; an unwritable output or a missing encoder fails before any simulation, naming the
path given. A progress bar with ETA is drawn on a terminal only; the last line sums up frames,
seconds, mean FPS and guard warnings.
"""

from __future__ import annotations

import contextlib
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from app.errors import InputError

VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov")


def add_arguments(p) -> None:
    p.add_argument("scene", help="scene TOML file (may hold [[timeline]] entries)")
    p.add_argument("-o", "--output", help="video file to write (.mp4, .mkv or .mov)")
    n = p.add_mutually_exclusive_group()
    n.add_argument("--frames", type=int, help="frames to render")
    n.add_argument("--seconds", type=float,
                   help="seconds of video (default: the timeline's end + 1 s, at least 3 s)")
    p.add_argument("--fps", type=float, default=30.0, help="frames per second (default 30)")
    p.add_argument("--width", type=int, help="image width (px, even); default from [render]")
    p.add_argument("--height", type=int, help="image height (px, even)")
    p.add_argument("--spp", type=int, help="samples per pixel")
    p.add_argument("--bounces", type=int, help="maximum reflection/refraction depth")
    p.add_argument("--seed", type=int, help="random seed (jitter, rain); default the scene's")
    p.add_argument("--device", help="OpenCL device: gpu, cpu, P:D or part of a name")
    p.add_argument("--caustics", choices=("off", "traced", "projected"),
                   help="caustics under the water (key C in the window); default from "
                        "[shading] caustics")
    p.add_argument("--frames-dir", metavar="DIR",
                   help="write a PNG sequence DIR/frame_000000.png ... (instead of or besides -o)")
    p.add_argument("--quality", type=float, default=8.0,
                   help="H.264 quality 0-10 (imageio-ffmpeg's scale: CRF (1 - q/10) * 51; "
                        "default 8, CRF 10)")
    p.add_argument("--preset", choices=PRESETS, default=PRESET,
                   help=f"x264 speed preset (default {PRESET}: keeps up with the GPU at 1080p; "
                        "slower ones make smaller files); the encoder runs a fixed "
                        f"{THREADS} threads, so the bytes do not depend on the machine")
    p.add_argument("--workers", type=int, metavar="N",
                   help="render on N Ray actors (one per GPU, else per CPU), this process "
                        "stepping the water; same bytes as without (needs lbwater[cluster])")
    p.add_argument("--ray-address", metavar="ADDR",
                   help="Ray cluster to join (HOST:PORT or auto; default: a local Ray)")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")


# ---- checks before any simulation ------------------------------------------------------------
def _check_numbers(args) -> None:
    for name, lo, hi in (("frames", 1, 10**7), ("width", 2, 16384), ("height", 2, 16384),
                         ("spp", 1, 4096), ("bounces", 0, 32), ("seed", 0, 2**32 - 1)):
        v = getattr(args, name)
        if v is not None and not lo <= v <= hi:
            raise InputError(f"--{name} {v} is out of range; allowed [{lo}, {hi}]")
    for name in ("width", "height"):
        v = getattr(args, name)
        if v is not None and v % 2:
            raise InputError(f"--{name} {v} must be even (H.264 yuv420p halves the colour planes)")
    if not (math.isfinite(args.fps) and 0.1 <= args.fps <= 1000):
        raise InputError(f"--fps {args.fps:g} is out of range; allowed [0.1, 1000]")
    if args.seconds is not None and not (math.isfinite(args.seconds) and 0 < args.seconds <= 1e5):
        raise InputError(f"--seconds {args.seconds:g} is out of range; allowed (0, 1e5]")
    if not 0 <= args.quality <= 10:
        raise InputError(f"--quality {args.quality:g} is out of range; allowed [0, 10]")


def partial_path(output: Path) -> Path:
    """Where the video grows until it is complete: ``NAME.partial.SUFFIX`` beside it."""
    return output.with_name(f"{output.stem}.partial{output.suffix}")


def check_output(output: str, force: bool) -> Path:
    """The video path, checked: suffix, no silent overwrite, folder writable (by creating the
    partial file). One InputError naming ``output`` as the user gave it."""
    path = Path(output)
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise InputError(f"-o {output!r} must end in {', '.join(VIDEO_SUFFIXES)}")
    if path.is_dir():
        raise InputError(f"-o {output!r} is a folder")
    if path.exists() and not force:
        raise InputError(f"-o {output!r} exists; use --force to overwrite it")
    part = partial_path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(part, "wb"):
            pass
    except OSError as exc:
        raise InputError(f"-o {output!r}: cannot write there ({exc.strerror or exc})") from None
    return path


def check_frames_dir(folder: str, force: bool) -> Path:
    path = Path(folder)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--frames-dir {folder!r}: cannot create it ({exc.strerror or exc})") \
            from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise InputError(f"--frames-dir {folder!r} is not writable")
    if not force and any(path.glob("frame_*.png")):
        raise InputError(f"--frames-dir {folder!r} already holds frame_*.png files; use --force")
    return path


def find_encoder() -> str:
    """The ffmpeg of imageio-ffmpeg, with H.264 (libx264); else one InputError."""
    try:
        import imageio_ffmpeg

        exe = imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as exc:
        raise InputError(f"no video encoder: imageio-ffmpeg's ffmpeg is missing ({exc}); "
                         "pip install imageio-ffmpeg, or use --frames-dir") from None
    try:
        out = subprocess.run([exe, "-hide_banner", "-encoders"], capture_output=True, text=True,
                             timeout=30).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        raise InputError(f"no video encoder: {exe} does not run ({exc})") from None
    if "libx264" not in out:
        raise InputError(f"no video encoder: {exe} has no H.264 (libx264); use --frames-dir")
    return exe


# ---- the encoder -------------------------------------------------------------------------------
#: x264 speed preset (ultrafast: ~19 ms/frame at 1920x1080 on one core; see README) and the
#: encoder's thread count: fixed, not the machine's, since x264's bytes depend on it
PRESET, THREADS = "ultrafast", 8
PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow")


def crf(quality: float) -> int:
    """H.264 CRF of a 0-10 quality (imageio-ffmpeg's scale: 10 is CRF 0, 8 is CRF 10)."""
    return int((1 - quality / 10.0) * 51)


class VideoWriter:
    """H.264 from yuv420p planes through imageio-ffmpeg's ``write_frames`` (ffmpeg in a
    subprocess that ignores SIGINT, so Ctrl-C reaches only us and :meth:`close` still finishes
    the file). Fragmented MP4: a file cut at any point plays up to its last fragment.

    :meth:`write` takes the flat Y, U, V planes (``World(image="yuv420p")``, converted on the
    device) or an RGBA8 image (converted on the host by the same integer formula,
    kernels.video_yuv: the same bytes). ffmpeg gets raw yuv420p (no swscale), BT.601 limited
    range, tagged. A writer thread feeds the pipe from a queue of ``queue_frames`` frames, so
    the frame loop renders frame N+1 while ffmpeg takes frame N; the writer is never
    interrupted by Ctrl-C (only the main thread gets SIGINT), so no frame is ever cut."""

    def __init__(self, path: Path, size: tuple[int, int], fps: float, quality: float, *,
                 preset: str = PRESET, threads: int = THREADS, queue_frames: int = 2):
        import queue
        import threading

        import imageio_ffmpeg

        from kernels.video_yuv import FFMPEG_TAGS, yuv_bytes

        self.path, self.frames, self.size = path, 0, tuple(size)
        self.frame_bytes = yuv_bytes(*self.size)
        params = ["-movflags", "frag_keyframe+empty_moov+default_base_moof",
                  "-g", str(max(1, round(fps))), "-flags", "+bitexact", "-fflags", "+bitexact",
                  "-crf", str(crf(quality)), "-preset", preset, "-threads", str(int(threads)),
                  *FFMPEG_TAGS]
        self._gen = imageio_ffmpeg.write_frames(
            str(path), size, pix_fmt_in="yuv420p", pix_fmt_out="yuv420p", fps=fps,
            quality=None, codec="libx264", macro_block_size=1, ffmpeg_log_level="error",
            output_params=params)
        self._gen.send(None)
        self._queue: queue.Queue = queue.Queue(maxsize=max(1, int(queue_frames)))
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._feed, name="lbwater-video", daemon=True)
        self._thread.start()

    def _feed(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._error is None:   # after an error, drain so the producer never blocks
                try:
                    self._gen.send(item)
                    self.frames += 1
                except BaseException as exc:  # noqa: BLE001 - handed to the frame loop
                    self._error = exc

    def _put(self, item) -> None:
        import queue

        while True:
            if self._error is not None:
                raise self._error
            try:
                self._queue.put(item, timeout=0.1)
                return
            except queue.Full:
                if not self._thread.is_alive():
                    raise RuntimeError("internal error: the video writer thread died") from None

    def write(self, image: np.ndarray) -> None:
        """Queue one frame (waits only while ``queue_frames`` frames are waiting already). The
        array must not change afterwards: World.read_frame hands out fresh copies."""
        if image.ndim == 3:
            from kernels.video_yuv import rgba_to_yuv420p

            image = rgba_to_yuv420p(image)
        if image.dtype != np.uint8 or image.size != self.frame_bytes:
            raise RuntimeError(f"internal error: a yuv420p frame of {self.size} is "
                               f"{self.frame_bytes} bytes, got {image.size} of {image.dtype}")
        self._put(np.ascontiguousarray(image))

    def close(self) -> None:
        """Write the frames still queued, then finish the file (ffmpeg flushes and exits)."""
        if self._gen is None:
            return
        try:
            if self._thread.is_alive():
                self._queue.put(None)
                self._thread.join()
        finally:
            gen, self._gen = self._gen, None
            gen.close()
        if self._error is not None:
            raise self._error


def _write_png(folder: Path, index: int, rgba: np.ndarray) -> None:
    import imageio.v3 as iio

    from app.io import atomic_path

    with atomic_path(folder / f"frame_{index:06d}.png") as tmp:
        iio.imwrite(tmp, rgba, extension=".png")


# ---- progress ----------------------------------------------------------------------------------
class Progress:
    """A one-line bar with ETA, redrawn on a terminal only (quiet when piped or --quiet)."""

    def __init__(self, total: int, enabled: bool, stream=None):
        self.total, self.stream = total, stream or sys.stderr
        self.enabled = enabled and self.stream.isatty()
        self.t0 = time.perf_counter()
        self._last = 0.0

    def update(self, done: int, note: str = "") -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and done < self.total:
            return
        self._last = now
        el = now - self.t0
        rate = done / el if el > 0 else 0.0
        eta = (self.total - done) / rate if rate > 0 else 0.0
        w = 30
        fill = int(w * done / max(self.total, 1))
        self.stream.write(f"\r[{'#' * fill}{'.' * (w - fill)}] {done}/{self.total} "
                          f"{rate:5.1f} FPS  ETA {int(eta) // 60}:{int(eta) % 60:02d} {note}  ")
        self.stream.flush()

    def finish(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


# ---- the command -------------------------------------------------------------------------------
class _Written:
    """What :func:`_stream` has written so far (kept when it stops early)."""

    def __init__(self):
        self.done, self.write_s, self.guard_notes = 0, 0.0, []


def _stream(frames, n: int, video, frames_dir, st: _Written, progress: bool) -> None:
    """Write every (i, image, guard) of ``frames`` to the video and/or PNG folder, counting in
    ``st``; when stopped (Ctrl-C, a crash), close the video (playable up to its last frame)
    and say in one line what was written and where."""
    bar = Progress(n, progress)
    try:
        for i, img, guard in frames:
            if guard.get("nan") or guard.get("acted"):
                st.guard_notes.append(f"frame {i}: {guard.get('report', 'guard acted')}")
            tw = time.perf_counter()
            if video is not None:
                video.write(img)
            if frames_dir is not None:
                _write_png(frames_dir, i, img)
            st.write_s += time.perf_counter() - tw
            st.done += 1
            bar.update(st.done, f"{len(st.guard_notes)} guard warnings" if st.guard_notes
                       else "")
    except BaseException:
        bar.finish()
        where = ""
        if video is not None:
            with contextlib.suppress(Exception):
                video.close()
            if st.done:   # without a frame the caller removes the file
                where = f"; partial video ({st.done} frames): {video.path}"
        if frames_dir is not None:
            where += f"; {st.done} PNG frames in {frames_dir}"
        print(f"lbwater capture: stopped after {st.done} of {n} frames{where}", file=sys.stderr)
        raise
    bar.finish()
def frame_count(args, timeline) -> int:
    if args.frames is not None:
        return int(args.frames)
    seconds = args.seconds if args.seconds is not None else max(timeline.duration + 1.0, 3.0)
    return max(1, round(seconds * args.fps))


def _local_frames(world, timeline, n: int, dt: float):
    """Yield (i, image, guard dict) for frames 0..n-1 of one World (the timeline's frames; the
    World may have run frames before), frame i+1 enqueued before frame i is read (it renders
    while i is encoded). The image is the World's (RGBA8 or yuv420p planes), a fresh array."""
    first = world.frames_enqueued
    timeline.apply(world, 0)
    world.enqueue_frame(dt)
    for i in range(n):
        if i + 1 < n:
            timeline.apply(world, i + 1)
            world.enqueue_frame(dt)
        index, img = world.read_frame()
        if index != first + i:
            raise RuntimeError(f"internal error: frame {index} came back for frame {first + i}")
        st = world.stats
        guard = st.guard if st is not None and st.frame == index and st.guard else {}
        yield i, img, guard   # read_frame copies it out of the pinned ring


def _cluster_frames(args, scene, timeline, n: int, dt: float, kw: dict, stack):
    """(image size, frames) for ``--workers``: this process steps the water (a World that
    renders nothing: World.snapshot_frame), Ray actors render the snapshots (app.cluster)."""
    from app import cluster, snapshot
    from app.frames import open_world

    stepper = open_world(scene, args.device, **{**kw, "width": 8, "height": 8, "spp": 1})
    stack.callback(stepper.close)

    def snapshot_of(i: int) -> bytes:
        timeline.apply(stepper, i)
        return stepper.snapshot_frame(dt)

    first = snapshot_of(0)
    # the video alone: the actors convert to yuv420p on their devices (1.5 B/px back through Ray)
    actor_kw = {**kw, "image": "yuv420p"} if args.frames_dir is None else kw
    pool = cluster.Pool(args.workers, address=args.ray_address, device=args.device,
                        capture=(str(Path(args.scene).resolve()), actor_kw, first))
    stack.callback(pool.close)
    size = tuple(pool.info[pool.live[0]]["size"])
    kept = {0: first}

    def frames():
        inner = cluster.render_frames(
            pool, n, lambda i: kept.pop(i) if i in kept else snapshot_of(i))
        try:
            for i, img, snap in inner:
                yield i, img, snapshot.peek(snap)["guard"]
        finally:
            inner.close()   # cancels the frames in flight while Ray is still up

    gen = frames()
    stack.callback(gen.close)   # before pool.close (the stack unwinds last in, first out)
    return size, gen


def run(args) -> int:
    from app.assemble import caustic_settings
    from app.frames import open_world, with_shading
    from app.scene import load_scene
    from app.timeline import Timeline

    if args.output is None and args.frames_dir is None:
        raise InputError("give -o VIDEO.mp4 and/or --frames-dir DIR")
    _check_numbers(args)
    workers = getattr(args, "workers", None)
    if workers is not None:
        from app.cluster import check_workers, import_ray

        check_workers(workers)
        import_ray()
    elif getattr(args, "ray_address", None):
        raise InputError("--ray-address needs --workers N")
    scene = load_scene(args.scene)
    scene = with_shading(scene, {"caustics": args.caustics} if args.caustics else None)
    caustic_settings(scene)  # a bad mode fails before any simulation
    timeline = Timeline(scene, args.fps)
    n = frame_count(args, timeline)
    # every check that can fail without simulating comes first
    video = None
    size = (args.width or scene.render.width, args.height or scene.render.height)
    if args.output is not None:
        if size[0] % 2 or size[1] % 2:
            raise InputError(f"{args.scene}: image {size[0]}x{size[1]} must have even sides for "
                             "H.264 yuv420p (use --width/--height)")
        find_encoder()
        out = check_output(args.output, args.force)
    frames_dir = check_frames_dir(args.frames_dir, args.force) if args.frames_dir else None

    kw = {"width": size[0], "height": size[1], "spp": args.spp, "bounces": args.bounces,
          "seed": args.seed, "caustics": args.caustics}
    dt = 1.0 / args.fps
    log = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    st = _Written()
    try:
        with contextlib.ExitStack() as stack:
            if workers is not None:
                size_got, frames = _cluster_frames(args, scene, timeline, n, dt, kw, stack)
            else:   # the video alone: yuv420p planes made on the device, 1.5 B/px read
                image = "yuv420p" if frames_dir is None else "rgba"
                world = open_world(scene, args.device, image=image, **kw)
                stack.callback(world.close)
                size_got, frames = world.size, _local_frames(world, timeline, n, dt)
            if tuple(size_got) != size:
                raise RuntimeError(f"internal error: asked {size}, the World renders {size_got}")
            if args.output is not None:
                video = VideoWriter(partial_path(out), size, args.fps, args.quality,
                                    preset=getattr(args, "preset", PRESET))
            t0 = time.perf_counter()
            _stream(frames, n, video, frames_dir, st, not args.quiet)
    except BaseException:
        if args.output is not None and st.done == 0:   # no frame: no empty partial file left
            with contextlib.suppress(OSError):
                partial_path(out).unlink()
        raise
    if video is not None:
        video.close()
        os.replace(video.path, out)
    guard_notes, write_s = st.guard_notes, st.write_s
    wall = time.perf_counter() - t0
    target = ", ".join(str(p) for p in (args.output, args.frames_dir) if p)
    guard = (f"{len(guard_notes)} guard warnings (first: {guard_notes[0]})" if guard_notes
             else "guard: ok")
    on = f" on {workers} Ray workers" if workers is not None else ""
    log(f"{target}: {n} frames {size[0]}x{size[1]} ({n / args.fps:.2f} s at {args.fps:g} fps)"
        f"{on}, {wall:.1f} s wall, mean {n / wall:.2f} FPS, encoding {1e3 * write_s / n:.1f} "
        f"ms/frame ({100 * write_s / wall:.0f}% of the wall time), {guard}")
    return 0
