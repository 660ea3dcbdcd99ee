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
    __slots__ = ("events", "first_ns", "folded_ms", "last_ns", "tag")

    def __init__(self, tag):
        self.tag = tag
        self.events: list[tuple[str, cl.Event]] = []
        self.folded_ms: dict[str, float] = {}
        self.first_ns: int | None = None   # the earliest start and latest end of its events
        self.last_ns: int | None = None

    def fold(self, count: int, done: bool = False) -> None:
        """Keep only the per-stage sums of the oldest ``count`` events, waiting for the last of
        them (one in-order queue: then all are complete) unless ``done`` says they are."""
        events = self.events[:count]
        if not events:
            return
        if not done:
            events[-1][1].wait()
        ms, get = self.folded_ms, self.folded_ms.get
        first, last = self.first_ns, self.last_ns
        for stage, evt in events:
            info = evt.get_profiling_info
            try:
                start, end = info(_START), info(_END)
            except cl.Error:  # not complete after all (an event of another queue): wait
                evt.wait()
                start, end = info(_START), info(_END)
            ms[stage] = get(stage, 0.0) + (end - start) * 1e-6
            first = start if first is None or start < first else first
            last = end if last is None or end > last else last
        self.first_ns, self.last_ns = first, last
        del self.events[:count]

    def done(self) -> bool:
        # one in-order queue: the last event complete means all are
        return not self.events or (
            self.events[-1][1].command_execution_status == _COMPLETE)

    def stage_ms(self, done: bool = False) -> dict[str, float]:
        self.fold(len(self.events), done)
        return dict(self.folded_ms)

    def span_ms(self) -> float:
        """Device ms from its first command's start to its last one's end: its kernels' time
        plus the device's idle time between them (0.0 with no events)."""
        if self.first_ns is None:
            return 0.0
        return (self.last_ns - self.first_ns) * 1e-6


class StageTimer:
    """Collects events by stage name, per frame; a bounded ring of closed frames."""

    def __init__(self, enabled: bool = True, *, max_frames: int = 8, max_events: int = 4096):
        self.enabled = enabled
        self.max_frames, self.max_events = int(max_frames), int(max_events)
        self._open = _Frame(None)
        self._closed: deque[_Frame] = deque()
        self._dropped: dict[str, float] = {}  # frames folded out of the ring, for collect()
        self._spans: dict = {}   # tag -> span_ms of the frames completed() returned, until taken

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
            self._spans[f.tag] = f.span_ms()
        while len(self._spans) > 4 * self.max_frames:   # tags nobody took
            del self._spans[next(iter(self._spans))]
        return out

    def take_span_ms(self, tag) -> float:
        """The device span (:meth:`_Frame.span_ms`: first start to last end, gaps between its
        commands included) of a frame :meth:`completed` returned; 0.0 when unknown."""
        return self._spans.pop(tag, 0.0)

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
        self._spans = {}
