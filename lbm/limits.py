"""What grid the solver can take on a device: the kernels' 32-bit population index and the
device's memory, checked before anything is allocated (one call in the solver's constructor)."""

from __future__ import annotations

from kernels.limits import check_fits

#: The step kernels index the populations as ``m * n_cells + s`` in a 32-bit int (m < 9,
#: kernels/lbm_step.cl): 9 n_cells must stay below 2^31, about 238.6 M cells (15446^2).
MAX_CELLS = (2**31 - 1) // 9

#: Device bytes per cell the solver allocates: populations ping, pong and checkpoint (3 x 9
#: floats), depth ping, pong and checkpoint (3 floats) and the bed (1 float).
DEVICE_BYTES_PER_CELL = 3 * 36 + 3 * 4 + 4


def check_grid(rt, nx: int, ny: int) -> None:
    """One-line ValueError when an ``nx`` x ``ny`` grid overflows the kernels' indices or does
    not fit ``rt``'s device (the estimate and the limit in the message)."""
    n = int(nx) * int(ny)
    if n > MAX_CELLS:
        raise ValueError(f"grid {nx}x{ny} has {n:,} cells; the LBM kernels address at most "
                         f"{MAX_CELLS:,} (32-bit population index m * n_cells + s)")
    check_fits(rt, DEVICE_BYTES_PER_CELL * n, f"LBM grid {nx}x{ny}", largest=36 * n)
