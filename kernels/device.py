"""Choosing an OpenCL device: a GPU first, PoCL's CPU device as the embedded fallback.

A device is named by a *spec*: ``"gpu"``, ``"cpu"``, ``"P:D"`` (platform and device index, as in
``PYOPENCL_CTX``), ``"P"`` or a case-insensitive substring of the platform or device name
(``"nvidia"``, ``"h100"``), or a vendor alias from :data:`ALIASES` (``"pocl"`` names the platform
"Portable Computing Language" whose devices are called "pthread-<cpu>"; ``"cuda"`` names NVIDIA's).
The spec comes from the caller (``--device``), else ``LBWATER_DEVICE``, else ``PYOPENCL_CTX``, else
the default order.
"""

from __future__ import annotations

import os
import re
from dataclasses import asdict, dataclass

import pyopencl as cl

#: Extensions that matter to lbwater, reported by ``lbwater devices``.
RELEVANT_EXTENSIONS = (
    "cl_khr_fp64",
    "cl_khr_fp16",
    "cl_khr_global_int32_base_atomics",
    "cl_khr_int64_base_atomics",
    "cl_khr_gl_sharing",
    "cl_khr_subgroups",
    "cl_nv_device_attribute_query",
)


#: Vendor and driver names users type -> substrings of the platform's name or vendor that mean
#: it (lower case). A spec that is a key matches platforms by these terms, then, like any other
#: spec, platforms and devices whose names contain it.
ALIASES = {
    "pocl": ("portable computing language", "pocl"),
    "portable": ("portable computing language",),
    "nvidia": ("nvidia",),
    "cuda": ("nvidia",),
    "intel": ("intel(r) opencl", "intel(r) corporation", "intel"),
    "oneapi": ("intel(r) opencl",),
    "amd": ("amd accelerated parallel processing", "advanced micro devices", "amd"),
    "rocm": ("amd accelerated parallel processing", "advanced micro devices"),
    "apple": ("apple",),
    "rusticl": ("rusticl",),
    "mesa": ("rusticl", "clover", "mesa"),
}


class DeviceError(ValueError):
    """No OpenCL device matches a request, or no OpenCL platform exists at all."""


@dataclass(frozen=True)
class DeviceInfo:
    """What ``lbwater devices`` reports about one device."""

    spec: str
    platform: str
    name: str
    type: str
    compute_units: int
    global_mem_mib: int
    max_alloc_mib: int
    local_mem_kib: int
    max_work_group_size: int
    opencl_version: str
    driver_version: str
    extensions: tuple[str, ...]
    device_fence: str

    def as_dict(self) -> dict:
        return asdict(self)


def _platforms() -> list[cl.Platform]:
    try:
        return cl.get_platforms()
    except cl.Error as exc:  # pyopencl raises LogicError when no ICD is installed
        raise DeviceError(f"no OpenCL platform found ({exc}); install pocl-binary-distribution "
                          "or a GPU driver") from None


def _type_name(device: cl.Device) -> str:
    t = device.type
    for flag, name in ((cl.device_type.GPU, "GPU"), (cl.device_type.CPU, "CPU"),
                       (cl.device_type.ACCELERATOR, "ACCELERATOR")):
        if t & flag:
            return name
    return "OTHER"


def _all_devices() -> list[tuple[str, cl.Platform, cl.Device]]:
    out = []
    for ip, platform in enumerate(_platforms()):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue
        for idev, device in enumerate(devices):
            out.append((f"{ip}:{idev}", platform, device))
    return out


def describe(spec: str, platform: cl.Platform, device: cl.Device) -> DeviceInfo:
    """Collect the facts about one device that the CLI and the benchmarks print."""
    exts = set(device.extensions.split())
    return DeviceInfo(
        spec=spec,
        platform=platform.name.strip(),
        name=device.name.strip(),
        type=_type_name(device),
        compute_units=int(device.max_compute_units),
        global_mem_mib=int(device.global_mem_size >> 20),
        max_alloc_mib=int(device.max_mem_alloc_size >> 20),
        local_mem_kib=int(device.local_mem_size >> 10),
        max_work_group_size=int(device.max_work_group_size),
        opencl_version=device.version.strip(),
        driver_version=device.driver_version.strip(),
        extensions=tuple(e for e in RELEVANT_EXTENSIONS if e in exts),
        device_fence=FENCE_DOC[fence_kind(device)],
    )


#: What kernels/common.h's DEVICE_FENCE() is on a device, by :func:`fence_kind`.
FENCE_DOC = {
    "membar": "membar.gl (PTX, NVIDIA)",
    "atomic_fence": "atomic_work_item_fence(global, acq_rel, device scope)",
    "mem_fence": "mem_fence (OpenCL 1.2; not a device-scope fence)",
}

_FENCE_FEATURES = ("__opencl_c_atomic_order_acq_rel", "__opencl_c_atomic_scope_device")


def _c_versions(device: cl.Device) -> list[tuple[int, int]]:
    """OpenCL C versions the device compiles, as (major, minor)."""
    out = []
    try:
        for v in device.opencl_c_all_versions:  # OpenCL 3.0 devices
            out.append((v.version >> 22, (v.version >> 12) & 0x3FF))
    except (cl.Error, AttributeError):
        pass
    try:
        text = device.opencl_c_version.split()[2]  # "OpenCL C 1.2 ..."
        major, minor = text.split(".")[:2]
        out.append((int(major), int(minor)))
    except (cl.Error, AttributeError, IndexError, ValueError):
        pass
    return out


def _c_features(device: cl.Device) -> set[str]:
    try:
        return {f.name for f in device.opencl_c_features}
    except (cl.Error, AttributeError):
        return set()


def fence_kind(device: cl.Device) -> str:
    """How DEVICE_FENCE() is made on ``device`` (a key of :data:`FENCE_DOC`).

    NVIDIA: PTX ``membar.gl`` (measured sufficient, BENCHMARKS.md). Otherwise OpenCL C 3.0 with
    the acq_rel order and device scope features, or OpenCL C 2.x: ``atomic_work_item_fence``.
    Otherwise only OpenCL 1.2's ``mem_fence``, which does not promise that stores reach other
    work-groups before a following atomic (see kernels/common.h for what that means)."""
    if "nvidia" in device.platform.name.lower():
        return "membar"
    versions = _c_versions(device)
    if any(v >= (3, 0) for v in versions) and set(_FENCE_FEATURES) <= _c_features(device):
        return "atomic_fence"
    if any((2, 0) <= v < (3, 0) for v in versions):
        return "atomic_fence"
    return "mem_fence"


def cl_std_option(device: cl.Device) -> str:
    """The ``-cl-std=`` build option for ``device``: CL3.0 or CL2.0 where DEVICE_FENCE needs
    their atomic fence, else CL1.2 (NVIDIA stays on CL1.2 with its PTX fence)."""
    if fence_kind(device) != "atomic_fence":
        return "-cl-std=CL1.2"
    versions = _c_versions(device)
    if any(v >= (3, 0) for v in versions) and set(_FENCE_FEATURES) <= _c_features(device):
        return "-cl-std=CL3.0"
    return "-cl-std=CL2.0"


def list_devices() -> list[DeviceInfo]:
    """Every OpenCL device on this machine, in ``P:D`` order."""
    return [describe(spec, p, d) for spec, p, d in _all_devices()]


def pocl_version(platform: cl.Platform) -> tuple[int, int]:
    """(major, minor) of a PoCL platform from its version string ("OpenCL 3.0 PoCL 3.1+debian
    ..."); (0, 0) when it names none."""
    m = re.search(r"PoCL (\d+)\.(\d+)", platform.version)
    return (int(m.group(1)), int(m.group(2))) if m else (0, 0)


def _default_order(candidates):
    """GPUs first, then PoCL, newest PoCL first: where two are installed (pyopencl's wheel
    bundles PoCL 3.0 with LLVM 14, whose compiler rejects CPUs newer than it, such as AMD
    family 1Ah: "unknown target CPU 'generic'"; Debian's pocl-opencl-icd is PoCL 3.1 with
    LLVM 15, which falls back to the CPU's features), the newer compiler knows more CPUs."""
    gpus = [c for c in candidates if c[2].type & cl.device_type.GPU]
    pocl = [c for c in candidates if "portable computing language" in c[1].name.lower()
            or "pocl" in c[1].name.lower()]
    pocl.sort(key=lambda c: pocl_version(c[1]), reverse=True)   # stable: platform order next
    return gpus + pocl + [c for c in candidates if c not in gpus and c not in pocl]


def _match(spec: str, candidates):
    s = spec.strip().lower()
    if s in ("", "default", "auto"):
        return _default_order(candidates)
    if s in ("gpu", "cpu", "accelerator"):
        flag = {"gpu": cl.device_type.GPU, "cpu": cl.device_type.CPU,
                "accelerator": cl.device_type.ACCELERATOR}[s]
        return _default_order([c for c in candidates if c[2].type & flag])
    head = s.split(":")
    if all(part.isdigit() for part in head if part) and head[0]:
        if len(head) == 1 or head[1] == "":
            return [c for c in candidates if c[0].split(":")[0] == head[0]]
        return [c for c in candidates if c[0] == f"{int(head[0])}:{int(head[1])}"]
    by_platform = [c for c in candidates if _platform_matches(s, c[1])]
    by_device = [c for c in candidates if c not in by_platform and s in c[2].name.lower()]
    return by_platform + by_device


def _platform_matches(spec: str, platform: cl.Platform) -> bool:
    """``spec`` names this platform: part of its name, or an alias of its name or vendor."""
    text = f"{platform.name} {platform.vendor}".lower()
    return spec in platform.name.lower() or any(t in text for t in ALIASES.get(spec, ()))


def resolve_spec(spec: str | None = None) -> tuple[str, str]:
    """The spec in force and where it came from (argument, environment variable or default)."""
    if spec:
        return spec, "--device"
    for var in ("LBWATER_DEVICE", "PYOPENCL_CTX"):
        if os.environ.get(var):
            return os.environ[var], var
    return "default", "default"


def select_device(spec: str | None = None) -> cl.Device:
    """The device named by ``spec`` (see the module docstring), or the default one."""
    spec, origin = resolve_spec(spec)
    candidates = _all_devices()
    if not candidates:
        raise DeviceError("no OpenCL device found; install pocl-binary-distribution "
                          "or a GPU driver")
    matches = _match(spec, candidates)
    if not matches:
        names = ", ".join(f"{c[0]} {c[2].name.strip()}" for c in candidates)
        raise DeviceError(f"no OpenCL device matches {origin}={spec!r}; available: {names} "
                          "(use gpu, cpu, P:D, a vendor such as pocl, nvidia, intel, amd, "
                          "or part of a name)")
    return matches[0][2]
