"""The frame as a pipeline of device stages (docs/frame_api.md): per frame only the RGBA8 image
and a few scalars cross to the host, frames are deterministic, stats arrive a frame late, and
long runs keep host memory and the event ring flat."""

import ast
import dataclasses
import resource
from pathlib import Path

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest

from app.scene import load_scene, parse_scene
from app.world import World
from tests.transfer_counter import HOST_PATHS, TransferCounter, check_complete

ROOT = Path(__file__).resolve().parents[2]

TINY = """
[render]
width = 24
height = 16
bounces = 2

[camera]
eye = [0.5, 1.2, -0.2]
target = [0.5, 0.0, 0.5]

[water]
size = [1.0, 1.0]
cells = [16, 16]
depth = 0.2

[water.rain]
rate = 30
radius = 0.08
height = 0.01

[[lights]]
kind = "directional"
direction = [-0.3, -1.0, 0.2]

[pool]
steps = 0
wall_height = 0.3
deck = 0.2
"""


@pytest.fixture
def tiny(tmp_path):
    return parse_scene(TINY, tmp_path / "tiny.toml")


# ---- the counter itself ---------------------------------------------------------------------
def test_counter_classifies_every_pyopencl_enqueue_function():
    check_complete()
    assert set(HOST_PATHS) >= {"_enqueue_read_buffer", "_enqueue_write_buffer",
                               "enqueue_map_buffer"}


def test_counter_sees_each_host_path(rt):
    q = rt.queue
    buf = rt.buffer(4096)
    host = np.zeros(256, np.float32)
    with TransferCounter() as c:
        steps = [
            ("write", lambda: cl.enqueue_copy(q, buf, host)),
            ("read", lambda: cl.enqueue_copy(q, host, buf)),
            ("read nonblocking", lambda: cl.enqueue_copy(q, host, buf, is_blocking=False)
             .wait()),
            ("read rect", lambda: cl.enqueue_copy(
                q, host, buf, buffer_origin=(0, 0), host_origin=(0, 0), region=(64, 2),
                buffer_pitches=(64,), host_pitches=(64,))),
            ("write rect", lambda: cl.enqueue_copy(
                q, buf, host, buffer_origin=(0, 0), host_origin=(0, 0), region=(64, 2),
                buffer_pitches=(64,), host_pitches=(64,))),
            ("fill", lambda: cl.enqueue_fill_buffer(q, buf, np.float32(0), 0, 1024)),
            ("map", lambda: cl.enqueue_map_buffer(q, buf, cl.map_flags.READ, 0, (16,),
                                                  np.float32)[0].base.release()),
            ("array set", lambda: cla.to_device(q, host)),
            ("array get", lambda: cla.zeros(q, 16, np.float32).get()),
            ("runtime to_device", lambda: rt.to_device(host)),
        ]
        for what, fn in steps:
            before = (len(c.calls), len(c.buffers), c.bytes)
            fn()
            q.finish()
            after = (len(c.calls), len(c.buffers), c.bytes)
            assert after[0] + after[1] > before[0] + before[1], f"{what}: not counted"
            assert after[2] > before[2], f"{what}: no bytes counted"
        c.reset()
        cl.enqueue_copy(q, rt.buffer(64), buf, byte_count=64)  # device to device: not counted
        q.finish()
        assert c.bytes == 0


def test_no_module_moves_host_bytes_around_the_counted_paths():
    """Host-initialised buffers are made only in kernels/runtime.py (where the counter hooks);
    pyopencl.array is used only by a benchmark comparing against pyopencl's sort."""
    allowed = {"kernels/runtime.py", "kernels/layout.py", "app/bench_bvh.py"}
    offenders = []
    for pkg in ("app", "lbm", "raytrace", "kernels"):
        for path in sorted((ROOT / pkg).glob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel in allowed:
                continue
            tree = ast.parse(path.read_text())
            for node in ast.walk(tree):
                if isinstance(node, ast.Attribute) and node.attr in ("COPY_HOST_PTR",
                                                                      "USE_HOST_PTR"):
                    offenders.append(f"{rel}:{node.lineno} makes a buffer from host memory")
                if isinstance(node, ast.keyword) and node.arg == "hostbuf":
                    offenders.append(f"{rel}:{node.lineno} passes hostbuf=")
                if isinstance(node, ast.Import | ast.ImportFrom):
                    names = [a.name for a in node.names] + [getattr(node, "module", "") or ""]
                    if any("pyopencl.array" in n for n in names):
                        offenders.append(f"{rel}:{node.lineno} imports pyopencl.array")
    assert not offenders, offenders


# ---- per frame: the image and a few scalars --------------------------------------------------
@pytest.mark.parametrize("light_buffer", [None, 48])
def test_pool_frames_move_only_the_image_and_scalars(rt, light_buffer):
    """20 frames of scenes/pool.toml (the floating sailboat, caustics, rain on, a drop, a moving
    camera), with the device's light buffer (none on a CPU) and with one (built every frame
    from the boat's device-written transform row)."""
    from app.frames import with_shading

    scene = with_shading(load_scene(ROOT / "scenes" / "pool.toml"),
                         {"caustics": "traced", "caustic_photons": 4096})
    assert scene.boats, "the pool floats a boat: its bodies stage runs in every frame"
    world = World(scene, rt, width=40, height=24, cells=40, water_steps=0,
                  light_buffer=light_buffer)
    world.set_rain(20.0)
    world.frame(1 / 60)  # the first frame uploads tables and builds layouts
    image = 40 * 24 * 4
    with TransferCounter() as c:
        eye, target, up, fov = world.camera
        for i in range(20):
            world.set_camera((eye[0] + 0.02 * i, eye[1], eye[2]), target, up, fov)
            if i == 5:
                world.add_drop(1.0, 1.0, 0.2, 0.02)
            world.enqueue_frame(1 / 60)
            if i:
                world.read_frame()
        world.drain()
        per_frame = c.bytes / 20
        scalars = [b for name, b in c.calls if b != image]
    assert not c.buffers, f"buffers made from host data inside frames: {c.buffers}"
    assert image <= per_frame <= image + 4096, (per_frame, c.calls[:12])
    assert max(scalars, default=0) <= 1024, "only scalars besides the image"
    assert world.stats.frame == 20 and world.stats.guard["nan"] is False
    assert world.stats.stage_ms.get("lbm.bodies", 0) > 0
    assert world.stats.stage_ms.get("caustics.photons", 0) > 0
    if light_buffer:
        assert world.stats.stage_ms.get("render.light_buffer.raster", 0) > 0


def test_a_frame_reads_its_image_counts_and_guard_once(tiny, rt):
    """A frame's device-to-host copies: the image, the ray counts and the guard record, one
    each (the solver's own read after each check and the renderer's own count read are left to
    the World's pinned rings)."""
    from lbm.structs import GUARD_DTYPE
    from raytrace.render_types import STATS_LEN

    world = World(tiny, rt, frames_in_flight=2)
    image = world.frame(1 / 60).nbytes
    with TransferCounter() as c:
        for _ in range(4):
            world.enqueue_frame(1 / 60)
            world.read_frame()
        world.drain()
    sizes = sorted(b for _, b in c.calls)
    assert sizes == sorted([image, 4 * STATS_LEN, GUARD_DTYPE.itemsize] * 4), c.calls
    # the record read is the copy each frame's last check made; a frame without steps copies
    # the record as it stands (a drop's volume in it)
    world.frame(0.2)
    assert world.stats.lbm_steps > 0
    before = world.stats.guard["volume_sources"]
    world.add_drop(0.4, 0.6, 0.2, 0.03)
    world.frame(0.0)
    assert world.stats.lbm_steps == 0
    assert world.stats.guard["volume_sources"] > before
    live = world.sim.guard_record()    # still read on demand
    assert live["checks"] > 0 and live["sources"] == pytest.approx(
        world.stats.guard["volume_sources"] / world.sim.dx ** 2, rel=1e-6)


# ---- determinism -----------------------------------------------------------------------------
def _run(scene, rt, n, *, drop_at=2):
    world = World(scene, rt)
    images = []
    for i in range(n):
        if i == drop_at:
            world.add_drop(0.4, 0.6, 0.2, 0.03)
        images.append(world.frame(1 / 30))
    return world, images


def test_frames_rendered_twice_from_one_start_are_byte_identical(tiny, rt):
    _, a = _run(tiny, rt, 6)
    _, b = _run(tiny, rt, 6)
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        assert np.array_equal(x, y), f"frame {i} differs"
    assert not np.array_equal(a[0], a[-1]), "the water should move"


def test_a_frame_rendered_alone_equals_the_same_frame_in_a_run(tiny, rt):
    """No dependence on the previous frame's ray counts: frame 5 rendered after the water was
    advanced without rendering equals frame 5 of a run that rendered every frame."""
    _, run = _run(tiny, rt, 6)
    world = World(tiny, rt)
    for i in range(5):
        if i == 2:
            world.add_drop(0.4, 0.6, 0.2, 0.03)
        world.advance(1 / 30)
    alone = world.frame(1 / 30)
    assert np.array_equal(alone, run[5])


# ---- time, stats a frame late -----------------------------------------------------------------
def test_simulated_time_follows_frame_time(tiny, rt):
    world = World(tiny, rt)
    dt = world.sim.dt
    fps = 60.0
    assert abs(round(1 / fps / dt) - 1 / fps / dt) > 0.05, "pick an fps that does not divide dt"
    for _ in range(30):
        world.enqueue_frame(1 / fps)
        world.read_frame()
    assert abs(world.sim_time - 30 / fps) < dt


def test_stats_are_the_last_completed_frame(tiny, rt):
    world = World(tiny, rt, frames_in_flight=2)
    assert world.stats is None
    world.enqueue_frame(0.05)
    world.enqueue_frame(0.05)
    assert world.stats is None, "nothing has been read yet: no frame is complete"
    i, img = world.read_frame()
    assert i == 0 and world.stats.frame == 0
    assert img.shape == (16, 24, 4)
    st = world.stats
    assert st.lbm_steps >= 1 and st.stage_ms["lbm.step"] > 0 and st.kernel_ms > 0
    # the device span: the kernels one after another on one queue, with the gaps between them
    assert st.device_span_ms >= st.kernel_ms * (1 - 1e-9)
    assert st.device_span_ms <= st.wall_ms + 5.0   # inside the host's enqueue-to-image time
    assert st.n_rays >= 24 * 16 and st.rays_per_depth[0] == 24 * 16
    assert st.n_triangles > 0 and st.device_bytes > 0 and st.water_cells == (16, 16)
    world.enqueue_frame(0.05)  # a third frame waits for neither of the two in flight
    world.drain()
    assert world.stats.frame == 2
    assert dataclasses.is_dataclass(st)


def test_read_frame_without_copy_is_the_pinned_buffer_with_the_frames_bytes(tiny, rt):
    """The window's read (copy=False) hands over the pinned read-back array itself, holding the
    same bytes a copying read of the same frame returns; no new array per frame."""
    ref = World(tiny, rt).frame(1 / 30)
    world = World(tiny, rt, frames_in_flight=2)
    pinned = world._rings["image"]._arrays
    world.enqueue_frame(1 / 30)
    world.enqueue_frame(1 / 30)
    i, img = world.read_frame(copy=False)
    assert i == 0 and any(img is a for a in pinned)
    assert np.array_equal(img, ref)
    kept = img.copy()
    world.enqueue_frame(1 / 30)   # reuses frame 0's slot: the view now holds frame 2
    _, img1 = world.read_frame(copy=False)
    _, img2 = world.read_frame(copy=False)
    assert img2 is img and img1 is not img and not np.array_equal(img, kept)
    world.enqueue_frame(1 / 30)
    _, copied = world.read_frame()
    assert not any(np.shares_memory(copied, a) for a in pinned)


def test_pick_hits_the_live_water_where_the_tracer_says(tiny, rt):
    from raytrace import intersect

    world = World(tiny, rt)
    world.add_drop(0.5, 0.5, 0.3, 0.05)
    world.frame(0.0)
    p = world.pick(12, 9)
    assert p is not None and p.water
    f = world.water_fields()
    # the pool point lies on the water surface: compare with a trace of the same ray against
    # the water mesh built from the solver's fields on the host
    import lbm

    nx, ny, dx = world.sim.nx, world.sim.ny, world.sim.dx
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny))
    V = np.stack([(ii + 0.5) * dx, (f["bed"] + f["h"]), (jj + 0.5) * dx], -1).reshape(-1, 3)
    eye = np.asarray(world.camera[0])
    d = np.asarray(p.point) - eye
    hit = intersect(V, lbm.grid_triangles(nx, ny), eye[None], d[None], device=rt)
    assert hit["hit"][0] and abs(hit["t"][0] - 1.0) < 1e-3


# ---- long runs stay flat -----------------------------------------------------------------------
def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def test_long_step_loops_and_frame_runs_keep_memory_and_the_ring_flat(tiny, rt):
    world = World(tiny, rt, width=8, height=8)
    timer = rt.timer
    for _ in range(2000):
        world.sim.step(1)
    rss0 = _rss_mb()
    for _ in range(10_000):
        world.sim.step(1)
    assert timer.pending() <= timer.max_events
    for _ in range(300):
        world.enqueue_frame(1 / 60)
        world.read_frame()
    rss1 = _rss_mb()
    for _ in range(1700):
        world.enqueue_frame(1 / 60)
        world.read_frame()
    rss2 = _rss_mb()
    assert timer.pending() <= timer.max_events + 200
    assert rss2 - rss1 < 8, f"host memory grew {rss2 - rss1:.1f} MB over 1700 frames"
    assert rss1 - rss0 < 64
    assert world.stats.frame == 1999
