"""Probe the window's display paths in a headless EGL context: the shared path (app.ext_share:
external memory that OpenCL writes and GL reads, no host copy) against the copy path (pinned
read-back, then the pixel-buffer upload), per frame, at the given sizes. Each frame is a known
random RGBA8 image in an OpenCL buffer, sent to a texture and drawn; the drawn pixels are
compared with it byte for byte.

    python bench/gl_share_probe.py [--device gpu] [--sizes 1920x1080 3840x2160] [--out F.json]

Prints one JSON object (also written to --out): whether the device offers cl_khr_gl_sharing,
why the shared path is unavailable (or null), and per size the median host ms per frame of each
path (enqueue, wait, upload, draw and glFinish) and whether its drawn pixels were exact.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def _timed(frames: int, one_frame) -> float:
    """Median ms of ``one_frame()`` over ``frames`` calls after 5 untimed ones."""
    walls = []
    for i in range(frames + 5):
        t0 = time.perf_counter()
        one_frame()
        if i >= 5:
            walls.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(walls)


def main(argv=None) -> int:
    import moderngl
    import pyopencl as cl

    from app.ext_share import ExternalShareError, ExternalTargets
    from app.window import Presenter, parse_size
    from kernels.device import select_device
    from kernels.pinned import PinnedRing
    from kernels.runtime import Runtime

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None)
    ap.add_argument("--sizes", nargs="+", default=["1920x1080"])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    gl = moderngl.create_standalone_context(backend="egl")
    rt = Runtime(select_device(args.device))
    report = {"device": rt.device.name.strip(), "gl_renderer": gl.info["GL_RENDERER"],
              "date": time.strftime("%Y-%m-%d"),
              "cl_khr_gl_sharing": "cl_khr_gl_sharing" in rt.device.extensions.split(),
              "shared_why_not": None, "sizes": {}}
    presenter = Presenter(gl, "pbo")
    for text in args.sizes:
        w, h = parse_size(text)
        fbo = gl.simple_framebuffer((w, h), components=4)
        fbo.use()
        frame = np.random.default_rng(7).integers(0, 256, (h, w, 4), dtype=np.uint8)
        buf = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR,
                        hostbuf=frame)

        def drawn_exact(fbo=fbo, frame=frame, w=w, h=h) -> bool:
            got = np.frombuffer(fbo.read(components=4, alignment=1), np.uint8).reshape(h, w, 4)
            return bool(np.array_equal(got[::-1, :, :3], frame[:, :, :3]))

        def show(img, w=w, h=h):
            presenter.upload(img)
            presenter.draw((w, h))
            gl.finish()

        ring = PinnedRing(rt, w * h * 4, np.uint8, (h, w, 4))
        row = {"copy_ms": _timed(args.frames,
                                 lambda ring=ring, buf=buf: show(ring.enqueue_read(
                                     rt.queue, buf).wait()))}
        row["copy_exact"] = drawn_exact()
        try:
            targets = ExternalTargets(gl, rt, (w, h))
        except ExternalShareError as exc:
            report["shared_why_not"] = str(exc)
        else:
            row["shared_ms"] = _timed(args.frames, lambda t=targets, buf=buf: show(
                t.enqueue(rt.queue, buf).wait()))
            row["shared_exact"] = drawn_exact()
            row["shared_release_gl_errors"] = targets.release()
        presenter.reset()
        fbo.release()
        report["sizes"][text] = row
    print(json.dumps(report, indent=1))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
