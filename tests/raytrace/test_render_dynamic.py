"""Dynamic meshes written in place: the buffers add_dynamic_mesh hands out are what the BVH
and the shader read (float64 reference after each write), and update() copies nothing."""

import numpy as np
import pyopencl as cl
import pytest

from raytrace import render_reference as ref
from raytrace.render import Renderer, RenderSettings
from raytrace.render_scene import Material, RenderScene
from raytrace.render_types import MESH_DYNAMIC


def grid(n):
    """An n x n vertex grid's triangles (two per cell)."""
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    b, c, d = a + 1, a + n, a + n + 1
    return np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])


def surface(n, phase):
    """A wavy height field over [-1, 1]^2 and its unit normals, as float4 rows."""
    x, z = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n), indexing="ij")
    y = 0.15 * np.sin(3 * x + phase) * np.cos(2 * z)
    dydx = 0.45 * np.cos(3 * x + phase) * np.cos(2 * z)
    dydz = -0.3 * np.sin(3 * x + phase) * np.sin(2 * z)
    v = np.zeros((n * n, 4), np.float32)
    v[:, 0], v[:, 1], v[:, 2] = x.ravel(), y.ravel(), z.ravel()
    nrm = np.stack([-dydx.ravel(), np.ones(n * n), -dydz.ravel()], 1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    out = np.zeros((n * n, 4), np.float32)
    out[:, :3] = nrm
    return v, out


def water_scene(rt, n):
    sc = RenderScene(rt)
    water = sc.add_material(Material(diffuse=(0.1, 0.3, 0.4), specular=(0.5, 0.5, 0.5),
                                     shininess=50, reflectivity=0.3))
    floor = sc.add_material(Material(diffuse=(0.8, 0.7, 0.5)))
    mesh, vbuf, nbuf = sc.add_dynamic_mesh(n * n, grid(n), material=water)
    sc.add_instance(mesh)
    fv = np.array([[-2, -0.5, -2], [2, -0.5, -2], [2, -0.5, 2], [-2, -0.5, 2]], np.float32)
    sc.add_instance(sc.add_mesh(fv, [[0, 2, 1], [0, 3, 2]], material=floor))
    sc.add_light("directional", direction=(-0.3, -1, -0.2), color=(1, 1, 1))
    return sc, mesh, vbuf, nbuf


def test_dynamic_mesh_is_read_in_place_and_never_copied(rt, monkeypatch):
    n = 8
    sc, mesh, vbuf, nbuf = water_scene(rt, n)
    assert sc.meshes[mesh]["flags"] & MESH_DYNAMIC
    assert sc.scene.mesh_record(mesh).vertices_buf is vbuf  # the BVH reads the same buffer
    r = Renderer(rt, sc, RenderSettings(width=16, height=12, bounces=1))
    r.set_camera((0.3, 1.6, 2.4), (0, 0, 0), (0, 1, 0), 50)
    copies = []
    real_copy = cl.enqueue_copy
    for frame, phase in enumerate((0.0, 1.3)):
        v, nrm = surface(n, phase)  # the "writer": fills the handed-out buffers
        cl.enqueue_copy(rt.queue, vbuf, v)
        cl.enqueue_copy(rt.queue, nbuf, nrm)
        monkeypatch.setattr(cl, "enqueue_copy",
                            lambda *a, f=frame, **kw: copies.append(f) or real_copy(*a, **kw))
        sc.update()
        monkeypatch.setattr(cl, "enqueue_copy", real_copy)
        r.enqueue_frame(update_scene=False)
        fb = r.read_framebuffer()
        tables = sc.tables()
        np.testing.assert_array_equal(tables["meshes"][mesh]["vertices"], v[:, :3])
        out = ref.render(tables, r.camera, r.params(), sc.lights)
        ok = ~out["fragile"]
        assert ok.mean() > 0.9
        err = np.abs(fb - out["framebuffer"]).max(axis=2)
        scale = np.maximum(1.0, out["framebuffer"].max(axis=2))
        assert np.all(err[ok] <= 2e-4 * scale[ok]), f"frame {frame}: max error {err[ok].max()}"
    # the first update uploads the static tables; later frames copy nothing at all
    assert copies and set(copies) == {0}


def test_second_dynamic_mesh_moves_the_first_with_its_contents(rt):
    sc = RenderScene(rt)
    a, va, na = sc.add_dynamic_mesh(9, grid(3))
    v, nrm = surface(3, 0.5)
    cl.enqueue_copy(rt.queue, va, v)
    cl.enqueue_copy(rt.queue, na, nrm)
    b, vb, nb = sc.add_dynamic_mesh(16, grid(4), normals=False)
    assert nb is None
    va2, na2 = sc.dynamic_buffers(a)
    assert va2 is not va and sc.dynamic_buffers(b)[0] is vb
    align = rt.device.mem_base_addr_align // 8
    assert (16 * sc.meshes[b]["dyn_offset"]) % align == 0 and sc.meshes[b]["dyn_offset"] >= 9
    np.testing.assert_array_equal(rt.to_host(va2, np.float32, 36).reshape(9, 4), v)
    np.testing.assert_array_equal(rt.to_host(na2, np.float32, 36).reshape(9, 4), nrm)
    assert sc.scene.mesh_record(a).vertices_buf is va2
    with pytest.raises(ValueError, match="not made by add_dynamic_mesh"):
        sc.dynamic_buffers(5)
    with pytest.raises(ValueError, match=r"indices must lie in \[0, 8\]"):
        sc.add_dynamic_mesh(9, [[0, 1, 9]])
