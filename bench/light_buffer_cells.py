"""How full a scene's light-buffer cells are: the cells that list more than N triangles for N of
8 to 256 (a cell keeps ``LB_SLOTS`` of them; a ray in a fuller one walks the BVH), the
triangles past those counts, and the fullest cell's triangles (instances, median area). Runs
anywhere (PoCL included: the map is built as on a GPU).

    PYTHONPATH=$PWD python bench/light_buffer_cells.py --light-buffer 1024 2048 4096
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
COUNTS = (8, 16, 32, 64, 128, 256)


def measure(scene: str, cells: int, light_buffer: int, size) -> dict:
    """Light 0's map of ``scene`` after one frame."""
    from app.world import World

    w = World(scene, width=size[0], height=size[1], cells=cells, light_buffer=light_buffer)
    w.frame(0.0)
    lb = w.renderer.light_buffer
    got = lb.read(0)
    count = got["count"]
    j, i = np.unravel_index(int(np.argmax(count)), count.shape)
    tris = lb.rt.to_host(lb.tris_buf, np.float32, 12 * lb.n_tris).reshape(-1, 3, 4)
    inst = tris[:, 0, 3].copy().view(np.int32)
    # the fullest cell's triangles: its slots hold LB_SLOTS of them; the rest are found by
    # testing every triangle's footprint against the cell as the raster did (float64 boxes)
    m = lb.maps[0]
    world = lb._world_vertices(w.render_scene.scene, tris.reshape(-1, 4))
    world = world.reshape(-1, 3, 3)
    cu = world @ m["u"][:3].astype(np.float64) + m["u"][3]
    cv = world @ m["v"][:3].astype(np.float64) + m["v"][3]
    g = float(m["margin"])
    near = ((cu.min(1) - g <= i + 1) & (cu.max(1) + g >= i)
            & (cv.min(1) - g <= j + 1) & (cv.max(1) + g >= j))
    p = tris[near, :, :3].astype(np.float64)
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1) / 2
    ids, per = np.unique(inst[near], return_counts=True)
    return {"scene": scene, "light_buffer": light_buffer,
            "map": [int(x) for x in count.shape], "cells_listing": int((count > 0).sum()),
            "pairs": int(count.sum()), "most": int(count.max()),
            "over": {str(n): int((count > n).sum()) for n in COUNTS},
            "past": {str(n): int(np.maximum(count - n, 0).sum()) for n in COUNTS},
            "fullest_cell_boxes": {"triangles": int(near.sum()),
                                   "instances": {int(a): int(b) for a, b in zip(ids, per,
                                                                                strict=True)},
                                   "median_object_area": float(np.median(area))}}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=str(ROOT / "bench" / "scenes" / "pool_static_boat.toml"))
    p.add_argument("--cells", type=int, default=128, help="water cells along the longer side")
    p.add_argument("--size", type=int, nargs=2, default=[160, 90])
    p.add_argument("--light-buffer", type=int, nargs="+", default=[1024], metavar="CELLS")
    p.add_argument("--json", help="write the numbers here")
    args = p.parse_args(argv)
    rows = []
    for lb in args.light_buffer:
        r = measure(args.scene, args.cells, lb, args.size)
        rows.append(r)
        print(f"{lb} cells: map {r['map']}, {r['cells_listing']} cells list {r['pairs']} "
              f"triangles, the fullest {r['most']}")
        print("  cells over N:   " + "  ".join(f"{n}: {r['over'][str(n)]}" for n in COUNTS))
        print("  triangles past: " + "  ".join(f"{n}: {r['past'][str(n)]}" for n in COUNTS))
        f = r["fullest_cell_boxes"]
        print(f"  fullest cell: {f['triangles']} triangles whose boxes meet it, by instance "
              f"{f['instances']}, median area {f['median_object_area']:.3g} (object units)")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
