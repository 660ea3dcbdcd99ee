"""Caustic noise against photons per frame: CSV + PNG.

    python bench/caustics_noise.py -o out/caustics_noise [--scene scenes/pool.toml]
        [--photons 4096,16384,65536,262144] [--reference 2097152] [--cells 100] [--device D]

On the scene's water after a few drops have spread (LBM steps, then held still), for each photon
count: the caustic map of the pool floor (the scene's filter; no temporal blend) against a
high-photon reference of the same water (relative RMS error over the floor), the frame-to-frame
flicker of still water (relative RMS difference of two consecutive frames' maps: only the
per-frame jitter differs), the flicker with the scene's temporal blend after it has settled,
and the device time of the caustics stage. The chart is log-log: Monte Carlo noise falls as
photons^-1/2 until texel quantisation remains.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def rel_rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2)))


def floor_map(world, frame: int) -> np.ndarray:
    c = world._caustics
    c.enqueue(frame)
    return c.read_map()["floor"][..., 0].astype(np.float64)


def study(scene_path: str, photons: list[int], reference: int, cells: int, device,
          settle: int) -> list[dict]:
    from app.scene import load_scene
    from app.world import World

    base = load_scene(scene_path)
    sh = base.shading

    def world_with(n: int, blend: float | None = None):
        spec = dataclasses.replace(base, shading=dataclasses.replace(
            sh, caustics="traced", caustic_photons=int(n),
            caustic_blend=sh.caustic_blend if blend is None else blend))
        w = World(spec, device, width=16, height=16, cells=cells, water_steps=200,
                  caustics="traced")
        w.frame(0.0)   # the water as after 200 steps; held still from here
        return w

    ref_world = world_with(reference, blend=0.0)
    ref = floor_map(ref_world, 10_000)
    rows = []
    for n in photons:
        w = world_with(n, blend=0.0)
        c = w._caustics
        a = floor_map(w, 1)
        b = floor_map(w, 2)
        rt = w.rt
        rt.finish()
        t0 = time.perf_counter()
        for f in range(3, 6):
            c.enqueue(f)
        rt.finish()
        host_ms = (time.perf_counter() - t0) / 3 * 1e3
        wb = world_with(n)   # the scene's blend
        cb = wb._caustics
        for f in range(settle):
            cb.enqueue(f)
        m1 = cb.read_map()["floor"][..., 0].astype(np.float64)
        cb.enqueue(settle)
        m2 = cb.read_map()["floor"][..., 0].astype(np.float64)
        texels = c.nx * c.nz
        rows.append({
            "photons": n, "photons_per_floor_texel": round(n / texels, 3),
            "error_vs_reference": round(rel_rms(a, ref), 5),
            "flicker": round(rel_rms(b, a), 5),
            "flicker_blended": round(rel_rms(m2, m1), 5),
            "blend": cb.settings.blend, "filter": c.settings.filter,
            "ms_per_frame_host": round(host_ms, 2), "device": w.device_name,
            "texels": f"{c.nx}x{c.nz}", "reference_photons": reference})
        print(rows[-1], flush=True)
    return rows


def chart(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from app.io import atomic_path

    n = np.array([r["photons"] for r in rows], float)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.loglog(n, [r["error_vs_reference"] for r in rows], "o-", label="error vs reference")
    ax.loglog(n, [r["flicker"] for r in rows], "s-", label="frame-to-frame flicker, no blend")
    ax.loglog(n, [r["flicker_blended"] for r in rows], "^-",
              label=f"flicker, blend {rows[0]['blend']}")
    k = rows[0]["flicker"] * math.sqrt(n[0])
    ax.loglog(n, k / np.sqrt(n), "k:", label="photons$^{-1/2}$")
    ax.set_xlabel("photons per frame")
    ax.set_ylabel("relative RMS over the pool floor")
    ax.set_title(f"caustic noise ({rows[0]['texels']} floor texels, filter {rows[0]['filter']})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-o", "--output", required=True, help="folder for CSV and PNG")
    p.add_argument("--scene", default="scenes/pool.toml")
    p.add_argument("--photons", default="4096,16384,65536,262144")
    p.add_argument("--reference", type=int, default=2_097_152)
    p.add_argument("--cells", type=int, default=100, help="water cells along the longer side")
    p.add_argument("--settle", type=int, default=8, help="frames before the blended flicker")
    p.add_argument("--device")
    a = p.parse_args(argv)
    from app.io import atomic_path

    photons = [int(x) for x in a.photons.split(",")]
    rows = study(a.scene, photons, a.reference, a.cells, a.device, a.settle)
    out = Path(a.output)
    with atomic_path(out / "caustics_noise.csv") as tmp, open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    chart(rows, out / "caustics_noise.png")
    print(f"{out / 'caustics_noise.csv'}, {out / 'caustics_noise.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
