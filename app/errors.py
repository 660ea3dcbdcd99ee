"""Errors the CLI reports as one line and a non-zero exit (never a traceback)."""

from __future__ import annotations


class LbwaterError(Exception):
    """Base for user-facing errors: bad input, bad scene, unstable simulation, bad device."""


class InputError(LbwaterError, ValueError):
    """A file, key or value given by the user is wrong; the message names it and the rule."""
