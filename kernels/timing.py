"""Per-stage timing from OpenCL profiling events.

Every launch goes through :meth:`kernels.Runtime.launch`, which hands its event to the runtime's
:class:`StageTimer` under a stage name (``"lbm.step"``, ``"bvh.refit"``). Reading the times waits
on the events, so callers read the previous frame's record, never one inside a frame.
"""

from __future__ import annotations

from collections import defaultdict

import pyopencl as cl


class StageTimer:
    """Collects events by stage name; :meth:`collect` turns them into milliseconds."""

    def __init__(self, enabled: bool = True):
        self.enabled = enabled
        self._events: dict[str, list[cl.Event]] = defaultdict(list)

    def record(self, stage: str, event: cl.Event) -> cl.Event:
        if self.enabled and event is not None:
            self._events[stage].append(event)
        return event

    def pending(self) -> int:
        return sum(len(v) for v in self._events.values())

    def collect(self) -> dict[str, float]:
        """Milliseconds per stage summed over the events recorded since the last call."""
        out: dict[str, float] = {}
        for stage, events in self._events.items():
            total_ns = 0
            for evt in events:
                evt.wait()
                total_ns += evt.profile.end - evt.profile.start
            out[stage] = total_ns * 1e-6
        self._events.clear()
        return out

    def reset(self) -> None:
        self._events.clear()
