"""OpenCL entry points that pip's pyopencl does not bind, through ctypes on the same ICD loader
pyopencl uses (its wheel bundles one); handles they return are wrapped as pyopencl objects with
``from_int_ptr``. Used by the window's shared display path (app.ext_share)."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import glob
import os

import pyopencl as cl


@functools.cache
def loader() -> ctypes.CDLL:
    """The OpenCL ICD loader pyopencl is linked against, else the system's."""
    here = os.path.dirname(cl.__file__)
    found = sorted(glob.glob(os.path.join(here, ".libs", "libOpenCL*.so*")))
    return ctypes.CDLL(found[0] if found else ctypes.util.find_library("OpenCL")
                       or "libOpenCL.so.1")


def error_name(code: int) -> str:
    """``CL_...`` name of an OpenCL status code."""
    names = {v: k for k, v in vars(cl.status_code).items() if isinstance(v, int)}
    return names.get(code, f"error {code}")
