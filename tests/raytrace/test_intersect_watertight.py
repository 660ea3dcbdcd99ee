"""Watertightness: rays aimed exactly at the shared vertices and edge midpoints of a closed mesh,
from inside and from outside, never miss."""

import numpy as np
import pytest

from raytrace import intersect


def icosphere(level: int) -> tuple[np.ndarray, np.ndarray]:
    t = (1 + 5 ** 0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
         [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    v = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(level):
        mid = {}
        out = []

        def m(a, b, mid=mid):
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = v[a] + v[b]
                v.append(p / np.linalg.norm(p))
                mid[key] = len(v) - 1
            return mid[key]

        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            out += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = out
    return np.array(v), np.array(f)


def edges(tri):
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0)


def leak_rays(bumpy: bool):
    """A closed icosphere (made non-convex when ``bumpy``), moved to awkward floats, and rays that
    must all hit it: from the centre towards each shared vertex and edge midpoint (the first
    ``n_targets`` rays) and from outside along the same radial line towards the centre.
    Returns (vertices, faces, origins, directions, n_targets)."""
    rng = np.random.default_rng(12)
    v, f = icosphere(3)
    if bumpy:  # still star-shaped around the centre, but no longer convex
        v = v * (1 + 0.3 * rng.random((len(v), 1)))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    center = np.array([0.37, -1.21, 2.05])
    v = (v @ q.T * 3.1 + center).astype(np.float32)   # awkward floats everywhere
    e = edges(f)
    targets = np.concatenate([v.astype(np.float64),
                              0.5 * (v[e[:, 0]].astype(np.float64) + v[e[:, 1]])])
    o_out = targets + 2.0 * (targets - center)
    o = np.concatenate([np.broadcast_to(center, targets.shape), o_out])
    d = np.concatenate([targets - center, center - o_out])
    return v, f, o, d, len(targets)


@pytest.mark.parametrize("bumpy", [False, True])
def test_closed_mesh_never_leaks(rt, bumpy):
    v, f, o, d, n_in = leak_rays(bumpy)
    hits = intersect(v, f, o, d, device=rt)
    assert len(o) > 5000
    assert np.all(hits["prim"] >= 0), f"{np.sum(hits['prim'] < 0)} rays leaked"
    # from the centre the first hit is at the target itself (t = 1) for a convex sphere
    if not bumpy:
        assert np.allclose(hits["t"][: len(v)], 1.0, atol=1e-5)
        assert np.all(hits["t"][:n_in] <= 1.0 + 1e-5)
