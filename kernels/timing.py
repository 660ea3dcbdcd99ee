"""Per-stage timing from OpenCL profiling events, in a bounded ring of frames.

Every launch hands its event to the runtime's :class:`StageTimer` under a stage name
(``"lbm.step"``, ``"bvh.refit"``). Events belong to the open frame until :meth:`StageTimer.
close_frame` closes it; a closed frame's times are read once its last event has completed
(:meth:`StageTimer.completed`, which never waits), so the host reads frame N's times while frames
N+1.. run. Memory stays bounded: at most ``max_frames`` closed frames are kept (older ones are
folded in, waiting on them only then), and an open frame that collects more than ``max_events``
events (a long ``step(1)`` loop with no frames) folds its oldest half into per-stage sums.
"""

from __future__ import annotations

from collections import deque

import pyopencl as cl

_COMPLETE = cl.command_execution_status.COMPLETE
_START, _END = cl.profiling_info.START, cl.profiling_info.END


class _Frame:
    __slots__ = ("events", "folded_ms", "tag")

    def __init__(self, tag):
        self.tag = tag
        self.events: list[tuple[str, cl.Event]] = []
        self.folded_ms: dict[str, float] = {}

    def fold(self, count: int, done: bool = False) -> None:
        """Keep only the per-stage sums of the oldest ``count`` events, waiting for the last of
        them (one in-order queue: then all are complete) unless ``done`` says they are."""
        events = self.events[:count]
        if not events:
            return
        if not done:
            events[-1][1].wait()
        ms, get = self.folded_ms, self.folded_ms.get
        for stage, evt in events:
            try:
                info = evt.get_profiling_info
                t = (info(_END) - info(_START)) * 1e-6
            except cl.Error:  # not complete after all (an event of another queue): wait
                t = _event_ms(evt)
            ms[stage] = get(stage, 0.0) + t
        del self.events[:count]

    def done(self) -> bool:
        # one in-order queue: the last event complete means all are
        return not self.events or (
            self.events[-1][1].command_execution_status == _COMPLETE)

    def stage_ms(self, done: bool = False) -> dict[str, float]:
        self.fold(len(self.events), done)
        return dict(self.folded_ms)


def _event_ms(evt: cl.Event) -> float:
    evt.wait()
    return (evt.get_profiling_info(_END) - evt.get_profiling_info(_START)) * 1e-6


class StageTimer:
    """Collects events by stage name, per frame; a bounded ring of closed frames."""

    def __init__(self, enabled: bool = True, *, max_frames: int = 8, max_events: int = 4096):
        self.enabled = enabled
        self.max_frames, self.max_events = int(max_frames), int(max_events)
        self._open = _Frame(None)
        self._closed: deque[_Frame] = deque()
        self._dropped: dict[str, float] = {}  # frames folded out of the ring, for collect()

    def record(self, stage: str, event: cl.Event) -> cl.Event:
        if self.enabled and event is not None:
            self._open.events.append((stage, event))
            if len(self._open.events) > self.max_events:
                self._open.fold(self.max_events // 2)
        return event

    def pending(self) -> int:
        """Events held (open and closed frames): bounded by the ring's limits."""
        return len(self._open.events) + sum(len(f.events) for f in self._closed)

    def close_frame(self, tag) -> None:
        """End the open frame under ``tag`` (a frame index) and open the next one."""
        self._closed.append(self._open)
        self._open.tag = tag
        self._open = _Frame(None)
        while len(self._closed) > self.max_frames:
            old = self._closed.popleft()
            for k, v in old.stage_ms().items():
                self._dropped[k] = self._dropped.get(k, 0.0) + v

    def completed(self, wait: bool = False) -> list[tuple[object, dict[str, float]]]:
        """``(tag, {stage: ms})`` of the closed frames whose work has finished, oldest first,
        removed from the ring. Never waits unless ``wait`` (then every closed frame)."""
        out = []
        while self._closed and (wait or self._closed[0].done()):
            f = self._closed.popleft()
            out.append((f.tag, f.stage_ms(done=not wait)))
        return out

    def collect(self) -> dict[str, float]:
        """Milliseconds per stage summed over everything recorded since the last call (waits on
        the events; benchmarks and tests use it, the frame loop uses :meth:`completed`)."""
        out = dict(self._dropped)
        frames = [*self._closed, self._open]
        for f in frames:
            for k, v in f.stage_ms().items():
                out[k] = out.get(k, 0.0) + v
        self.reset()
        return out

    def reset(self) -> None:
        self._open = _Frame(None)
        self._closed.clear()
        self._dropped = {}
