"""NumPy mirrors of the device structs in ``kernels/lbm.h`` (layouts proved by tests/lbm)."""

from __future__ import annotations

import numpy as np

#: LbmParams, 56 bytes: the solver's constants, passed by value to every lbm kernel.
PARAMS_DTYPE = np.dtype([
    ("nx", "<i4"), ("ny", "<i4"), ("n_cells", "<i4"),
    ("dx", "<f4"), ("e", "<f4"), ("g_lat", "<f4"), ("drag", "<f4"),
    ("h_min", "<f4"), ("u2_max", "<f4"), ("fr2_max", "<f4"),
    ("rest0", "<f4"), ("rest_axis", "<f4"), ("rest_diag", "<f4"), ("quantum", "<f4"),
])

#: LbmGuard, 112 bytes: the guard's device record, read by the host once per frame.
GUARD_DTYPE = np.dtype([
    ("tau", "<f4"), ("tau_user", "<f4"),
    ("mass", "<f4"), ("max_u2", "<f4"), ("max_fr2", "<f4"), ("min_h", "<f4"),
    ("ckpt_mass", "<f4"), ("ckpt_max_u2", "<f4"), ("ckpt_max_fr2", "<f4"), ("ckpt_min_h", "<f4"),
    ("mass0", "<f4"), ("sources", "<f4"), ("clipped", "<f4"), ("created", "<f4"),
    ("peak_fr2", "<f4"), ("peak_acc", "<f4"),
    ("nan_cells", "<u4"), ("action", "<u4"), ("clamped", "<u4"), ("clamped_checked", "<u4"),
    ("restored", "<u4"), ("damped", "<u4"), ("saved", "<u4"), ("checks", "<u4"),
    ("damped_cells", "<u4"), ("pad0", "<u4"), ("pad1", "<u4"),
])

#: LbmPartial, 32 bytes: one work-group's partial reduction.
PARTIAL_DTYPE = np.dtype([
    ("mass", "<f4"), ("max_u2", "<f4"), ("max_fr2", "<f4"), ("min_h", "<f4"),
    ("nan_cells", "<u4"), ("damped_cells", "<u4"), ("mass_lo", "<f4"), ("pad1", "<u4"),
])

#: LbmSource, 48 bytes: a drop or a push, its launch box and the volume it asks for.
SOURCE_DTYPE = np.dtype([
    ("x", "<f4"), ("y", "<f4"), ("dx", "<f4"), ("dy", "<f4"),
    ("radius", "<f4"), ("amount", "<f4"), ("i0", "<i4"), ("j0", "<i4"),
    ("volume", "<f4"), ("pad0", "<f4"), ("pad1", "<f4"), ("pad2", "<f4"),
])

_F4 = ("<f4", (4,))
#: LbmBody, 256 bytes (kernels/lbm_bodies.h): one floating rigid body and its hull footprint.
BODY_DTYPE = np.dtype([
    ("pos", *_F4), ("quat", *_F4), ("vel", *_F4), ("omega", *_F4), ("inertia", *_F4),
    ("damping", *_F4), ("force", *_F4), ("torque", *_F4),
    ("base_r0", *_F4), ("base_r1", *_F4), ("base_r2", *_F4), ("foot", *_F4),
    ("foot_n", "<i4", (4,)), ("flags", "<i4", (4,)), ("box", "<i4", (4,)),
    ("box_old", "<i4", (4,)),
])

#: LbmBodyStep, 48 bytes: one bodies launch, by value.
BODY_STEP_DTYPE = np.dtype([
    ("origin", *_F4), ("dt", "<f4"), ("gravity", "<f4"), ("rho", "<f4"), ("n_bodies", "<i4"),
    ("size_x", "<f4"), ("size_z", "<f4"), ("floor", "<f4"), ("n_sub", "<i4"),
])

#: (header, struct name, dtype) of every device struct the lbm package declares.
STRUCTS = [
    ("lbm.h", "LbmParams", PARAMS_DTYPE),
    ("lbm.h", "LbmGuard", GUARD_DTYPE),
    ("lbm.h", "LbmPartial", PARTIAL_DTYPE),
    ("lbm.h", "LbmSource", SOURCE_DTYPE),
    ("lbm_bodies.h", "LbmBody", BODY_DTYPE),
    ("lbm_bodies.h", "LbmBodyStep", BODY_STEP_DTYPE),
]


def record(dtype: np.dtype, **values) -> np.void:
    """One struct value (every field named, none forgotten) for a by-value kernel argument."""
    missing = set(dtype.names) - set(values) - {n for n in dtype.names if n.startswith("pad")}
    extra = set(values) - set(dtype.names)
    if missing or extra:
        raise TypeError(f"struct fields missing {sorted(missing)} / unknown {sorted(extra)}")
    rec = np.zeros(1, dtype)
    for k, v in values.items():
        rec[k] = v
    return rec[0]
