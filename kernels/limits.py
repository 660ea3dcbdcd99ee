"""What fits on a device: checked before allocating, so a grid, an image or a sample count that
is too large fails at once with the estimate and the device's limit, not with a driver error
(or a swapping host) in the middle of a run.

Owners call one line before their allocations::

    check_fits(rt, total_bytes, "LBM grid 4096x4096", largest=population_bytes)
"""

from __future__ import annotations

#: Share of the device's global memory one object may plan to use: the rest is left to the other
#: objects of a frame (scene, BVH, renderer, solver) and to the driver.
MEMORY_FRACTION = 0.9


class DeviceLimitError(ValueError):
    """A request does not fit the device; the message gives the estimate and the limit."""


def _mib(nbytes: float) -> str:
    return f"{nbytes / 2**20:,.0f} MiB" if nbytes < 2**30 * 10 else f"{nbytes / 2**30:,.1f} GiB"


def device_memory(rt) -> tuple[int, int]:
    """(global memory bytes, largest single buffer bytes) of ``rt``'s device."""
    return int(rt.device.global_mem_size), int(rt.device.max_mem_alloc_size)


def check_fits(rt, nbytes: int, what: str, *, largest: int | None = None) -> None:
    """Raise :class:`DeviceLimitError` when ``nbytes`` in all (``largest`` in one buffer) does
    not fit ``rt``'s device: more than MEMORY_FRACTION of its global memory, or a buffer over
    its largest allocation. ``what`` names the request in the message ("render 8192x8192")."""
    total, max_alloc = device_memory(rt)
    name = rt.device.name.strip()
    if largest is not None and largest > max_alloc:
        raise DeviceLimitError(
            f"{what} needs a {_mib(largest)} buffer; {name} allows at most {_mib(max_alloc)} "
            "per buffer")
    if nbytes > MEMORY_FRACTION * total:
        raise DeviceLimitError(
            f"{what} needs about {_mib(nbytes)} of device memory; {name} has {_mib(total)} "
            f"({MEMORY_FRACTION:.0%} usable)")
