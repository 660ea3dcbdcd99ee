"""The interactive window's frame rate as a user sees it: `lbwater window` run REPEATS times
(each a fresh process: its own auto-quality probe, then FRAMES frames), every run's --report
collected, and the median FPS written as JSON. Needs a display; without DISPLAY it runs each
window under `xvfb-run -a` (Xvfb and Mesa's llvmpipe, which share the CPU with the device).

    PYTHONPATH=. python bench/window_fps.py --out out/window_fps.json \\
        -- --quality auto --size 640x360 --frames 120

Arguments after ``--`` go to `lbwater window` (default: the line above, pool scene, no vsync).
Writes {"runs": [report, ...], "median_fps", "min_fps", "max_fps", "command", ...}.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT = ["--quality", "auto", "--size", "640x360", "--frames", "120"]


def window_command(window_args: list[str], report: Path) -> list[str]:
    cmd = [sys.executable, "-m", "app.cli", "window", *window_args, "--no-vsync",
           "--report", str(report)]
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        xvfb = shutil.which("xvfb-run")
        if xvfb is None:
            sys.exit("window_fps: no DISPLAY and no xvfb-run (apt-get install xvfb xauth)")
        cmd = [xvfb, "-a", "-s", "-screen 0 1920x1080x24", *cmd]
    return cmd


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    window_args = DEFAULT
    if "--" in argv:
        i = argv.index("--")
        argv, window_args = argv[:i], argv[i + 1:]
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=5, help="window runs (median of their FPS)")
    p.add_argument("--pause", type=float, default=2.0, help="seconds between runs")
    p.add_argument("--out", default="out/window_fps.json", help="JSON file to write")
    args = p.parse_args(argv)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeats):
            report = Path(tmp) / f"run{k}.json"
            cmd = window_command(window_args, report)
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
            if proc.returncode != 0 or not report.exists():
                tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
                sys.exit(f"window_fps: run {k + 1} failed ({proc.returncode}): {tail[0]}")
            runs.append(json.loads(report.read_text()))
            r = runs[-1]
            print(f"run {k + 1}/{args.repeats}: {r['fps']:.1f} FPS ({r['frame_ms']:.1f} ms a "
                  f"frame); {r['quality']}; load {r['load_average'][0]:.1f}", flush=True)
            time.sleep(args.pause)
    fps = [r["fps"] for r in runs]
    out = {"command": "lbwater window " + " ".join(window_args) + " --no-vsync",
           "date": time.strftime("%Y-%m-%d"), "device": runs[0]["device"],
           "gl_renderer": runs[0]["gl_renderer"], "cpus": os.cpu_count(),
           "median_fps": statistics.median(fps), "min_fps": min(fps), "max_fps": max(fps),
           "runs": runs}
    path = Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1) + "\n")
    print(f"median {out['median_fps']:.1f} FPS (min {out['min_fps']:.1f}, max "
          f"{out['max_fps']:.1f}) over {len(runs)} runs -> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
