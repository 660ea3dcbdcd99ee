"""Events whose release would wait: kept until they complete, so the host never blocks on them.

pyopencl returns a ``NannyEvent`` for a copy between a device buffer and host memory (a NumPy
array); it holds the host array and, when its last reference goes, *waits for the copy* in its
destructor. Dropping one right after a non-blocking ``enqueue_copy`` (or replacing the only
reference to it) is therefore a hidden ``wait`` on everything queued before the copy: frame
N's enqueue would wait for frame N-1 to finish. :meth:`EventKeeper.keep` holds such events
until the in-order queue has passed them (checked from the oldest, never waiting) and drops
them then; past ``limit`` held events the oldest is dropped anyway (it may wait: memory stays
bounded when nothing ever completes).
"""

from __future__ import annotations

from collections import deque

import pyopencl as cl

_COMPLETE = cl.command_execution_status.COMPLETE


class EventKeeper:
    """Holds events of one in-order queue until they complete."""

    __slots__ = ("_held", "limit")

    def __init__(self, limit: int = 256):
        self._held: deque = deque()
        self.limit = int(limit)

    def keep(self, event):
        """Hold ``event`` (None is ignored) until it completes; returns it."""
        if event is not None:
            held = self._held
            held.append(event)
            while held and held[0].command_execution_status == _COMPLETE:
                held.popleft()
            if len(held) > self.limit:
                held.popleft()
        return event

    def __len__(self) -> int:
        return len(self._held)

    def clear(self) -> None:
        """Drop every held event (waits for those not complete)."""
        self._held.clear()
