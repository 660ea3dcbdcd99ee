"""Analytic shallow-water solutions: they live in :mod:`lbm.analytic` (the studies use them too)."""

from lbm.analytic import stoker, stoker_middle_celerity

__all__ = ["stoker", "stoker_middle_celerity"]
