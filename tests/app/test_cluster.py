"""``--workers`` (app.cluster) on a local Ray cluster of 2 CPU slots with PoCL actors: an 8-frame
capture is byte-identical to the single-process one, also when a worker is killed mid-run;
Ctrl-C stops the actors and leaves a playable partial video; a two-point sweep on 2 workers
writes the rows 1 worker writes (timings aside); a missing Ray is one line naming the extra."""

import json
import os
import sys

import pytest

from app import cluster
from app.cli import main
from tests.app.test_capture import SCENE, _decode

ray = pytest.importorskip("ray", reason="Ray is the cluster extra: pip install -e .[test,cluster]")

CAPTURE = ["--frames", "8", "--fps", "10", "--width", "40", "--height", "30", "--seed", "3",
           "--quiet"]
TIMINGS = {"fps", "frame_wall_ms", "kernel_ms", "stages_ms", "date"}


@pytest.fixture(scope="module")
def fault_dir(tmp_path_factory):
    """The actors' fault hook folder (app.cluster.FAULT_ENV): armed by a test, it makes the
    first actor asked for its second frame exit."""
    return tmp_path_factory.mktemp("fault")


@pytest.fixture(scope="module")
def local_ray(fault_dir):
    os.environ[cluster.FAULT_ENV] = str(fault_dir)   # the actors' processes inherit it
    try:
        ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR",
                 log_to_driver=False)
        yield ray
        ray.shutdown()
    finally:
        os.environ.pop(cluster.FAULT_ENV, None)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    p = tmp_path_factory.mktemp("scene") / "s.toml"
    p.write_text(SCENE)
    return p


@pytest.fixture(scope="module")
def single(scene, tmp_path_factory):
    """The single-process capture of the scene (no Ray)."""
    out = tmp_path_factory.mktemp("single") / "one.mp4"
    assert main(["capture", str(scene), "-o", str(out), *CAPTURE]) == 0
    return out.read_bytes()


def _watch(monkeypatch, action):
    """Pool.after_item -> action(pool, done); returns the list of (done, pids of live actors)."""
    seen = []

    def hook(pool, done):
        seen.append((done, sorted(pool.info[a]["pid"] for a in pool.live)))
        action(pool, done)

    monkeypatch.setattr(cluster.Pool, "after_item", hook)
    return seen


def test_capture_on_two_workers_equals_the_single_process_capture(local_ray, scene, single,
                                                                  tmp_path, monkeypatch):
    seen = _watch(monkeypatch, lambda pool, done: None)
    out = tmp_path / "two.mp4"
    assert main(["capture", str(scene), "-o", str(out), "--workers", "2", *CAPTURE]) == 0
    assert out.read_bytes() == single
    assert [d for d, _ in seen] == list(range(1, 9))
    assert len(seen[-1][1]) == 2                        # two actors, two processes


def test_a_worker_killed_mid_run_has_its_frames_rendered_elsewhere(local_ray, fault_dir, scene,
                                                                   single, tmp_path,
                                                                   monkeypatch):
    """The fault hook makes the first actor asked for its second frame exit (os._exit) inside
    that render call: the frame is in flight on a dead process, so it must be rendered again
    by the other actor or a replacement, and the video is still the single-process one."""
    (fault_dir / "arm").write_text("")
    seen = _watch(monkeypatch, lambda pool, done: None)
    out = tmp_path / "killed.mp4"
    assert main(["capture", str(scene), "-o", str(out), "--workers", "2", *CAPTURE]) == 0
    died = [p.name.split("_") for p in fault_dir.glob("died_*")]
    assert len(died) == 1 and not (fault_dir / "arm").exists()   # exactly one actor died
    pid, frame = int(died[0][1]), int(died[0][2])
    assert 1 <= frame < 8
    assert out.read_bytes() == single                  # its frame was rendered again, elsewhere
    assert [d for d, _ in seen] == list(range(1, 9))
    # once its frame was written (re-rendered), the dead actor is no longer among the live ones
    assert all(pid not in pids for done, pids in seen if done > frame)
    assert not (tmp_path / "killed.partial.mp4").exists()


def test_ctrl_c_stops_the_workers_and_leaves_a_playable_partial_video(local_ray, scene,
                                                                      tmp_path, monkeypatch):
    actors = []

    def interrupt(pool, done):
        actors.extend(pool.live)
        if done == 3:
            raise KeyboardInterrupt

    _watch(monkeypatch, interrupt)
    out = tmp_path / "cut.mp4"
    assert main(["capture", str(scene), "-o", str(out), "--workers", "2", *CAPTURE]) == 130
    partial = tmp_path / "cut.partial.mp4"
    assert not out.exists() and len(_decode(partial)[1]) == 3
    with pytest.raises(ray.exceptions.RayActorError):
        ray.get(actors[0].info.remote(), timeout=60)


def test_a_pool_that_cannot_start_leaves_no_partial_file(local_ray, scene, tmp_path, capsys):
    out = tmp_path / "v.mp4"
    assert main(["capture", str(scene), "-o", str(out), "--workers", "3", *CAPTURE]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the Ray cluster has 2 CPUs" in err[0]
    assert list(tmp_path.iterdir()) == []


def _rows(path):
    return [{k: v for k, v in r.items() if k not in TIMINGS and not k.endswith("_ms")}
            for r in json.loads((path / "sweep.json").read_text())["rows"]]


def test_two_point_sweep_on_two_workers_writes_the_rows_of_one(local_ray, scene, tmp_path):
    argv = ["sweep", str(scene), "--cells", "12,20", "--size", "32x24", "--frames", "2",
            "--warmup", "1", "--quiet"]
    for n in ("1", "2"):
        assert main([*argv, "-o", str(tmp_path / n), "--workers", n]) == 0
    one, two = _rows(tmp_path / "1"), _rows(tmp_path / "2")
    assert len(one) == 2 and {r["water_cells"] for r in one} == {"12x12", "20x20"}
    key = lambda r: r["cells"]  # noqa: E731
    assert sorted(two, key=key) == sorted(one, key=key)
    assert all(r["rays_per_frame"] >= 32 * 24 for r in one)
    # resumable as before: a rerun on 2 workers measures nothing
    assert main([*argv, "-o", str(tmp_path / "2"), "--workers", "2"]) == 0
    assert len(_rows(tmp_path / "2")) == 2


def test_missing_ray_is_one_line_naming_the_extra(scene, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)   # import ray -> ImportError
    for cmd in (["capture", str(scene), "-o", str(tmp_path / "v.mp4")],
                ["sweep", str(scene), "-o", str(tmp_path / "s")]):
        assert main([*cmd, "--workers", "2"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "pip install lbwater[cluster]" in err[0]
    assert not (tmp_path / "v.mp4").exists()
