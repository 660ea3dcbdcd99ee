"""Analytic shallow-water solutions in float64 (REFERENCES.md sec. 2): the oracles of the
validation tests and of `lbwater study lbm-resolution`."""

from __future__ import annotations

import math

import numpy as np


def stoker_middle_celerity(h0: float, hr: float, g: float) -> float:
    """c_m = sqrt(g h_m) of the wet dam break: the root in (sqrt(g hr), sqrt(g h0)) of
    -8 g hr c^2 (c0 - c)^2 + (c^2 - g hr)^2 (c^2 + g hr) = 0 (SWASHES, Delestre et al. 2013),
    by bisection to machine precision."""
    c0 = math.sqrt(g * h0)

    def p(c):
        return -8 * g * hr * c * c * (c0 - c) ** 2 + (c * c - g * hr) ** 2 * (c * c + g * hr)

    lo, hi = math.sqrt(g * hr), c0
    assert p(lo) < 0 < p(hi) or p(lo) > 0 > p(hi)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if (p(mid) > 0) == (p(hi) > 0):
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def stoker(x, t: float, x0: float, h0: float, hr: float, g: float = 9.81):
    """Depth and velocity of Stoker's wet dam break at time t > 0 (dam at x0, h0 left, hr
    right): still water, rarefaction fan, constant middle state, shock, still water."""
    x = np.asarray(x, np.float64)
    c0 = math.sqrt(g * h0)
    cm = stoker_middle_celerity(h0, hr, g)
    hm, um = cm * cm / g, 2 * (c0 - cm)
    s = 2 * cm * cm * (c0 - cm) / (cm * cm - g * hr)
    xi = (x - x0) / t
    h = np.where(xi <= -c0, h0, np.where(xi <= 2 * c0 - 3 * cm, (2 * c0 - xi) ** 2 / (9 * g),
                                         np.where(xi <= s, hm, hr)))
    u = np.where(xi <= -c0, 0.0, np.where(xi <= 2 * c0 - 3 * cm, 2 / 3 * (xi + c0),
                                          np.where(xi <= s, um, 0.0)))
    return h, u


def bernoulli_depth(z, energy: float, q: float, g: float = 9.81):
    """Subcritical depth h(z) of steady 1D flow with discharge q (m^2/s) and head ``energy``
    (m): the root above the critical depth (q^2/g)^(1/3) of h + q^2/(2 g h^2) + z = energy
    (Zhou 2004's flow over a bump; SWASHES), by bisection in float64."""
    z = np.asarray(z, np.float64)
    lo = np.full(z.shape, (q * q / g) ** (1.0 / 3.0))
    hi = energy - z
    assert np.all(hi > lo), "the head is below critical: no subcritical solution"
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        above = mid + q * q / (2 * g * mid * mid) + z > energy
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    return 0.5 * (lo + hi)
