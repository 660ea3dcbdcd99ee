"""Window display-path benchmark, with no display: a headless EGL context
(moderngl.create_standalone_context(backend="egl")) stands in for the window's.

Per image size: the bare frame (World.frame: water, BVH, render, RGBA8 read-back; what
`bench frame` times), the window's loop (two frames in flight: enqueue the next, take the oldest
on the window's display path, draw the quad into a framebuffer of that size, glFinish), and the
upload + draw alone. ``--upload auto`` (as the window) takes the shared path where the device
offers it (app.ext_share: the frame copied on the device into memory GL reads, no read-back),
else the copy path (the oldest read into its pinned buffer without a copy, uploaded to a
texture through pixel buffers). The goal (issue 11): the window's loop
<= 1.1x the bare frame. Every size is checked in the same run: the drawn framebuffer must equal
the frame's image exactly, else the run fails. Each row names the GL renderer: where EGL lists
several devices (a GPU and Mesa's llvmpipe), ``GLCONTEXT_DEVICE_INDEX=N`` picks another one.

``--quality auto|low|medium|high``: each size is a window's; the quality is chosen as `lbwater
window` chooses it (auto: its probe drawn with the HUD into the window-size framebuffer) and the
image, at the chosen scale, is drawn stretched to the window with the HUD over it, as the window
does. The row adds the choice, its predicted frame time and the loop's FPS.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"


def add_arguments(p) -> None:
    p.add_argument("--scene", default=str(SCENES_DIR / "pool.toml"), help="scene TOML file")
    p.add_argument("--sizes", nargs="+", default=["1280x720", "1920x1080"],
                   help="image sizes WxH")
    p.add_argument("--cells", type=int, help="water cells along the pool's longer side "
                                             "(default: the scene's)")
    p.add_argument("--frames", type=int, default=30, help="timed frames (median)")
    p.add_argument("--warmup", type=int, default=5, help="untimed frames first")
    p.add_argument("--frame-time", type=float, default=1 / 60,
                   help="simulated seconds of water per frame")
    p.add_argument("--upload", choices=("auto", "shared", "pbo", "direct"), default="auto",
                   help="display path, as the window's --upload (default auto: shared where "
                        "available, else pbo)")
    p.add_argument("--quality", choices=("auto", "low", "medium", "high"),
                   help="sizes are windows' and the window's quality choice sets the image "
                        "(default: the image is the size, at the scene's settings)")
    p.add_argument("--target-fps", type=float, default=60.0,
                   help="frame rate --quality auto aims for")


def _egl_context():
    import moderngl

    from app.errors import LbwaterError

    try:
        return moderngl.create_standalone_context(backend="egl")
    except Exception as exc:
        raise LbwaterError(f"bench window: no EGL context ({str(exc).splitlines()[0]}); "
                           "install the GPU driver's or Mesa's libEGL") from None


def _median_ms(xs) -> float:
    return statistics.median(xs) * 1e3


def run(args) -> int:
    from app.hud import Hud
    from app.io import write_csv, write_json
    from app.quality import scaled_size
    from app.scene import load_scene
    from app.window import Presenter, attach_display, caustic_scene, make_world, parse_size
    from kernels import get_runtime

    sizes = [parse_size(s, "--sizes") for s in args.sizes]
    scene = load_scene(args.scene)
    rt = get_runtime(args.device)
    ctx = _egl_context()
    presenter = Presenter(ctx, "direct" if args.upload == "direct" else "pbo")
    hud = Hud(ctx) if args.quality else None
    rows = []
    ft = args.frame_time
    for size in sizes:
        quality, wscene, (w, h) = None, scene, size   # (w, h): the image's size
        spp, bounces, cells = scene.render.spp, scene.render.bounces, args.cells
        if args.quality:   # size is the window's; a framebuffer of it stands in for it
            window = ctx.simple_framebuffer(size, components=4)
            quality = _quality(args, scene, rt, size, ctx, window, presenter, hud)
            wscene = caustic_scene(scene, quality.photons)
            w, h = scaled_size(size, quality.scale)
            spp, bounces, cells = 1, quality.bounces, quality.cells
        world = make_world(wscene, rt, size=(w, h), spp=spp, bounces=bounces, cells=cells,
                           caustics=quality.caustics if quality else None)
        fbo = ctx.simple_framebuffer((w, h), components=4)
        fbo.use()
        for _ in range(args.warmup):
            world.frame(ft)
        bare = []
        for _ in range(args.frames):
            t0 = time.perf_counter()
            world.frame(ft)
            bare.append(time.perf_counter() - t0)
        # the window's loop: two frames in flight, on the window's display path
        targets, path = attach_display(world, ctx, args.upload)
        world.enqueue_frame(ft)
        loop, upload = [], []
        for k in range(args.warmup + args.frames):
            t0 = time.perf_counter()
            world.enqueue_frame(ft)
            _, img = world.read_frame(copy=False)   # as the window: uploaded before reuse
            t1 = time.perf_counter()
            presenter.upload(img)
            if quality is None:
                presenter.draw((w, h))
            else:   # stretched to the window, the HUD over it (text renewed as it is there)
                window.use()
                presenter.draw(window.size)
                hud.draw([(_hud_text(world, quality, k // 15), 8, 8)], window.size)
            ctx.finish()
            t2 = time.perf_counter()
            if k >= args.warmup:
                loop.append(t2 - t0)
                upload.append(t2 - t1)
        _, img = world.read_frame()
        presenter.upload(img)
        if targets is not None:   # the shared frame's bytes, read back here to compare
            img = world.renderer.read_rgba()
        shown = presenter.snapshot((w, h))
        fbo.use()
        if not np.array_equal(shown, img):
            bad = np.mean(np.any(shown != img, axis=2))
            raise RuntimeError(f"bench window: {w}x{h}: the drawn frame differs from the image "
                               f"on {bad:.1%} of pixels")
        if quality is not None:
            window.release()
        # the row's numbers are the stored (rounded) ones, and the ratio is of those
        bare_ms, loop_ms = round(_median_ms(bare), 3), round(_median_ms(loop), 3)
        cells = getattr(world.stats, "water_cells", None)
        row = {"device": world.device_name, "gl_renderer": ctx.info["GL_RENDERER"],
               "date": time.strftime("%Y-%m-%d"), "width": w, "height": h,
               "cells": f"{cells[0]}x{cells[1]}" if cells else "",
               "upload": "shared" if targets is not None else args.upload,
               "display_path": path,
               "bare_frame_ms": bare_ms, "window_frame_ms": loop_ms,
               "ratio": round(loop_ms / bare_ms, 3),
               "upload_draw_ms": round(_median_ms(upload), 3),
               "window_fps": round(1e3 / loop_ms, 1)}
        if quality is not None:
            row.update(window=f"{size[0]}x{size[1]}",
                       quality=quality.describe(), source=quality.source,
                       scale=quality.scale, bounces=quality.bounces,
                       caustics=world.caustics, photons=quality.photons,
                       target_fps=args.target_fps,
                       predicted_ms=None if quality.predicted_ms is None
                       else round(quality.predicted_ms, 3))
            print(f"window {row['window']}: {quality.describe()}", flush=True)
        rows.append(row)
        print(f"{w}x{h}: bare frame {bare_ms:.2f} ms, window loop {loop_ms:.2f} ms "
              f"({row['ratio']:.2f}x), upload+draw {row['upload_draw_ms']:.2f} ms "
              f"[{row['gl_renderer']}; {row['upload']}]", flush=True)
        fbo.release()
        world.close()
        if targets is not None:
            presenter.reset()
            targets.release()
    out = Path(args.out)
    write_json(out / "bench_window.json", rows)
    write_csv(out / "bench_window.csv", rows)
    return 0


def _quality(args, scene, rt, window_size, ctx, window, presenter, hud):
    """The window's quality choice (app.window.decide_quality), its probe frames drawn into
    ``window`` (a framebuffer of the window's size) with the HUD, as the window draws them."""
    import argparse

    from app.window import decide_quality

    def present(world, img):
        presenter.upload(img)
        window.use()
        window.clear(0.0, 0.0, 0.0, 1.0)
        presenter.draw(window.size)
        hud.draw([(_hud_text(world, None, 0), 8, 8)], window.size)
        ctx.finish()

    wargs = argparse.Namespace(quality=args.quality, target_fps=args.target_fps,
                               cells=args.cells, scale=None, bounces=None, spp=None,
                               caustics=None)
    return decide_quality(wargs, scene, rt, window_size, args.frame_time, present=present)


def _hud_text(world, quality, tick: int) -> list[str]:
    """The window's HUD lines for ``world`` (its text changes with ``tick``, as the FPS does)."""
    from app.hud import hud_lines
    from app.window import caustics_label

    return hud_lines(world.stats, fps=float(tick), path="copy", size=tuple(world.size),
                     device=world.device_name,
                     quality=quality.describe() if quality else "quality auto: measuring ...",
                     bounces=world.bounces, caustics=caustics_label(world.scene, world))
