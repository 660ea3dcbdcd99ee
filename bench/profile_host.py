"""Where the host's time goes in the frame loop: cProfile over pipelined frames of a scene (as
`lbwater bench frame` runs them), the top functions by own time, and the wall and kernel ms.

    PYTHONPATH=. python bench/profile_host.py --cells 1024 --size 1920 1080 --frames 60
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "pool.toml"))
    ap.add_argument("--cells", type=int, default=1024)
    ap.add_argument("--size", type=int, nargs=2, default=[1920, 1080])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--device")
    args = ap.parse_args(argv)

    from app.scene import load_scene
    from app.world import World

    world = World(load_scene(args.scene), args.device, width=args.size[0],
                  height=args.size[1], cells=args.cells)
    for _ in range(10):
        world.frame(1 / 60)
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    for i in range(args.frames):
        world.enqueue_frame(1 / 60)
        if i:
            world.read_frame(copy=False)
    world.read_frame(copy=False)
    prof.disable()
    wall = (time.perf_counter() - t0) / args.frames * 1e3
    st = world.stats
    print(f"{world.device_name}: {args.frames} frames, {wall:.2f} ms/frame wall under cProfile, "
          f"kernels {st.kernel_ms:.2f} ms, {st.lbm_steps} LBM steps")
    pstats.Stats(prof).sort_stats("tottime").print_stats(args.top)
    world.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
