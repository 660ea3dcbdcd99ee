"""The window's shared display path (app.ext_share): where the device offers it, a frame reaches
the GL texture exactly with no host copy; where it does not (PoCL, Mesa), one line says why and
the window falls back to the copy path. The World's display hook is checked with a stand-in
target on any device."""

import numpy as np
import pyopencl as cl
import pytest

from app.errors import InputError
from app.ext_share import ExternalShareError, ExternalTargets, device_uuid, missing_cl
from app.scene import parse_scene
from app.window import Presenter, attach_display, display_path
from app.world import World
from tests.app.test_frame_pipeline import TINY
from tests.transfer_counter import TransferCounter


@pytest.fixture(scope="module")
def gl(gl_ctx):
    return gl_ctx


def _shared_or_reason(gl, rt, size):
    try:
        return ExternalTargets(gl, rt, size), None
    except ExternalShareError as exc:
        return None, str(exc)


def test_unavailable_shared_path_says_why_in_one_line(gl, rt):
    targets, why = _shared_or_reason(gl, rt, (32, 16))
    if targets is not None:
        targets.release()
        assert not missing_cl(rt.device)
        return
    assert "\n" not in why and why
    if missing_cl(rt.device):   # PoCL: the extensions are named
        assert why.startswith("no cl_khr_external_memory")
        with pytest.raises(ExternalShareError, match="no device UUID"):
            device_uuid(rt.device)


def test_display_path_text_names_the_path_and_the_reason():
    assert display_path("shared").startswith("shared")
    assert display_path("pbo") == "copy (2 in flight, pixel-buffer upload)"
    text = display_path("auto", "no cl_khr_external_memory on X")
    assert text == ("copy (2 in flight, pixel-buffer upload); shared path unavailable: "
                    "no cl_khr_external_memory on X")
    assert display_path("direct").startswith("copy (2 in flight, direct upload)")


def test_attach_display_falls_back_or_refuses_in_one_line(gl, rt, tmp_path):
    world = World(parse_scene(TINY, tmp_path / "t.toml"), rt)
    try:
        targets, path = attach_display(world, gl, "auto")
        if targets is None:
            assert "shared path unavailable" in path
            with pytest.raises(InputError, match="--upload shared: unavailable here"):
                attach_display(world, gl, "shared")
        else:
            assert path.startswith("shared")
            targets.release()
        assert attach_display(world, gl, "pbo") == (None, display_path("pbo"))
    finally:
        world.close()


def test_shared_path_draws_the_frame_exactly(gl, rt):
    """Runs where the shared path exists (the NVIDIA H200's OpenCL and GL, BENCHMARKS.md);
    PoCL and Mesa offer no external memory, which the test above checks instead."""
    targets, why = _shared_or_reason(gl, rt, (64, 48))
    if targets is None:
        pytest.skip(f"no shared path on this device: {why}")
    frame = np.random.default_rng(5).integers(0, 256, (48, 64, 4), dtype=np.uint8)
    frame[..., 3] = 255
    buf = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR,
                    hostbuf=frame)
    p = Presenter(gl, "pbo")
    try:
        for _ in range(3):   # both slots, then the first again
            with TransferCounter() as c:
                p.upload(targets.enqueue(rt.queue, buf).wait())
            assert c.bytes == 0
            np.testing.assert_array_equal(p.snapshot((64, 48)), frame)
    finally:
        p.reset()
        targets.release()


class _DeviceTargets:
    """A stand-in for ExternalTargets on any device: frames copied into a device buffer."""

    class Frame:
        def __init__(self, event, buf, size):
            self.event, self.buf, self.size = event, buf, size

        def wait(self):
            self.event.wait()
            return self

    def __init__(self, rt, size):
        self.rt, self.size = rt, size
        self.buf = rt.buffer(size[0] * size[1] * 4)
        self.calls = 0

    def enqueue(self, queue, rgba):
        self.calls += 1
        evt = cl.enqueue_copy(queue, self.buf, rgba, byte_count=self.size[0] * self.size[1] * 4)
        return self.Frame(evt, self.buf, self.size)


def test_world_with_a_display_sends_frames_there_and_reads_none_back(rt, tmp_path):
    scene = parse_scene(TINY, tmp_path / "t.toml")
    with World(scene, rt) as plain:
        want = [plain.frame(1 / 30) for _ in range(3)]
    with World(scene, rt) as world:
        targets = _DeviceTargets(rt, world.size)
        world.set_display(targets)
        got = []
        with TransferCounter() as c:
            for _ in range(3):
                world.enqueue_frame(1 / 30)
                _, frame = world.read_frame(copy=False)
                assert isinstance(frame, _DeviceTargets.Frame)
                got.append(rt.to_host(frame.buf, np.uint8, frame.buf.size).reshape(want[0].shape))
        # per frame only the scalars cross, no image bytes (the test's own reads excepted)
        assert c.bytes - sum(g.nbytes for g in got) <= 3 * 4096
        assert targets.calls == 3
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, w)
        world.set_display(None)
        world.enqueue_frame(1 / 30)
        assert isinstance(world.read_frame()[1], np.ndarray)
        with pytest.raises(ValueError, match="targets of"):
            world.set_display(_DeviceTargets(rt, (8, 8)))
