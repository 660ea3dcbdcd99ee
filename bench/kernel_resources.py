"""Per-kernel resources of the frame's programs on a device: registers, spills and stack from the
compiler's report (NVIDIA: ``-cl-nv-verbose``, set here through LBWATER_CL_OPTIONS), and each
kernel's work-group info (largest work-group, private and local memory).

Usage: python3 bench/kernel_resources.py [--scene S] [--out FILE.json]
It renders two small frames of the scene (so every program a frame uses is built, the
cooperative ones included on a GPU), then reads the build logs. On devices whose compiler
writes no resource report the JSON still holds the work-group info."""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

#: ptxas lines: "ptxas info    : Function properties for render_trace" / "Used 72 registers"
_FUNC = re.compile(r"(?:Compiling entry function|Function properties for) '?(\w+)'?")
_USED = re.compile(r"Used (\d+) registers")
_SPILL = re.compile(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads")


def parse_log(log: str) -> dict:
    """{kernel: {registers, stack, spill_stores, spill_loads}} from a ptxas verbose log."""
    out, name = {}, None
    for line in log.splitlines():
        m = _FUNC.search(line)
        if m:
            name = m.group(1)
            out.setdefault(name, {})
        if name is None:
            continue
        m = _USED.search(line)
        if m:
            out[name]["registers"] = int(m.group(1))
        m = _SPILL.search(line)
        if m:
            out[name].update(stack=int(m.group(1)), spill_stores=int(m.group(2)),
                             spill_loads=int(m.group(3)))
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=str(ROOT / "bench/scenes/pool_static_boat.toml"))
    p.add_argument("--out", default=None, help="JSON file")
    a = p.parse_args()
    import pyopencl as cl

    from app.scene import load_scene
    from app.world import World
    from kernels import get_runtime

    rt = get_runtime()   # programs are built later, with the options then in force
    if "nvidia" in rt.device.platform.name.lower():   # the option is NVIDIA's
        os.environ["LBWATER_CL_OPTIONS"] = (os.environ.get("LBWATER_CL_OPTIONS", "")
                                            + " -cl-nv-verbose")
    world = World(load_scene(a.scene), rt, width=320, height=180, cells=128)
    for _ in range(3):
        world.frame(1 / 60)
    rows = []
    for (source, defines), prg in sorted(rt._programs.items(), key=lambda kv: kv[0][0]):
        log = prg.get_build_info(rt.device, cl.program_build_info.LOG) or ""
        regs = parse_log(log)
        for k in prg.all_kernels():
            name = k.function_name
            wg = k.get_work_group_info
            rows.append({"source": source, "defines": dict(defines), "kernel": name,
                         **regs.get(name, {}),
                         "max_work_group": wg(cl.kernel_work_group_info.WORK_GROUP_SIZE,
                                              rt.device),
                         "private_bytes": wg(cl.kernel_work_group_info.PRIVATE_MEM_SIZE,
                                             rt.device),
                         "local_bytes": wg(cl.kernel_work_group_info.LOCAL_MEM_SIZE,
                                           rt.device)})
    rows = [r for r in rows if r["source"].startswith(("render", "lbm", "bvh", "caustics"))]
    for r in rows:
        d = ",".join(f"{k}={v}" for k, v in r["defines"].items() if k != "TRACE_WIDE")
        print(f"{r['source']:24} {r['kernel']:32} {d:28} regs {r.get('registers', '-'):>4} "
              f"stack {r.get('stack', '-'):>5} spill {r.get('spill_stores', '-'):>4} "
              f"wg {r['max_work_group']:>5} private {r['private_bytes']:>6}")
    if a.out:
        from app.io import write_json

        write_json(a.out, {"device": rt.name, "kernels": rows})   # atomic
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
