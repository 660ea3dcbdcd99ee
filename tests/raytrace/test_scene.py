"""Two-level scene: instances moved by transforms hit exactly what the transformed mesh, traced
directly, hits; dynamic meshes follow their device buffers through update()."""

import numpy as np
import pyopencl as cl

from raytrace import RayQuery, Scene
from raytrace.bvh import HIT_DTYPE, vertices_to_float4
from raytrace.query import intersect_reference, pack_rays


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def affine(r, t, s=1.0):
    m = np.eye(4)
    m[:3, :3] = r * s
    m[:3, 3] = t
    return m


def trace(rt, scene, o, d):
    ro, rd = pack_rays(o, d)
    hits = rt.buffer(HIT_DTYPE.itemsize * len(o))
    q = RayQuery(scene, rt.to_device(ro), rt.to_device(rd), hits, len(o))
    q.enqueue()
    out = rt.to_host(hits, HIT_DTYPE, len(o))
    scene.check()
    return out


def test_instances_equal_transformed_meshes(rt):
    rng = np.random.default_rng(5)
    va = rng.random((90, 3)).astype(np.float32) - 0.5
    ta = np.arange(90).reshape(30, 3)
    vb = rng.random((60, 3)).astype(np.float32) - 0.5
    tb = np.arange(60).reshape(20, 3)[:, ::-1].copy()
    scene = Scene(rt)
    ma, mb = scene.add_mesh(va, ta), scene.add_mesh(vb, tb)
    xf = [affine(rotation([1, 2, 3], 0.7), [2, 0, 0]),
          affine(rotation([0, 1, 0], 2.0), [-1, 0.5, 0], 1.5),
          affine(np.eye(3), [0, 0, 1]),
          affine(rotation([1, 0, 0], -1.0), [0, -1, 0], 0.5)]
    meshes = [ma, mb, ma, mb]
    ids = [scene.add_instance(m, x) for m, x in zip(meshes, xf, strict=True)]
    assert ids == [0, 1, 2, 3]
    scene.update()

    def reference(xforms):
        # the transformed meshes as one soup traced directly in float64
        vs, ts, owner, local = [], [], [], []
        base = 0
        for inst, (m, x) in enumerate(zip(meshes, xforms, strict=True)):
            v, t = (va, ta) if m == ma else (vb, tb)
            vs.append(v @ x[:3, :3].T + x[:3, 3])
            ts.append(t + base)
            owner.append(np.full(len(t), inst))
            local.append(np.arange(len(t)))
            base += len(v)
        return np.concatenate(vs), np.concatenate(ts), np.concatenate(owner), np.concatenate(local)

    n = 3000
    o = rng.uniform(-3, 3, (n, 3))
    d = rng.normal(size=(n, 3))
    for step in range(2):
        if step == 1:  # move two instances; only the TLAS is rebuilt
            xf[0] = affine(rotation([0, 0, 1], 0.3), [0.3, -0.2, 0.1], 2.0)
            xf[3] = affine(np.eye(3), [0.1, 0.1, 0.1])
            scene.set_transform(0, xf[0])
            scene.set_transform(3, xf[3])
            scene.update()
        v, t, owner, local = reference(xf)
        ref = intersect_reference(v, t, o, d)
        got = trace(rt, scene, o, d)
        hit = ref["prim"] >= 0
        assert 0.05 < hit.mean() < 0.95
        assert np.array_equal(got["prim"] >= 0, hit)
        assert np.allclose(got["t"][hit], ref["t"][hit], rtol=1e-4, atol=1e-5)
        same = (got["inst"][hit] == owner[ref["prim"][hit]]) & (
            got["prim"][hit] == local[ref["prim"][hit]])
        assert same.mean() > 0.999


def test_dynamic_mesh_from_device_buffers_refit_and_rebuild(rt):
    rng = np.random.default_rng(6)
    v = rng.random((60, 3)).astype(np.float32)
    t = np.arange(60, dtype=np.uint32).reshape(20, 3)
    vbuf, tbuf = rt.to_device(vertices_to_float4(v)), rt.to_device(t)
    scene = Scene(rt)
    m = scene.add_mesh(vbuf, tbuf, dynamic=True, n_vertices=60, n_triangles=20)
    scene.add_instance(m)
    scene.update()
    o = rng.uniform(-0.5, 1.5, (800, 3))
    d = rng.normal(size=(800, 3))
    for rebuild in (False, True):
        v = (v + rng.normal(scale=0.2, size=v.shape)).astype(np.float32)
        cl.enqueue_copy(rt.queue, vbuf, vertices_to_float4(v))
        scene.update(rebuild=rebuild)
        ref = intersect_reference(v, t, o, d)
        got = trace(rt, scene, o, d)
        assert np.array_equal(got["prim"], ref["prim"])
        hit = ref["prim"] >= 0
        assert np.allclose(got["t"][hit], ref["t"][hit], rtol=1e-4, atol=1e-5)


def test_transform_row_layout(rt):
    from kernels.layout import check_struct
    from raytrace.scene import TRANSFORM_DTYPE

    check_struct(rt, "transform.h", "Transform", TRANSFORM_DTYPE)


def transform_record(m):
    from raytrace.scene import TRANSFORM_DTYPE

    rec = np.zeros(1, TRANSFORM_DTYPE)[0]
    for k in range(3):
        rec[f"r{k}"] = np.asarray(m, np.float64)[k]
    return rec


def test_device_written_row_moves_the_instance(rt):
    """A kernel composes a pose into the instance's row of the transform buffer (no host copy,
    set_transform never called): after update() rays hit the moved mesh as the float64
    reference of the moved mesh does, and the host writes a row only when it changes."""
    rng = np.random.default_rng(11)
    v = rng.random((60, 3)).astype(np.float32) - 0.5
    t = np.arange(60).reshape(20, 3)
    scene = Scene(rt)
    m = scene.add_mesh(v, t)
    x0 = affine(rotation([0, 1, 1], 0.4), [0.2, 0, 0], 1.3)
    scene.add_instance(m)                      # a decoy at the identity
    inst = scene.add_instance(m, x0)
    scene.update()
    delta = affine(rotation([1, 0, 0], 0.9), [0, 0.7, -0.3])
    delta[:3, :3] *= [[1.0], [0.5], [2.0]]     # rows scaled: non-uniform
    k = rt.kernel_launcher("transform.cl", "transform_compose", stage="test.pose")
    k.bind(rows=scene.transform_buffer, row=scene.transform_row(inst),
           delta=transform_record(delta[:3])).launch(1)
    scene.update()
    moved = delta @ x0
    np.testing.assert_allclose(scene.read_transforms()[inst], moved[:3], rtol=1e-5, atol=1e-6)
    n = 2000
    vw = np.concatenate([v, v @ moved[:3, :3].T + moved[:3, 3]])
    o = rng.uniform(-3, 3, (n, 3))
    d = vw[60 + rng.integers(0, 60, n)] + rng.normal(scale=0.2, size=(n, 3)) - o  # at the moved
    got = trace(rt, scene, o, d)
    ref = intersect_reference(vw, np.concatenate([t, t + 60]), o, d)
    hit = ref["prim"] >= 0
    assert (got["inst"] == inst).mean() > 0.2 and hit.mean() < 0.95
    assert np.array_equal(got["prim"] >= 0, hit)
    assert np.array_equal(got["inst"][hit], ref["prim"][hit] // 20)
    np.testing.assert_allclose(got["t"][hit], ref["t"][hit], rtol=1e-4)
    # the host's own write: only a changed value crosses
    writes = []
    orig = cl.enqueue_copy
    try:
        cl.enqueue_copy = lambda *a, **kw: writes.append(1) or orig(*a, **kw)
        scene.set_transform(0, np.eye(4))     # unchanged: nothing written
        assert writes == []
        scene.set_transform(0, x0)
        assert writes == [1]
    finally:
        cl.enqueue_copy = orig


def test_normal_transform_is_inverse_transpose(rt):
    """tlas_prep writes each instance's normal rows: the inverse transpose of its linear part
    (float64 reference), for shears and non-uniform scales."""
    from raytrace.scene import TRANSFORM_DTYPE

    rng = np.random.default_rng(3)
    scene = Scene(rt)
    m = scene.add_mesh(np.eye(3, dtype=np.float32), [[0, 1, 2]])
    xs = []
    for _ in range(5):
        a = np.eye(4)
        a[:3, :3] = rotation(rng.normal(size=3), 1.0) @ np.diag(rng.uniform(0.2, 3, 3))
        a[0, 1] += 0.4  # shear
        a[:3, 3] = rng.normal(size=3)
        xs.append(a)
        scene.add_instance(m, a)
    scene.update()
    nrm = rt.to_host(scene.normal_buffer, TRANSFORM_DTYPE, 5)
    for i, a in enumerate(xs):
        want = np.linalg.inv(a[:3, :3]).T
        got = np.stack([nrm[f"r{k}"][i] for k in range(3)])
        np.testing.assert_allclose(got[:, :3], want, rtol=2e-5, atol=2e-6)
        assert (got[:, 3] == 0).all()
