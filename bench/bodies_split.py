"""Where the bodies update's time goes: the update kernel with parts of it removed, timed as
``bench/bodies_stage.py`` times it (the pool's water at ``--cells``, 1 and 16 boats). Variants:
``cur`` (as built), ``old`` (``--old FILE``: another lbm_bodies.cl, e.g. ``git show
REV:kernels/lbm_bodies.cl``), ``nopress`` (no pressure pass), ``nocols`` (no footprint
samples), ``noboth``. The variants are written beside the kernels as ``kernels/_split_*.cl``
for the run and removed after. A diagnostic (the physics of a variant is wrong); writes
DIR/bodies_split.json.

    python3 bench/bodies_split.py --old /tmp/lbm_bodies_old.cl --out DIR
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

PRESS = "    const int4 box = lbm_press_cells(l_body[b].box, l_body[b].box_old);"
AFTER = "/* zforce = bed + the hulls' pressure head on every cell."
COLUMNS = "for (int k = lid; k < n_s; k += LBM_BODY_WG)"


def variants(src: str, old: str | None) -> dict:
    """Kernel sources by variant name (the update's press or footprint loop cut out)."""
    def no_press(s):
        return s[:s.index(PRESS)] + "}\n" + s[s.index(AFTER):]

    no_cols = src.replace(COLUMNS, COLUMNS.replace("k < n_s", "k < 0"))
    out = {"cur": src, "nopress": no_press(src), "nocols": no_cols, "noboth": no_press(no_cols)}
    if old is not None:
        out["old"] = old
    return out


def main(argv=None) -> int:
    import bodies_stage

    import kernels.runtime as kr
    from app.scene import load_scene
    from kernels import get_runtime

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cells", type=int, default=1024)
    p.add_argument("--frames", type=int, default=40)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--old", help="another lbm_bodies.cl to time as the variant 'old'")
    p.add_argument("--device", default=None)
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    src = (kr.KERNEL_DIR / "lbm_bodies.cl").read_text()
    old = Path(args.old).read_text() if args.old else None
    files = {}
    for name, text in variants(src, old).items():
        files[name] = kr.KERNEL_DIR / f"_split_{name}.cl"
        files[name].write_text(text)
    launcher = kr.Runtime.kernel_launcher
    current = {"name": "cur"}

    def patched(self, source, name, **kw):
        if source == "lbm_bodies.cl":
            source = files[current["name"]].name
        return launcher(self, source, name, **kw)

    kr.Runtime.kernel_launcher = patched
    rows = []
    try:
        rt = get_runtime(args.device)
        scene = load_scene(str(ROOT / "scenes" / "pool.toml"))
        for rep in range(args.repeats):
            for name in files:
                current["name"] = name
                for n in (1, 16):
                    row = bodies_stage.measure(rt, scene, args.cells, n, args.frames, 10, False)
                    row.update(variant=name, rep=rep)
                    rows.append(row)
                    print(f"{name:8s} run {rep}: {n:2d} boats {row['bodies_ms']:.4f} ms/frame "
                          f"({row['ms_per_launch']:.4f} per launch)", flush=True)
    finally:
        kr.Runtime.kernel_launcher = launcher
        for f in files.values():
            f.unlink(missing_ok=True)
    d = Path(args.out)
    d.mkdir(parents=True, exist_ok=True)
    (d / "bodies_split.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
