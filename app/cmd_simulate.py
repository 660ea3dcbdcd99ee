"""Run a scene's water (the LBM solver) without rendering and save the fields.

    lbwater simulate scenes/pool.toml --steps 2000 --save out/pool_water.npz

The .npz holds h, u, v, bed (ny, nx float32 arrays: depth m, velocity m/s along x and y, bed m),
x (nx,) and y (ny,) cell-centre coordinates in m, time (s), dt (s), steps, and the guard's last
report; with ``[[boats]]`` also boat_position (boats x 3, the centre of mass in world m),
boat_rotation (boats x 4, quaternion w, x, y, z) and boat_names (the boats float on the water,
coupled both ways, lbm.bodies). Written atomically: on any error no file is left behind.

``--vtk DIR --every K`` also writes the surface every K steps (and at the start and the end) as a
ParaView time series ``DIR/water.pvd`` of structured grids with h, u, v, bed, and with
``[[boats]]`` the boats' meshes placed by their poses at the same steps as ``DIR/boats.pvd``
(app.vtk_output).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from app.errors import InputError
from app.io import atomic_path


def _steps(text: str) -> int:
    import argparse

    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--steps {text!r} is not an integer") from None
    if not 1 <= n <= 10**9:
        raise argparse.ArgumentTypeError(f"--steps {n} is out of range; allowed [1, 1e9]")
    return n


def add_arguments(p) -> None:
    p.add_argument("scene", help="scene file (TOML) with a [water] section")
    p.add_argument("--steps", type=_steps, default=1000, help="LBM time steps (default 1000)")
    p.add_argument("--save", help="output .npz file")
    p.add_argument("--vtk", metavar="DIR", help="also write DIR/water.pvd (ParaView time series)")
    p.add_argument("--every", type=_steps, default=100, metavar="K",
                   help="with --vtk: steps between written surfaces (default 100)")
    p.add_argument("--device", help="OpenCL device: gpu, cpu, pocl, P:D or part of a name")
    p.add_argument("--chunk", type=_steps, default=500,
                   help="steps per guard report and progress line (default 500)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.add_argument("--strict", action="store_true",
                   help="fail (exit 2) when the guard acted: the water left the valid regime "
                        "(subcritical, wet) and was limited or restored")


def run(args) -> int:
    import lbm
    from app.io import check_output
    from app.scene import load_scene
    from kernels import get_runtime

    if args.save is None and args.vtk is None:
        raise InputError("give --save FILE.npz and/or --vtk DIR")
    if args.save is not None:
        check_output(args.save, "--save", (".npz",))
    vtk = None
    if args.vtk is not None:
        from app.vtk_output import PvdWriter

        vtk = PvdWriter(args.vtk)   # an unwritable folder fails here, before any simulation
    scene = load_scene(args.scene)
    if scene.water is None:
        raise InputError(f"{scene.path}: the scene has no [water] section to simulate")
    rt = get_runtime(args.device)
    try:
        sim = lbm.from_water_spec(scene.water, device=rt)
    except ValueError as exc:
        raise InputError(f"{scene.path}: [water]: {exc}") from None
    log = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    boats = None
    if scene.boats:
        from app.boats import boat_bodies, make_boats

        bodies = boat_bodies(scene)
        boats = make_boats(scene, sim, bodies, rt.buffer(48 * len(bodies)),
                           list(range(len(bodies))))
    log(f"{scene.name}: {sim.nx}x{sim.ny} cells of {sim.dx:g} m on {rt.name}; "
        f"e = {sim.e:.4g} m/s, dt = {sim.dt:.4g} s, tau = {sim.tau:.4g}")
    t0, done, stages, reports = time.perf_counter(), 0, {}, []
    acted = {"cells": 0, "restored": 0, "froude": 0.0}

    vtk_boats = None
    if vtk is not None and boats is not None:
        from app.vtk_output import PvdWriter, boats_polydata

        vtk_boats = PvdWriter(args.vtk, "boats")
        boat_meshes = [(b.vertices, b.faces) for b in bodies]

    def write_vtk():
        vtk.write(done, sim.time, sim.fields(), sim.dx, scene.water.origin)
        if vtk_boats is not None:
            vtk_boats.write_dataset(done, sim.time, boats_polydata(
                boat_meshes, boats.mesh_transforms()), "vtp")

    if vtk is not None:
        write_vtk()
    while done < args.steps:
        n = min(args.chunk, args.steps - done)
        if vtk is not None:
            n = min(n, args.every - done % args.every)
        sim.step(n)
        done += n
        s = sim.stats()   # waits for this chunk: the only host read per chunk
        for k, ms in rt.timer.collect().items():
            stages[k] = stages.get(k, 0.0) + ms
        if s["report"] != "ok":
            reports.append(f"t={s['time']:.4g}s: {s['report']}")
            log(reports[-1])
        if s["acted"]:
            acted["cells"] += s["cells_limited"]
            acted["restored"] += s["restored"]
            acted["froude"] = max(acted["froude"], s["max_froude"])
        if s["acted"] and args.strict:
            raise InputError(f"{scene.path}: --strict: the guard acted at t = {s['time']:.4g} s "
                             f"({s['report']})")
        if vtk is not None and (done % args.every == 0 or done == args.steps):
            write_vtk()
        log(f"step {done}/{args.steps}  t = {s['time']:.4g} s  volume = {s['mass']:.6g} m^3  "
            f"max |u|/e = {s['max_speed_ratio']:.3g}  max Fr = {s['max_froude']:.3g}")
    wall = time.perf_counter() - t0
    if acted["cells"] or acted["restored"]:
        print(f"lbwater simulate: warning: the guard acted: limited {acted['cells']} cell updates"
              f", restored {acted['restored']} checkpoints, max Froude seen "
              f"{acted['froude']:.3g}; volume clipped {s['volume_clipped']:.3g} m^3, created "
              f"{s['volume_created']:.3g} m^3 (docs/lbm.md: the valid regime)", file=sys.stderr)
    f = sim.fields()
    x = (np.arange(sim.nx) + 0.5) * sim.dx
    y = (np.arange(sim.ny) + 0.5) * sim.dx
    if vtk is not None:
        also = f" and {vtk_boats.pvd_path}" if vtk_boats is not None else ""
        log(f"wrote {vtk.pvd_path}{also} ({len(vtk.entries)} steps)")
    if args.save is None:
        return 0
    extra = {}
    if boats is not None:
        pos, quat = boats.poses()
        extra = dict(boat_position=pos, boat_rotation=quat, boat_names=np.array(boats.names))
    with atomic_path(args.save) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, h=f["h"], u=f["u"], v=f["v"], bed=f["bed"], x=x, y=y,
                            time=np.float64(sim.time), dt=np.float64(sim.dt),
                            steps=np.int64(sim.steps), guard="\n".join(reports) or "ok",
                            **extra)
    mlups = sim.nx * sim.ny * args.steps / max(stages.get("lbm.step", 0.0), 1e-9) / 1e3
    log(f"saved {args.save}: t = {sim.time:.6g} s after {sim.steps} steps in {wall:.2f} s; "
        f"lbm.step {stages.get('lbm.step', 0.0):.1f} ms ({mlups:.1f} MLUPs/s), "
        f"guard {stages.get('lbm.guard', 0.0):.1f} ms")
    return 0
