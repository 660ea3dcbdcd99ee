"""The device layer: OpenCL device selection, program builds from the .cl files beside this
module, kernel lookup once per program, and per-stage event timing.

Everything that touches a device goes through a :class:`Runtime`; ``lbm`` and ``raytrace`` take
one and never create contexts themselves. The names below load on first use, so importing
``kernels.errors`` (as ``app.errors`` does for the CLI's parser) does not import pyopencl.
"""

from __future__ import annotations

import importlib

_WHERE = {
    "DeviceError": "kernels.device", "DeviceInfo": "kernels.device",
    "list_devices": "kernels.device", "select_device": "kernels.device",
    "KernelBuildError": "kernels.runtime", "Runtime": "kernels.runtime",
    "get_runtime": "kernels.runtime", "StageTimer": "kernels.timing",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'kernels' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
