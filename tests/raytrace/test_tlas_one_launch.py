"""The TLAS of a few instances built in one launch (kernels/bvh_tlas.cl tlas_build_one_group)
is the five-launch build's TLAS byte for byte: instance records, normal transforms, nodes, leaf
order and header, for instance counts around the powers of two of its bitonic sort, with equal
Morton keys (instances at one place), an empty mesh and a height field among them."""

import re

import numpy as np
import pytest

from app.meshes import height_field_grid
from kernels.runtime import KERNEL_DIR
from raytrace import Scene
from raytrace.bvh import INFO_DTYPE, INSTANCE_DTYPE, NODE_DTYPE, node_count
from raytrace.scene import TLAS_LEAF_SIZE, TLAS_ONE_LAUNCH, TRANSFORM_DTYPE
from tests.raytrace.test_render_plans import BOX

INFO_PAD = INFO_DTYPE.fields["pad"][1]


def test_defines_mirror_the_kernel():
    src = (KERNEL_DIR / "bvh_tlas.cl").read_text()
    for name, value in (("TLAS_ONE_LAUNCH", TLAS_ONE_LAUNCH), ("TLAS_LEAF_SIZE", TLAS_LEAF_SIZE)):
        assert re.search(rf"#define {name} {value}\b", src), name


def build(rt, n, one_launch: bool, seed=3):
    rng = np.random.default_rng(seed)
    scene = Scene(rt)
    scene.tlas_one_launch = TLAS_ONE_LAUNCH if one_launch else 0
    meshes = [scene.add_mesh(*BOX), scene.add_mesh(*height_field_grid(9))]
    v, t = height_field_grid(5)
    meshes.append(scene.add_mesh(v, t, grid=(5, 5)))
    for i in range(n):
        m = np.eye(4)
        a = rng.uniform(0, 2 * np.pi)
        m[:3, :3] = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0],
                              [-np.sin(a), 0, np.cos(a)]]) * rng.uniform(0.2, 2.0)
        # a third of them at one of three places: equal Morton keys, ordered by index
        m[:3, 3] = rng.uniform(-5, 5, 3) if i % 3 else [(i % 9) - 4.0, 0.5, 1.0]
        scene.add_instance(meshes[i % len(meshes)], m)
    scene.update()
    return scene


def snapshot(scene):
    rt, n = scene.rt, scene.n_instances
    return {"instances": rt.to_host(scene.instances, INSTANCE_DTYPE, n).tobytes(),
            "normals": rt.to_host(scene.normal_buffer, TRANSFORM_DTYPE, n).tobytes(),
            "nodes": rt.to_host(scene.tlas_nodes, NODE_DTYPE, node_count(n)).tobytes(),
            "order": rt.to_host(scene.tlas_prims, np.uint32, n).tobytes(),
            # the header without its padding (never written)
            "info": rt.to_host(scene.tlas_info, INFO_DTYPE, 1).tobytes()[:INFO_PAD]}


@pytest.mark.parametrize("n", [1, 2, 3, 31, 64, 65, 200, TLAS_ONE_LAUNCH])
def test_one_launch_builds_the_five_launch_tlas(rt, n):
    one, five = build(rt, n, True), build(rt, n, False)
    a, b = snapshot(one), snapshot(five)
    for key in a:
        assert a[key] == b[key], key
    info = one.rt.to_host(one.tlas_info, INFO_DTYPE, 1)[0]
    assert info["root"] >= 0 and info["n_prims"] == n
    # moved instances, rebuilt: still the same
    for scene in (one, five):
        scene.set_transform(0, np.diag([1.0, 2.0, 1.0, 1.0]))
        scene.update()
    assert snapshot(one) == snapshot(five)


def test_more_instances_take_the_five_launches(rt):
    scene = build(rt, TLAS_ONE_LAUNCH + 1, True)
    assert scene.n_instances > scene.tlas_one_launch
    info = scene.rt.to_host(scene.tlas_info, INFO_DTYPE, 1)[0]
    assert info["root"] >= 0 and info["n_prims"] == TLAS_ONE_LAUNCH + 1
