"""The device layer: OpenCL device selection, program builds from the .cl files beside this
module, kernel lookup once per program, and per-stage event timing.

Everything that touches a device goes through a :class:`Runtime`; ``lbm`` and ``raytrace`` take
one and never create contexts themselves.
"""

from kernels.device import DeviceError, DeviceInfo, list_devices, select_device
from kernels.runtime import KernelBuildError, Runtime, get_runtime
from kernels.timing import StageTimer

__all__ = [
    "DeviceError",
    "DeviceInfo",
    "KernelBuildError",
    "Runtime",
    "StageTimer",
    "get_runtime",
    "list_devices",
    "select_device",
]
