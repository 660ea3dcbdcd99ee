"""User-facing errors, declared at the bottom layer so every package can raise them without
importing against the direction app -> {lbm, raytrace} -> kernels; ``app.errors`` re-exports them
and the CLI reports them as one line and a non-zero exit (never a traceback)."""

from __future__ import annotations


class LbwaterError(Exception):
    """Base for user-facing errors: bad input, bad scene, unstable simulation, bad device."""


class InputError(LbwaterError, ValueError):
    """A file, key or value given by the user is wrong; the message names it and the rule."""
