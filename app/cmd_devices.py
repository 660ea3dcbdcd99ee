"""List OpenCL platforms and devices: name, type, compute units, memory, OpenCL version and the
extensions that matter to lbwater. The device that ``--device``/``LBWATER_DEVICE`` would pick is
marked with ``*``."""

from __future__ import annotations

import json


def add_arguments(p) -> None:
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--device", help="mark the device this spec selects (gpu, cpu, pocl, P:D, name)")


def run(args) -> int:
    from kernels.device import list_devices, select_device

    infos = list_devices()
    chosen = select_device(args.device)
    chosen_name = chosen.name.strip()
    chosen_platform = chosen.platform.name.strip()
    rows = [dict(i.as_dict(), selected=(i.name == chosen_name and i.platform == chosen_platform))
            for i in infos]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    for r in rows:
        mark = "*" if r["selected"] else " "
        print(f"{mark} {r['spec']:5} {r['type']:4} {r['name']}  [{r['platform']}]")
        print(f"        {r['compute_units']} compute units, {r['global_mem_mib']} MiB "
              f"(max alloc {r['max_alloc_mib']} MiB), local {r['local_mem_kib']} KiB, "
              f"work-group <= {r['max_work_group_size']}")
        print(f"        {r['opencl_version']}; driver {r['driver_version']}")
        print(f"        extensions: {', '.join(r['extensions']) or 'none of note'}")
        print(f"        device fence: {r['device_fence']}")
    return 0
