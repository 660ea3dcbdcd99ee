"""Render a scene file to a PNG with the wavefront ray tracer (one still frame).

The water of a scene with [water] is the LBM solver's surface after [pool] steps (default 30)
from still water with the scene's drops; rain is not applied to a still. Example:

    lbwater render scenes/pool.toml -o pool.png --width 1280 --height 720 --spp 4
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from app.errors import InputError


# ---- the command ----------------------------------------------------------------------------
def add_arguments(p) -> None:
    p.add_argument("scene", help="scene TOML file")
    p.add_argument("-o", "--output", required=True, help="PNG file to write")
    p.add_argument("--width", type=int, help="image width (px); default from [render]")
    p.add_argument("--height", type=int, help="image height (px)")
    p.add_argument("--spp", type=int, help="samples per pixel")
    p.add_argument("--bounces", type=int, help="maximum reflection/refraction depth")
    p.add_argument("--device", help="OpenCL device: gpu, cpu, pocl, P:D or part of a name")
    p.add_argument("--caustics", choices=("off", "traced", "projected"),
                   help="caustics under the water; default from [shading] caustics")
    p.add_argument("--aov", help="also write primary depth, normal, prim and instance ids (.npz)")


def _check_args(args) -> None:
    """Every argument and output path, before any work (one-line InputError naming it)."""
    from app.io import check_output

    check_output(args.output, "--output", (".png",))
    if args.aov is not None:
        check_output(args.aov, "--aov", (".npz",))
        if Path(args.aov).absolute() == Path(args.output).absolute():
            raise InputError(f"--aov {args.aov!r} is the same file as --output")
    for name, lo, hi in (("width", 1, 16384), ("height", 1, 16384), ("spp", 1, 4096),
                         ("bounces", 0, 32)):
        v = getattr(args, name)
        if v is not None and not lo <= v <= hi:
            raise InputError(f"--{name} {v} is out of range; allowed [{lo}, {hi}]")


def run(args) -> int:
    from app.io import atomic_path
    from app.scene import load_scene
    from app.world import World

    _check_args(args)
    scene = load_scene(args.scene)
    t0 = time.perf_counter()
    world = World(scene, args.device, width=args.width, height=args.height, spp=args.spp,
                  bounces=args.bounces, aov=args.aov is not None,
                  caustics=getattr(args, "caustics", None))
    img = world.frame()
    elapsed = time.perf_counter() - t0
    if not np.isfinite(world.read_radiance()).all():
        raise InputError(f"{args.scene}: the render produced non-finite pixels")
    import imageio.v3 as iio

    aov = world.read_aov() if args.aov is not None else None
    with atomic_path(args.output) as tmp:   # both files appear, or neither
        iio.imwrite(tmp, img, extension=".png")
        if aov is not None:
            with atomic_path(args.aov, suffix=".partial.npz") as tmp_aov:
                np.savez_compressed(tmp_aov, **aov)
    st = world.stats
    w, h = world.size
    print(f"{args.output}: {w}x{h}, {world.spp} spp, {world.bounces} bounces, "
          f"{st.n_triangles} triangles, {st.n_rays} rays, "
          f"{elapsed:.2f} s on {world.device_name}")
    return 0
