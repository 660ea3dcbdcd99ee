"""Captures and sweeps over several GPUs or machines with Ray (optional: ``pip install
lbwater[cluster]``).

    lbwater capture scenes/timeline.toml -o pool.mp4 --workers 4            # 4 GPUs, this machine
    lbwater capture scenes/timeline.toml -o pool.mp4 --workers 8 --ray-address HOST:6379
    lbwater sweep scenes/pool.toml --cells 256,512,1024 --workers 4 -o out/sweep

**Capture.** The water is sequential in time, so this process steps it alone: a World that
renders nothing (``World.snapshot_frame``) turns each frame into a compact snapshot (surface
heights, transform rows, camera, caustic map; app.snapshot). One Ray actor per GPU
(``num_gpus=1``; one per CPU slot when the cluster has no GPU or ``--device cpu``) holds a World
of the same scene and settings, primed with frame 0's snapshot, and renders the frames it is
handed (``World.render_snapshot``): the same mesh launch, BVH topology and render as the
single-process capture, so the video is byte-identical to it on the same kind of device. Each
actor has at most two frames queued; frames return in any order and are written in order, and
no more than ``4 * workers`` frames are stepped and not yet written (memory stays flat).

**Sweep.** Each point runs on one actor (``app.sweep.measure``), one point per device at a time:
actors on one CPU share a device and take turns; GPUs run in parallel.

**Faults.** A worker that dies (its process or node) has its frames (or point) handed to the
others, and a replacement actor is started while the budget lasts (``--workers`` replacements);
work stops with an error only when no worker is left. Ctrl-C stops the actors (and the local
Ray instance this process started) and, for a capture, leaves the partial video playable.
"""

from __future__ import annotations

import contextlib
import os
import time

from app.errors import InputError, LbwaterError

INSTALL = "pip install lbwater[cluster]"
#: frames one actor holds at once (one rendering, one queued behind it)
PER_ACTOR = 2


class ClusterError(LbwaterError):
    """The cluster cannot do the work: every worker died, or none could be started."""


def import_ray():
    """The ``ray`` module, or one InputError naming the extra to install."""
    try:
        import ray
    except ImportError:
        raise InputError(f"--workers needs Ray, an optional dependency: {INSTALL}") from None
    return ray


def check_workers(workers) -> int:
    if workers is None or not 1 <= int(workers) <= 4096:
        raise InputError(f"--workers {workers} is out of range; allowed [1, 4096]")
    return int(workers)


def _wants_cpu(device: str | None) -> bool:
    return bool(device) and device.strip().lower() in ("cpu", "pocl", "portable")


# ---- the actor ----------------------------------------------------------------------------
#: test hook: a folder; the first actor asked for its second frame while FOLDER/arm exists takes
#: it (an atomic rename to FOLDER/died_PID_FRAME) and its process exits at once, so that frame
#: is in flight on a dead worker (tests/app/test_cluster.py)
FAULT_ENV = "LBWATER_TEST_WORKER_EXIT"


def _fault_hook(rendered: int, index: int) -> None:
    folder = os.environ.get(FAULT_ENV)
    if not folder or rendered < 2:
        return
    try:
        os.rename(os.path.join(folder, "arm"),
                  os.path.join(folder, f"died_{os.getpid()}_{index}"))
    except OSError:   # not armed, or another actor took it
        return
    os._exit(1)


class Worker:
    """One Ray actor: one OpenCL device and, for a capture, a World that renders snapshots.

    ``device``: the user's ``--device`` (None: the actor's GPU when Ray gave it one, else the
    default device). For a capture: the scene file, the World's keyword arguments and frame 0's
    snapshot."""

    def __init__(self, device: str | None, scene_path: str | None = None,
                 kw: dict | None = None, first: bytes | None = None):
        from kernels import get_runtime

        os.environ.setdefault("POCL_AFFINITY", "0")
        self.rt = get_runtime(self._device_spec(device))
        self.world = None
        if scene_path is not None:
            from app.frames import open_world
            from app.scene import load_scene

            self.world = open_world(load_scene(scene_path), self.rt, **(kw or {}))
            self.world.render_snapshot(first, image=False)   # frame 0's BVH topology

    @staticmethod
    def _device_spec(device: str | None) -> str | None:
        """The GPU Ray assigned (its index among this node's OpenCL GPUs) unless the driver
        already hides the others (CUDA_VISIBLE_DEVICES) or the user named a device."""
        import ray

        ids = ray.get_gpu_ids()
        if not ids or (device and device.strip().lower() not in ("gpu", "default", "auto")):
            return device
        from kernels.device import list_devices

        gpus = [d for d in list_devices() if d.type == "GPU"]
        if len(gpus) <= 1:
            return device or "gpu"
        return gpus[int(ids[0]) % len(gpus)].spec

    def info(self) -> dict:
        import ray

        ctx = ray.get_runtime_context()
        ids = [str(i) for i in ray.get_gpu_ids()]
        return {"device": self.rt.name, "node": ctx.get_node_id(), "pid": os.getpid(),
                "gpus": ids, "size": None if self.world is None else self.world.size,
                "key": f"{ctx.get_node_id()}/{self.rt.name}/{','.join(ids) or 'cpu'}"}

    def render(self, index: int, snap: bytes):
        """Frame ``index`` from its snapshot: (index, RGBA8 image)."""
        self.rendered = getattr(self, "rendered", 0) + 1
        _fault_hook(self.rendered, index)
        return index, self.world.render_snapshot(snap)

    def measure(self, scene_path: str, point: dict) -> dict:
        """One sweep point (app.sweep.measure) on this actor's device."""
        from app.scene import load_scene
        from app.sweep import measure

        return measure(load_scene(scene_path), self.rt, **point)


# ---- the pool of actors ---------------------------------------------------------------------
class Pool:
    """Ray actors doing one job: connects (or starts a local Ray), starts ``workers`` actors,
    replaces dead ones within a budget, and kills them all on :meth:`close`."""

    #: test hook: called as ``hook(pool, done)`` after each finished item (frame written, point
    #: saved); the fault tests kill an actor from it
    after_item = None

    def __init__(self, workers: int, *, address: str | None = None, device: str | None = None,
                 capture: tuple | None = None, start_timeout: float = 600.0):
        self.ray = ray = import_ray()
        self.workers, self.device = check_workers(workers), device
        self.start_timeout = start_timeout
        self._started_ray = False
        self.live: list = []         # actors that answered info()
        self.starting: dict = {}     # info ref -> actor
        self.info: dict = {}         # actor -> info dict
        if not ray.is_initialized():
            kw = {"include_dashboard": False, "logging_level": "ERROR",
                  "log_to_driver": False}
            try:
                ray.init(address=address, **kw)
            except (ConnectionError, ValueError, RuntimeError) as exc:
                where = f"--ray-address {address!r}" if address else "a local Ray instance"
                raise InputError(f"{where}: cannot connect ({str(exc).splitlines()[0]})") \
                    from None
            self._started_ray = True
        res = ray.cluster_resources()
        gpus = int(res.get("GPU", 0))
        self.use_gpus = gpus > 0 and not _wants_cpu(device)
        have = gpus if self.use_gpus else int(res.get("CPU", 0))
        what = "GPUs" if self.use_gpus else "CPUs"
        if self.workers > have:
            self.close()
            raise InputError(f"--workers {self.workers}: the Ray cluster has {have} {what}")
        opts = {"num_gpus": 1} if self.use_gpus else {"num_cpus": 1}
        self._cls = ray.remote(Worker).options(max_restarts=0, max_task_retries=0, **opts)
        self._args = ()
        if capture is not None:   # one copy of frame 0's snapshot in the object store
            self._args = (capture[0], capture[1], ray.put(capture[2]))
        self.replacements = self.workers
        try:
            for _ in range(self.workers):
                self._start()
            self._wait_started(all_of=True)
        except BaseException:     # Ctrl-C or a worker that cannot start: stop them all
            self.close()
            raise

    def _start(self) -> None:
        a = self._cls.remote(self.device, *self._args)
        self.starting[a.info.remote()] = a

    def _wait_started(self, all_of: bool = False, timeout: float = 0.0) -> None:
        """Move started actors to :attr:`live` (all of them, or those ready within
        ``timeout``); an actor that failed to start raises its error (a bad scene or device)."""
        ray = self.ray
        deadline = time.monotonic() + (self.start_timeout if all_of else timeout)
        while self.starting:
            left = max(0.0, deadline - time.monotonic())
            ready, _ = ray.wait(list(self.starting), num_returns=1, timeout=left)
            if not ready:
                if all_of:
                    raise ClusterError(f"{len(self.starting)} Ray workers did not start in "
                                       f"{self.start_timeout:g} s (resources busy?)")
                return
            a = self.starting.pop(ready[0])
            try:
                self.info[a] = ray.get(ready[0])
            except ray.exceptions.RayActorError as exc:
                if getattr(exc, "actor_init_failed", False):   # the scene, the device...
                    last = str(exc).strip().splitlines()[-1].strip()
                    raise ClusterError(f"a Ray worker failed to start: {last}") from None
                if all_of:
                    raise ClusterError(f"a Ray worker died while starting: "
                                       f"{str(exc).strip().splitlines()[0]}") from None
                if self.replacements > 0:   # a replacement that died: try another
                    self.replacements -= 1
                    self._start()
                continue
            self.live.append(a)

    def lost(self, actor) -> None:
        """``actor`` died: drop it and start a replacement while the budget lasts."""
        if actor in self.live:
            self.live.remove(actor)
            self.info.pop(actor, None)
            if self.replacements > 0:
                self.replacements -= 1
                self._start()

    def ensure_live(self) -> None:
        """Wait for a replacement when no worker is left; ClusterError when none comes."""
        self._wait_started()
        if not self.live:
            if not self.starting:
                raise ClusterError("every Ray worker died; no replacement left to start")
            self._wait_started(timeout=self.start_timeout)
            if not self.live:
                raise ClusterError("every Ray worker died and no replacement started in "
                                   f"{self.start_timeout:g} s")

    def is_death(self, exc: BaseException) -> bool:
        ex = self.ray.exceptions
        return isinstance(exc, ex.RayActorError | getattr(ex, "ActorUnavailableError", ()))

    def close(self) -> None:
        ray = self.ray
        for a in [*self.live, *self.starting.values()]:
            with contextlib.suppress(Exception):
                ray.kill(a, no_restart=True)
        self.live, self.starting = [], {}
        if self._started_ray:
            with contextlib.suppress(Exception):
                ray.shutdown()
            self._started_ray = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _cause(exc: BaseException) -> BaseException:
    """The user's error inside a Ray error (InputError, DeviceError, ...), else the error."""
    cause = getattr(exc, "cause", None) or getattr(exc, "__cause__", None)
    return cause if isinstance(cause, Exception) else exc


# ---- capture --------------------------------------------------------------------------------
def render_frames(pool: Pool, n: int, snapshot_of, *, max_ahead: int | None = None):
    """Yield ``(i, image, snapshot)`` for i = 0..n-1 in order. ``snapshot_of(i)`` steps the
    water and returns frame i's snapshot (called in order, at most ``max_ahead`` frames ahead
    of the last one yielded); the actors render them in any order."""
    ray = pool.ray
    max_ahead = max_ahead or 2 * PER_ACTOR * pool.workers
    snaps: dict = {}       # i -> snapshot, until written (a dead actor's frames are re-sent)
    pending: dict = {}     # ref -> (i, actor)
    load: dict = {}        # actor -> frames queued on it
    done: dict = {}        # i -> image, until its turn
    nxt = written = 0

    def submit(i):
        pool.ensure_live()
        a = min(pool.live, key=lambda x: load.get(x, 0))
        load[a] = load.get(a, 0) + 1
        pending[a.render.remote(i, snaps[i])] = (i, a)

    try:
        while written < n:
            pool._wait_started()
            while (nxt < n and nxt - written < max_ahead
                   and any(load.get(a, 0) < PER_ACTOR for a in pool.live)):
                snaps[nxt] = snapshot_of(nxt)
                submit(nxt)
                nxt += 1
            if not pending:      # every worker died: wait for a replacement (or fail)
                pool.ensure_live()
                continue
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                i, a = pending.pop(ref)
                load[a] = load.get(a, 0) - 1
                try:
                    _, img = ray.get(ref)
                except Exception as exc:
                    if not pool.is_death(exc):
                        raise _cause(exc) from None
                    pool.lost(a)
                    load.pop(a, None)
                    submit(i)            # re-rendered by another (or a replacement) worker
                    continue
                done[i] = img
            while written in done:
                yield written, done.pop(written), snaps.pop(written)
                written += 1
                if Pool.after_item is not None:
                    Pool.after_item(pool, written)
    finally:
        for ref in pending:
            with contextlib.suppress(Exception):
                ray.cancel(ref)


# ---- sweep ----------------------------------------------------------------------------------
def measure_points(pool: Pool, scene_path: str, points: list[dict]):
    """Yield ``(k, row, device_name)`` as points finish (any order): one point per device at
    a time (actors sharing a device take turns); a dead actor's point goes to another."""
    ray = pool.ray
    todo = list(range(len(points)))
    pending: dict = {}       # ref -> (k, actor)
    busy: set = set()        # device keys with a point running
    while todo or pending:
        pool._wait_started()
        if todo and not pending:
            pool.ensure_live()
        for a in list(pool.live):
            key = pool.info[a]["key"]
            if not todo or key in busy or a in {x for _, x in pending.values()}:
                continue
            k = todo.pop(0)
            busy.add(key)
            pending[a.measure.remote(scene_path, points[k])] = (k, a)
        ready, _ = ray.wait(list(pending), num_returns=1)
        for ref in ready:
            k, a = pending.pop(ref)
            info = pool.info.get(a, {})
            busy.discard(info.get("key"))
            try:
                row = ray.get(ref)
            except Exception as exc:
                if not pool.is_death(exc):
                    raise _cause(exc) from None
                pool.lost(a)
                todo.insert(0, k)
                continue
            yield k, row, info["device"]
            if Pool.after_item is not None:
                Pool.after_item(pool, k)
