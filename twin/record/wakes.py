"""When the twin wakes its recorder process, and when it waits for it (twin.record.process).

A recorder asleep in poll() costs nothing, but each wake-up costs it more than its own few system
calls: on our 2-core machines, code run just after 3 ms asleep ran about 4x slower than the same
code run again at once (its caches had gone cold), and the MCAP writer fed 48 frames every 3 ms
spent 13 us of CPU a frame against 8 us fed without pauses (docs/explanation/architecture.md has
the figures). So the twin wakes it as seldom as the files allow:

- With an MCAP file: just after each frame at which the MCAP writer flushes its chunk
  (twin.record.mcap.writer.flush_steps, every 0.5 s of simulated time): that is when the file
  grows, and a wake-up in between would only move rows from the ring into the writer's memory.
- Without one: once the Rerun writer's take has gathered.

The twin waits for the recorder only when it would otherwise go more than `ahead` frames past a
flush frame whose rows the MCAP writer has not taken in, or write over rows a writer has not read
(the ring's capacity). So what a kill -9 of every process loses stays bounded: the frames since the
last flush (under 0.5 s of simulated time) and at most `ahead` more.
"""

from __future__ import annotations

import collections
from collections.abc import Iterator


class WakeSchedule:
    """The twin's side of the schedule, asked at each publish (rows [0, written) in the ring)."""

    def __init__(self, flushes: Iterator[int] | None, *, gather: int, ahead: int) -> None:
        self._flushes = flushes  # the MCAP writer's flush steps; None without an MCAP file
        self._next_flush = next(flushes) if flushes is not None else None
        self._gather = gather  # rows between wake-ups without an MCAP file
        self.ahead = ahead
        self.woken_at = 0  # the rows published when the twin last woke the recorder
        # the row counts that end a flush frame, woken for but maybe not yet taken in, oldest first
        self._flushed: collections.deque[int] = collections.deque()

    def passed(self, written: int, step: int) -> bool:
        """Rows [0, written) are published, the last of them the frame of step `step`: whether
        the recorder is to be woken now."""
        if self._next_flush is None:
            return written - self.woken_at >= self._gather
        wake = False
        while step >= self._next_flush:
            # the flush frame's row, and every row before it
            self._flushed.append(written - (step - self._next_flush))
            self._next_flush = next(self._flushes)
            wake = True
        return wake

    def woken(self, written: int) -> None:
        self.woken_at = written

    def mcap_due(self, mcap_read: int, next_publish: int) -> int | None:
        """The rows the MCAP writer must have taken in before the twin steps on to row
        `next_publish`, or None when it may go on."""
        flushed = self._flushed
        while flushed and mcap_read >= flushed[0]:
            flushed.popleft()
        if flushed and next_publish - flushed[0] > self.ahead:
            return flushed[0]
        return None
