"""Errors the CLI reports as one line and a non-zero exit (never a traceback). Declared in
``kernels.errors`` so lbm and raytrace raise the same classes without importing app."""

from __future__ import annotations

from kernels.errors import InputError, LbwaterError

__all__ = ["InputError", "LbwaterError"]
