"""The traversal work counters of TRACE_COUNT builds (kernels/traverse.h, Scene.trace_counts):
exact counts on a scene small enough to count by hand, in both BVH layouts, and nothing counted
without the define."""

import numpy as np
import pytest

from app.meshes import height_field_grid
from raytrace import RayQuery, Scene
from raytrace import scene as scene_module
from raytrace.bvh import HIT_DTYPE
from raytrace.query import intersect_reference, pack_rays
from raytrace.scene import TRACE_KINDS

COUNT = {"TRACE_COUNT": 1}


def trace(rt, scene, o, d, *, any_hit=False, defines=COUNT):
    ro, rd = pack_rays(o, d)
    n = len(ro)
    hits = rt.buffer(HIT_DTYPE.itemsize * n)
    scene.reset_trace_counts()
    RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits, n, any_hit=any_hit,
             defines=defines).enqueue()
    h = rt.to_host(hits, HIT_DTYPE, n)
    return h, scene.trace_counts()


def two_triangles(rt, layout):
    """One triangle instanced twice, 10 m apart in x: instance 0 at the origin, 1 at x = 10."""
    scene = Scene(rt, layout=layout)
    mesh = scene.add_mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
                          np.array([[0, 1, 2]], np.uint32))
    scene.add_instance(mesh)
    m = np.eye(4)
    m[0, 3] = 10.0
    scene.add_instance(mesh, m)
    scene.update()
    return scene


@pytest.mark.parametrize("layout", ["binary", "wide"])
def test_counts_by_hand(rt, layout):
    scene = two_triangles(rt, layout)
    n_hit, n_miss = 37, 11
    o = np.concatenate([np.tile([[0.2, 0.3, 1.0]], (n_hit, 1)),
                        np.tile([[0.2, 0.3, 5.0]], (n_miss, 1))])
    d = np.concatenate([np.tile([[0.0, 0.0, -1.0]], (n_hit, 1)),
                        np.tile([[0.0, 1.0, 0.0]], (n_miss, 1))])  # above both boxes
    h, c = trace(rt, scene, o, d)
    assert (h["prim"][:n_hit] == 0).all() and (h["inst"][:n_hit] == 0).all()
    assert (h["prim"][n_hit:] < 0).all()
    q = c["query"]
    # every ray visits the TLAS root (its two children are the instances' leaves); only the
    # hitting rays enter instance 0's one-node BLAS and test its one triangle (a 4-lane block
    # in the wide layout); instance 1 is never entered
    tris = 1 if layout == "binary" else 4
    assert q["rays"] == q["traversals"] == n_hit + n_miss
    assert q["tlas_nodes"] == n_hit + n_miss
    assert q["blas_entries"] == q["blas_nodes"] == n_hit
    assert q["tri_tests"] == tris * n_hit
    assert q["hits"] == n_hit
    assert q["blas_nodes_by_instance"] == [n_hit] + [0] * 7
    for kind in TRACE_KINDS[1:]:  # other kinds untouched
        assert not any(v for k, v in c[kind].items() if k != "blas_nodes_by_instance")


def test_nothing_counted_without_the_define(rt):
    scene = two_triangles(rt, "binary")
    _, c = trace(rt, scene, [[0.2, 0.3, 1.0]], [[0.0, 0.0, -1.0]], defines=None)
    assert all(v == 0 for k, v in c["query"].items() if k != "blas_nodes_by_instance")


def test_any_hit_visits_no_more_than_closest_hit(rt):
    v, t = height_field_grid(33)
    scene = Scene(rt, layout="binary")
    scene.add_instance(scene.add_mesh(v, t))
    scene.update()
    rng = np.random.default_rng(5)
    n = 400
    o = np.stack([rng.uniform(-1, 1, n), np.full(n, 0.5), rng.uniform(-1, 1, n)], -1)
    d = np.stack([rng.normal(0, 0.3, n), -np.ones(n), rng.normal(0, 0.3, n)], -1)
    hc, cc = trace(rt, scene, o, d)
    ha, ca = trace(rt, scene, o, d, any_hit=True)
    ref = intersect_reference(v, t, o, d)
    n_hit = int((ref["prim"] >= 0).sum())
    assert cc["query"]["hits"] == ca["query"]["hits"] == n_hit > n // 2
    # both walk the same nodes up to the first hit; closest-hit goes on to prove it closest
    assert ca["query"]["blas_nodes"] < cc["query"]["blas_nodes"]
    assert ca["query"]["tri_tests"] <= cc["query"]["tri_tests"]


def test_stat_slots_match_the_header():
    from kernels.runtime import KERNEL_DIR

    text = (KERNEL_DIR / "scene.h").read_text()
    assert f"#define TRACE_STAT_LB_FIELDS {len(scene_module.LIGHT_BUFFER_COUNT_FIELDS)}\n" in text
    for name in ("TRACE_STAT_OVERFLOW", "TRACE_STAT_COOP_REDO", "TRACE_STAT_HF_CULLED",
                 "TRACE_STAT_HF_SKIPPED", "TRACE_STAT_LB"):
        assert f"#define {name} {getattr(scene_module, name)}\n" in text, name
    assert "#define TRACE_STAT_COUNT (TRACE_STAT_LB + TRACE_STAT_LB_FIELDS)\n" in text
    lb = (KERNEL_DIR / "light_buffer.h").read_text()   # the answers' slots, in order
    for i, field in enumerate(scene_module.LIGHT_BUFFER_COUNT_FIELDS):
        assert f"#define LB_CNT_{field.upper()} {i}\n" in lb, field
