"""A ring of packed Frame rows in memory shared with the recorder processes.

The twin packs each Frame straight into the ring (record.rows) and, every few frames, publishes how
many it has written; each recorder takes in the published rows when it wakes and says how far it has
read. No system call and no wake-up of the other core per frame: the twin wakes a recorder once a
take's worth of rows is published (see RecorderProcess).

The counters sit in the shared page and change only under one lock, whose acquire and release order
the row bytes before the counter that publishes them on every processor, not only on x86.
"""

from __future__ import annotations

import contextlib
import mmap
import multiprocessing
import struct

from twin.model.columns import FrameColumns
from twin.record.rows import FrameRows

_COUNTER = struct.Struct("<Q")
NO_ROW = 2**64 - 1  # others_from when every command, event and picture has gone to the recorder


class FrameRing:
    """`capacity` rows of `rows.size` bytes, a written counter, one read counter per reader and the
    row count before the first command, event or picture the recorder has not been sent yet
    (others_from). Made before the recorders are forked: they inherit the mapping and the lock."""

    def __init__(self, rows: FrameRows, capacity: int, readers: int) -> None:
        if capacity < 1 or readers < 1:
            raise ValueError(
                f"a ring of {capacity} rows for {readers} readers; expected at least one of each"
            )
        self.rows = rows
        self.capacity = capacity
        self.readers = readers
        # written, each reader's read, others_from
        self._header = _COUNTER.size * (2 + readers)
        self._others_at = _COUNTER.size * (1 + readers)
        # anonymous, shared with forks
        self.memory = mmap.mmap(-1, self._header + capacity * rows.size)
        self._lock = multiprocessing.get_context("fork").Lock()
        self._columns: FrameColumns | None = None  # the whole ring as columns, made on first use
        self.mark_others(NO_ROW)

    def offset(self, frame: int) -> int:
        """Where the row of frame number `frame` (counted from the run's first) lives in
        `memory`."""
        return self._header + (frame % self.capacity) * self.rows.size

    # -- the twin's side ------------------------------------------------------------------------
    def publish(self, written: int) -> list[int]:
        """Say that rows [0, written) are in the ring; returns each reader's read counter."""
        with self._lock:
            _COUNTER.pack_into(self.memory, 0, written)
            return [
                _COUNTER.unpack_from(self.memory, _COUNTER.size * (1 + i))[0]
                for i in range(self.readers)
            ]

    def mark_others(self, row: int) -> None:
        """Say that the commands, events and pictures from row `row` on have not been sent to the
        recorder (NO_ROW: all have). Set before the first of them is kept, cleared once they are
        sent: if the twin's process dies, the recorder keeps no published row after one it lost."""
        _COUNTER.pack_into(self.memory, self._others_at, row)

    def read(self, reader: int) -> int:
        """How many rows reader `reader` has taken in."""
        with self._lock:
            return _COUNTER.unpack_from(self.memory, _COUNTER.size * (1 + reader))[0]

    # -- a recorder's side ----------------------------------------------------------------------
    def orphaned(self) -> None:
        """The twin's process died (the recorder saw its pipe close), maybe holding the lock (a
        kill -9 inside a publish left a recorder waiting on it for good): nobody else writes the
        counters now, so this process reads and writes them without it from here on."""
        self._lock = contextlib.nullcontext()

    def written(self) -> int:
        """How many rows the twin has published."""
        with self._lock:
            return _COUNTER.unpack_from(self.memory, 0)[0]

    def others_from(self) -> int:
        """The rows whose commands, events and pictures have all been sent: [0, others_from)."""
        with self._lock:
            return _COUNTER.unpack_from(self.memory, self._others_at)[0]

    def release(self, reader: int, read: int) -> None:
        """Reader `reader` is done with rows [0, read): the twin may write over them."""
        with self._lock:
            _COUNTER.pack_into(self.memory, _COUNTER.size * (1 + reader), read)

    def runs(self, start: int, end: int) -> list[FrameColumns]:
        """Rows [start, end) as columns, strided views into the ring: one run, or two where they
        wrap around. Valid until `release` passes them. (The views of the whole ring are made once:
        slicing them costs a tenth of viewing the rows anew.)"""
        if self._columns is None:
            whole = memoryview(self.memory)[self._header :]
            self._columns = self.rows.columns(whole, copy=False)
        runs = []
        while start < end:
            # the ring's end, or `end`
            stop = min(end, start - start % self.capacity + self.capacity)
            at = start % self.capacity
            runs.append(self._columns.slice(at, at + stop - start))
            start = stop
        return runs
