"""What the rays of a frame's deeper levels are: per depth level, how many rays travel in water
or air, what they hit (instance name), how far, how steep, and with what weight; read back from
the renderer's wavefront buffers after a frame (the last two levels, which the ping-pong buffers
still hold: so each pair of levels from its own World with that many bounces, the levels before
the deepest being the same whatever the bounces). Used to find out why the pool's tail levels
cost ~0.2 ms each on the H200.

    PYTHONPATH=$PWD python3 bench/tail_rays.py [--scene S] [--cells N] [--size W H] [--out F]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def describe(rays: np.ndarray, hits: np.ndarray, names: dict) -> dict:
    """Counts and quantiles of one level's rays and hits."""
    dy = rays["dy"]
    w = np.maximum(np.maximum(rays["wr"], rays["wg"]), rays["wb"])
    hit_names = np.array([names.get(int(i), "miss" if i < 0 else f"inst{i}")
                          for i in hits["inst"]])
    kinds = {}
    for medium in ("water", "air"):
        sel = (rays["medium"] >= 0) == (medium == "water")
        for name in sorted(set(hit_names[sel])):
            m = sel & (hit_names == name)
            t = hits["t"][m]
            kinds[f"{medium}->{name}"] = {
                "rays": int(m.sum()),
                "t_median": float(np.median(t)) if np.isfinite(t).any() else None,
                "abs_dy_median": float(np.median(np.abs(dy[m]))),
                "abs_dy_below_0.1": int((np.abs(dy[m]) < 0.1).sum()),
                "weight_median": float(np.median(w[m]))}
    return {"rays": int(len(rays)), "in_water": int((rays["medium"] >= 0).sum()),
            "kinds": kinds}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=str(ROOT / "scenes" / "pool.toml"))
    p.add_argument("--cells", type=int, default=1024)
    p.add_argument("--size", type=int, nargs=2, default=[1920, 1080])
    p.add_argument("--frames", type=int, default=8, help="frames of 1/60 s before the read")
    p.add_argument("--out", default=None, help="JSON file")
    a = p.parse_args()

    from app.io import write_json
    from app.scene import load_scene
    from app.world import World
    from raytrace.bvh import HIT_DTYPE
    from raytrace.render_types import RAY

    scene = load_scene(a.scene)
    out = {"scene": a.scene, "levels": {}}
    for bounces in range(1, scene.render.bounces + 1, 2):
        world = World(scene, width=a.size[0], height=a.size[1], cells=a.cells,
                      bounces=bounces)
        for _ in range(a.frames):
            world.frame(1 / 60)
        r, rt = world.renderer, world.rt
        counts = r.read_stats()["rays_per_depth"]
        out.update(device=rt.name, rays_per_depth=counts)
        for d in (bounces - 1, bounces):   # the ping-pong buffers hold the last two levels
            n = int(counts[d])
            if n:
                rays = rt.to_host(r.rays[d % 2], RAY, n)
                hits = rt.to_host(r.hits[d % 2], HIT_DTYPE, n)
                out["levels"][d] = describe(rays, hits, world.instances)
    print(json.dumps(out, indent=1))
    if a.out:
        write_json(a.out, out)   # atomic: a temporary file, then a rename
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
