"""Host-side cost of each part of the window's display path, per frame, without a World:
the RGBA8 image read (non-blocking, into kernels.pinned.PinnedRing) from a device buffer,
``World.read_frame``'s view or copy of it, ``Presenter.upload`` (pbo, direct), the quad's draw,
and glFinish, in a headless EGL context. With Mesa's llvmpipe (a CPU GL) only the host copies
and conversions compare with a GPU's; the upload's DMA and the draw do not.

    PYTHONPATH=. python bench/window_host_parts.py --size 1920x1080 --frames 40

Prints one line per part: the median ms (and writes JSON with --out FILE).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--out")
    args = ap.parse_args(argv)
    import moderngl
    import pyopencl as cl

    from app.window import Presenter, parse_size
    from kernels import get_runtime
    from kernels.pinned import PinnedRing

    w, h = parse_size(args.size)
    rt = get_runtime(None)
    ctx = moderngl.create_standalone_context(backend="egl")
    fbo = ctx.simple_framebuffer((w, h), components=4)
    fbo.use()
    src = np.random.default_rng(1).integers(0, 256, (h, w, 4), np.uint8)
    dev = cl.Buffer(rt.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=src)
    ring = PinnedRing(rt, src.nbytes, np.uint8, (h, w, 4), slots=2)
    parts: dict[str, list[float]] = {}

    def timed(name, fn):
        t0 = time.perf_counter()
        out = fn()
        parts.setdefault(name, []).append(time.perf_counter() - t0)
        return out

    presenters = {m: Presenter(ctx, m) for m in ("pbo", "direct")}
    for k in range(args.frames + 3):
        img = timed("read (wait)", lambda: ring.enqueue_read(rt.queue, dev).wait())
        timed("copy (read_frame copy=True)", img.copy)
        for mode, p in presenters.items():
            timed(f"upload {mode}", lambda p=p, img=img: p.upload(img))
            timed(f"draw {mode}", lambda p=p: p.draw((w, h)))
            timed(f"finish {mode}", ctx.finish)
        if k < 3:
            parts.clear()
    rows = {name: round(statistics.median(xs) * 1e3, 3) for name, xs in parts.items()}
    print(f"{w}x{h} [{ctx.info['GL_RENDERER']}], median ms of {args.frames} frames:")
    for name, ms in rows.items():
        print(f"  {name:28s} {ms:8.3f}")
    if args.out:
        Path(args.out).write_text(json.dumps({"size": [w, h], "renderer": ctx.info["GL_RENDERER"],
                                              "ms": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
