"""Traversal work per ray kind on a scene: rays, BVH node visits and triangle tests per ray of the
renderer's primary, secondary and shadow rays (the any-hit query of opaque blockers, then the
crossings of dielectrics where the scene has some) and the caustics' photons, from the counters
of a TRACE_COUNT build (kernels/traverse.h). Runs anywhere (PoCL included: counts, not times);
the binary BVH layout (the GPU's) by default.

    PYTHONPATH=$PWD python bench/trace_visits.py                  # pool.toml, every variant
    PYTHONPATH=$PWD python bench/trace_visits.py --boat floating --caustics off --size 640 360

Boat variants of the scene's first [[boats]]: ``floating`` (as the scene has it, after
``--settle`` seconds of water), ``static`` (a static [[meshes]] entry at the same start pose),
``static-old`` (a static mesh at ``--old-y``, the pre-floating scene's keel height), ``none``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
KINDS = ("primary", "secondary", "shadow", "crossing", "photon")


def scene_variant(scene, boat: str, old_y: float):
    """``scene`` with its first boat floating (as given), static (a mesh), or removed."""
    from app.scene import MeshSpec

    if boat == "floating" or not scene.boats:
        return scene
    if boat == "none":
        return dataclasses.replace(scene, boats=())
    b = scene.boats[0]
    pos = tuple(b.position)
    if boat == "static-old":
        pos = (pos[0], old_y, pos[2])
    mesh = MeshSpec(file=b.file, material=b.material, materials=b.materials, position=pos,
                    rotation=tuple(b.rotation), size=b.size, smooth=b.smooth)
    return dataclasses.replace(scene, boats=scene.boats[1:], meshes=(*scene.meshes, mesh))


def measure(rt, scene, *, cells, size, caustics, settle, frames=1, light_buffer=0,
            one_crossing=True) -> dict:
    """Counters of ``frames`` frames after ``settle`` seconds of water, per ray kind (a shadow
    ray that the light buffer answers, or whose crossings one crossing leaves out, walks
    nothing and is not counted)."""
    from app.world import World

    world = World(scene, rt, width=size[0], height=size[1], cells=cells, caustics=caustics,
                  light_buffer=light_buffer)
    world.renderer.set_one_crossing(one_crossing)
    if settle > 0:
        world.frame(settle)
    sc = world.render_scene.scene
    sc.reset_trace_counts()
    for _ in range(frames):
        world.frame(0.0)
    counts = sc.trace_counts()
    hf = sc.heightfield.read()
    out = {"rays_per_depth": world.renderer.read_stats()["rays_per_depth"],
           "water_slope_bound": float(hf["slope"]) if sc.heightfield.mesh is not None else None,
           "water_walks": counts["heightfield"], "light_buffer": counts["light_buffer"],
           "instances": {int(k): v for k, v in world.instances.items()}, "raw": counts}
    for kind in KINDS:
        c = counts[kind]
        rays = max(c["rays"], 1)
        out[kind] = {"rays": c["rays"] // frames, "traversals": c["traversals"] / rays,
                     "tlas_nodes": c["tlas_nodes"] / rays,
                     "blas_entries": c["blas_entries"] / rays,
                     "blas_nodes": c["blas_nodes"] / rays, "tri_tests": c["tri_tests"] / rays,
                     "hit_rate": c["hits"] / max(c["traversals"], 1),
                     "blas_nodes_by_instance": [x / rays for x in c["blas_nodes_by_instance"]],
                     "total_nodes": c["tlas_nodes"] + c["blas_nodes"]}
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=str(ROOT / "scenes" / "pool.toml"))
    p.add_argument("--cells", type=int, default=256, help="water cells along the longer side")
    p.add_argument("--size", type=int, nargs=2, default=[320, 180])
    p.add_argument("--boat", nargs="+", default=["floating", "static", "static-old", "none"],
                   choices=["floating", "static", "static-old", "none"])
    p.add_argument("--caustics", nargs="+", default=["traced", "off"], choices=["traced", "off"])
    p.add_argument("--settle", type=float, default=0.5, help="seconds of water before counting")
    p.add_argument("--old-y", type=float, default=0.44, help="static-old keel height (m)")
    p.add_argument("--layout", default="binary", choices=["binary", "wide"])
    p.add_argument("--light-buffer", type=int, default=0, metavar="CELLS",
                   help="each directional light's map of what blocks it (RenderSettings."
                        "light_buffer): the shadow rays it answers walk nothing; default 0: none")
    p.add_argument("--one-crossing", choices=("on", "off"), default="on",
                   help="leave out the crossing walks that can find nothing (RenderSettings."
                        "one_crossing), or walk them; default on")
    p.add_argument("--json", help="write the numbers here")
    args = p.parse_args(argv)

    from app.scene import load_scene
    from kernels.runtime import Runtime

    rt = Runtime(None, bvh_layout=args.layout, defines={"TRACE_COUNT": 1})
    base = load_scene(args.scene)
    results = []
    print(f"{args.scene}: {args.cells} cells, {args.size[0]}x{args.size[1]}, {args.layout} BVH "
          f"on {rt.name}; per ray: traversals, TLAS nodes, BLAS entries, BLAS nodes, triangle "
          "tests; BLAS nodes per instance", flush=True)
    for boat in args.boat:
        for caustics in args.caustics:
            scene = scene_variant(base, boat, args.old_y)
            r = measure(rt, scene, cells=args.cells, size=args.size, caustics=caustics,
                        settle=args.settle, light_buffer=args.light_buffer,
                        one_crossing=args.one_crossing == "on")
            r.update(boat=boat, caustics=caustics)
            results.append(r)
            print(f"-- boat {boat}, caustics {caustics}: rays per depth {r['rays_per_depth']}; "
                  f"instances {r['instances']}; the water's slope bound "
                  f"{r['water_slope_bound']}, its walks culled whole "
                  f"{r['water_walks']['culled']}, spans skipped "
                  f"{r['water_walks']['skipped_spans']}; the light buffer's answers "
                  f"{r['light_buffer']}")
            for kind in KINDS:
                k = r[kind]
                if not k["rays"]:
                    continue
                inst = " ".join(f"{x:.1f}" for x in k["blas_nodes_by_instance"])
                print(f"  {kind:9s} {k['rays']:8d} rays  trav {k['traversals']:.2f}  "
                      f"tlas {k['tlas_nodes']:5.1f}  entries {k['blas_entries']:4.2f}  "
                      f"blas {k['blas_nodes']:6.1f}  tris {k['tri_tests']:6.1f}  "
                      f"hit {k['hit_rate']:.2f}  nodes {k['total_nodes']:9d}  [{inst}]",
                      flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
