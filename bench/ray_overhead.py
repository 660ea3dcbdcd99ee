"""What Ray costs a capture: ``lbwater capture`` plain against ``--workers N`` (a local Ray started
by the command), each run in a fresh process, median of ``--runs``. Reports the whole command's
wall time and the frame loop's (the summary line's "s wall": from the first frame to the last,
Ray and the actors already up), and fails when a run's video differs from the plain one's.

    python bench/ray_overhead.py --scene scenes/timeline.toml --frames 24 --size 256x144 \\
        --workers 1,2 --runs 3
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_once(scene: str, frames: int, size: str, workers: int | None, out: Path,
             device: str | None) -> tuple[float, float]:
    w, h = size.split("x")
    cmd = [sys.executable, "-m", "app.cli", "capture", scene, "-o", str(out), "--force",
           "--frames", str(frames), "--width", w, "--height", h, "--seed", "1"]
    if workers:
        cmd += ["--workers", str(workers)]
    if device:
        cmd += ["--device", device]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p))
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    total = time.perf_counter() - t0
    if p.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}): {p.stderr.strip()[-500:]}")
    m = re.search(r"([0-9.]+) s wall", p.stderr)
    if not m:
        raise SystemExit(f"no summary line in: {p.stderr.strip()[-300:]}")
    return total, float(m.group(1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "timeline.toml"))
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--size", default="256x144")
    ap.add_argument("--workers", default="1", help="comma-separated worker counts")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--device", help="OpenCL device for every process (default: the default)")
    args = ap.parse_args(argv)
    configs = [None] + [int(x) for x in args.workers.split(",")]
    results: dict = {c: [] for c in configs}
    with tempfile.TemporaryDirectory() as tmp:
        ref = None
        for _ in range(args.runs):
            for c in configs:
                out = Path(tmp) / f"w{c or 0}.mp4"
                results[c].append(run_once(args.scene, args.frames, args.size, c, out,
                                           args.device))
                data = out.read_bytes()
                ref = ref or (data if c is None else None)
                if ref is not None and data != ref:
                    raise SystemExit(f"--workers {c}: the video differs from the plain capture")
    print(f"{args.frames} frames {args.size} of {Path(args.scene).name}, median of {args.runs} "
          f"runs ({time.strftime('%Y-%m-%d')}); videos byte-identical to the plain capture")
    print("| run | command wall (s) | frame loop (s) | frames/s in the loop |")
    print("|---|---|---|---|")
    for c in configs:
        tot = statistics.median(r[0] for r in results[c])
        loop = statistics.median(r[1] for r in results[c])
        name = "plain" if c is None else f"--workers {c}"
        print(f"| {name} | {tot:.1f} | {loop:.1f} | {args.frames / loop:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
