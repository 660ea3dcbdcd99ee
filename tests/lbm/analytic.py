"""Analytic shallow-water solutions: they live in :mod:`lbm.analytic` (the studies use them too)."""

from lbm.analytic import bernoulli_depth, stoker, stoker_middle_celerity

__all__ = ["bernoulli_depth", "stoker", "stoker_middle_celerity"]
