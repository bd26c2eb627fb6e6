"""The recorder process's side (record.process forks it): one process runs every writer of a run,
the MCAP writer first, then the Rerun one, each fed from the ring at its own pace.

It sleeps in poll() until the twin wakes it (a message down the pipe: rows [0, N) are published, and
the commands, events and pictures that come before them), hands each writer its rows as column
views of the ring (record.ring: the writers copy what they keep) and says, per writer, how far it
has read. The MCAP writer takes every row it is woken for, in the main thread. The Rerun writer
takes rows only once TAKE of them have gathered, since its cost is per batch as much as per frame,
and in a thread of its own: one of its batches takes longer than the twin may run ahead of the
MCAP file. A writer that fails stops its own file there (kept, unfinalized, as after a crash) and
the process goes on reading, so the twin never waits for it; the close request is answered with the
failure, in one line.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import functools
import marshal
import operator
import os
import pickle
import select
import sys
import threading
import time
from pathlib import Path
from typing import NamedTuple

from twin.model.config import TwinConfig
from twin.model.images import CameraImage
from twin.model.sink import close_all
from twin.model.types import Command, Event
from twin.record.ring import FrameRing

WAKE, CLOSE = b"W", b"C"
DONE = b"OK\0"  # the recorder's last reply: finished, and its RecorderStats
STARTED = b"OK"  # a writer's start reply (else: its error, as text)
COMMAND, EVENT = 0, 1
IMAGE = 2  # a camera's picture (model.images.CameraImage), pickled like events
SWITCH_S = 0.0005  # the recorder process's GIL switch interval (serve)
# the later writers' thread's nice value, over the main thread's: on the recorder's one core, the
# MCAP writer the twin may wait on runs first; the Rerun writer and the threads its SDK starts (they
# inherit it) have the ring's slack, and their batches held the MCAP writer back (twin's waits per
# 16-cycle run, medians of 9: 16.9 ms at 0, 4.4 at 5; at 10, 5.0, but one run waited 72 ms)
LATER_NICE = 5
# item kind -> the sinks' method
_HANDLERS = {COMMAND: "on_command", EVENT: "on_event", IMAGE: "on_image"}
# item kind -> its class; an item travels as its fields' values, a plain tuple, pickled (their data
# come from tasks and may hold what marshal would silently turn into bytes, e.g. numpy scalars): a
# frozen dataclass pickles itself 5x slower (a Command: 5.7 us against 1.1, timeit; in a run, 18-31
# us a call)
_KINDS = {COMMAND: Command, EVENT: Event, IMAGE: CameraImage}
_VALUES = {
    kind: operator.attrgetter(
        *(cls._fields if issubclass(cls, tuple) else (f.name for f in dataclasses.fields(cls)))
    )
    for kind, cls in _KINDS.items()
}


def pack_other(kind: int, item: Command | Event | CameraImage) -> bytes:
    """A command, event or picture as the bytes that go down the pipe to the recorder."""
    return pickle.dumps(_VALUES[kind](item), protocol=pickle.HIGHEST_PROTOCOL)


def unpack_other(kind: int, data: bytes) -> Command | Event | CameraImage:
    """pack_other's bytes as the item they were made from."""
    return _KINDS[kind](*pickle.loads(data))


class RecorderStats(NamedTuple):
    """What the recorder process spent, from its first row to its files finalized (CPU seconds of
    all its threads), how much of it its writers spent (their calls, and the threads they run), and
    that share by writer ((name, seconds), ...)."""

    cpu_s: float
    writer_cpu_s: float
    frames: int
    by_writer: tuple = ()


class Writer(NamedTuple):
    """One writer the recorder runs: its kind ("mcap" or "rrd"), its file, the ring reader it reads
    as, and how many rows it lets gather before it takes them in (1: every wake-up)."""

    kind: str
    path: str | Path
    reader: int
    take: int


def poller(conn) -> select.poll:
    """One poll object for a pipe end: Connection.poll builds a selector on every call."""
    poll = select.poll()
    poll.register(conn.fileno(), select.POLLIN)
    return poll


def serve(
    conn,
    writers: list[Writer],
    ring: FrameRing,
    config: TwinConfig,
    run: dict,
    urdf: str,
    meshes: list[Path],
    rate: int,
    engine: dict[str, str] | None,
) -> None:
    """The recorder process: start each writer (one start reply each, in order), feed them what the
    twin publishes, finish on request. The first writer starts before anything else; the others
    start in a thread of their own while the first one is fed (the twin does not wait for them:
    their rows gather in the ring), and their start replies follow once they have started."""
    if "pandas" not in sys.modules:  # pyarrow (under rerun) would import it, 0.3 s, only to ask
        # whether arrays are pandas objects: they never are here
        sys.meta_path.insert(0, _NoPandas())
    make = functools.partial(
        _make, config=config, run=run, urdf=urdf, meshes=meshes, rate=rate, engine=engine
    )
    feeds = [_Feed(ring, None, writer) for writer in writers]
    error = _start(feeds[0], make)
    if error:
        conn.send_bytes(error.encode())
        for feed in feeds[1:]:  # the others end as error, as after a failure in the run
            _start(feed, make)
        _close_all([feed.sink for feed in feeds if feed.sink], "error", "recording could not start")
        os._exit(0)
    conn.send_bytes(STARTED)
    # the main thread, woken to feed the MCAP writer, takes the GIL from the later writers' thread
    # within this: Python's default (5 ms) is more than the twin's slack
    sys.setswitchinterval(SWITCH_S)
    clock = _Clock()  # from here: the first writer's start is not per frame, nor the others'
    _loop(conn, ring, feeds, clock, _Later(feeds[1:], make))


def _start(feed: _Feed, make) -> str:
    """Start a feed's writer: '' once it has, else why not, in one line."""
    try:
        feed.sink = make(feed.writer)
    except Exception as err:  # noqa: BLE001 - reported to the twin's process as one line
        return str(err)
    return ""


class _Later:
    """The writers after the first (the Rerun one), in a thread of their own: started one after
    another while the main thread feeds the first, then fed here, so that a Rerun batch (tens of
    ms) never keeps the MCAP writer from the rows the twin waits on (its slack is a few ms of the
    twin's time). The first start failure ends it. Its CPU time before they have started is not
    per frame (RecorderStats)."""

    def __init__(self, feeds: list[_Feed], make) -> None:
        self.feeds, self.make = feeds, make
        self.error = ""
        self.start_cpu_s = 0.0  # starting the writers
        self.feed_cpu_s = 0.0  # feeding them, every call around theirs included
        self.replied = not feeds  # whether the recorder has sent their start replies
        # a byte down this pipe wakes the recorder when the writers have started: a twin waiting
        # for one of them (it would pass the ring) sends no other wake-up
        self.done_fd, self._done_w = os.pipe()
        self._due = threading.Condition()
        self._synced = 0  # the rows the main thread says they may take in
        self._ending = None  # how the run ended, once it has (_take_messages)
        self._failures: list[str] = []
        # a thread of its own, not a Thread subclass: threading.Thread keeps private state under
        # names (its own `_started`, set as the thread begins) that a subclass's would replace
        self._thread = threading.Thread(target=self._run, name="twin-recorder-later", daemon=True)
        if feeds:
            self._thread.start()

    def _run(self) -> None:
        _lower_priority(LATER_NICE)
        t0 = time.thread_time()
        for feed in self.feeds:
            self.error = _start(feed, self.make)
            if self.error:
                break
        self.start_cpu_s = time.thread_time() - t0
        os.write(self._done_w, b"S")  # the one sign that they have started, or one could not
        if not self.error:
            self._feed()
        self.feed_cpu_s = time.thread_time() - t0 - self.start_cpu_s

    def _feed(self) -> None:
        fed = 0
        while True:
            with self._due:
                while self._synced == fed and self._ending is None:
                    self._due.wait()
                fed, ending = self._synced, self._ending
            if ending is not None:
                self._failures = [feed.end(fed, ending) for feed in self.feeds]
                return
            for feed in self.feeds:
                if feed.due(fed):
                    feed.take(fed, final=False)
                    feed.ring.release(feed.writer.reader, feed.read)

    def feed_to(self, synced: int) -> None:
        """Let the writers take rows [0, synced) in (and the others before them), in this thread,
        which is woken only once one of them has a take's worth: the main thread is woken every
        flush (120 frames), the Rerun writer takes 1024 at a time."""
        with self._due:
            self._synced = max(self._synced, synced)
            if any(feed.sink is not None and feed.due(self._synced) for feed in self.feeds):
                self._due.notify()

    def end(self, synced: int, ending) -> None:
        """Have the writers take rows [0, synced) and every other in, then end them (_Feed.end),
        in this thread: beside the first writer's end in the main thread."""
        with self._due:
            self._synced = max(self._synced, synced)
            self._ending = ending
            self._due.notify()

    def finish(self) -> str:
        """Wait for the writers' end; the first failure as text, or ''."""
        if self.feeds:  # the thread runs only for them
            self._thread.join()
        return next((text for text in self._failures if text), "")

    def reply(self, conn, feeds: list[_Feed], *, wait: bool) -> None:
        """Once every writer has started (waited for when `wait`): their start replies; after a
        failure, its text, the started writers ended as error and the process with them."""
        # the byte itself says so, not a flag set beside it: woken by the byte before such a flag
        # was set (that thread niced, on this one's core), the main loop left the byte unread and
        # woke again at once, over and over
        if self.replied or not (wait or select.select([self.done_fd], [], [], 0)[0]):
            return
        self.replied = True
        os.read(self.done_fd, 1)  # written once they have started, or one could not (waited for)
        if not self.error:
            for _ in self.feeds:
                conn.send_bytes(STARTED)
            return
        self._thread.join()
        conn.send_bytes(self.error.encode())
        _close_all([feed.sink for feed in feeds if feed.sink], "error", "recording could not start")
        os._exit(0)


def _make(writer: Writer, *, config, run, urdf, meshes, rate, engine):
    if writer.kind == "mcap":
        from twin.record.mcap.writer import McapRecorder  # loaded by the parent

        return McapRecorder(
            writer.path, config, run, urdf=urdf, meshes=meshes, rate=rate, engine=engine
        )
    from twin.record.rerun.writer import RerunRecorder

    return RerunRecorder(writer.path, config, urdf)


def _loop(conn, ring: FrameRing, feeds: list[_Feed], clock: _Clock, later: _Later) -> None:
    poll = poller(conn)  # the twin's pipe
    asleep = poller(conn)  # and the later writers' start
    asleep.register(later.done_fd, select.POLLIN)
    synced = 0  # the rows whose others have come: what the writers may take in
    while True:
        # asleep until the twin wakes it (rows to take in, with the others before them; the close),
        # the pipe ends or the later writers have started
        asleep.poll()
        end, woken_to = _take_messages(conn, poll, feeds)
        synced = max(synced, woken_to)
        if end == "died":  # every published row before the first other it was not sent
            ring.orphaned()
            synced = max(synced, min(ring.written(), ring.others_from()))
        if end != "died":  # the close waits for the writers still starting
            later.reply(conn, feeds, wait=end is not None)
        first = feeds[0]  # the later writers take their rows in in their own thread
        if end is None:
            later.feed_to(synced)
            # the rows the twin woke it for: those whose others it has
            if first.sink is not None and first.due(synced):
                first.take(synced, final=False)
                ring.release(first.writer.reader, first.read)
            continue
        # the close, or the twin's process died: every writer ends, side by side (the files'
        # fsyncs overlap), with every row the twin woke it for and every other it sent
        later.end(synced, end)
        failure = first.end(synced, end)
        later_failure = later.finish()
        failure = failure or later_failure
        if end == "died":
            os._exit(0)
        stats = clock.stats(feeds, later)
        conn.send_bytes(failure.encode() if failure else DONE + marshal.dumps(stats))
        os._exit(0)


def _take_messages(conn, poll: select.poll, feeds: list[_Feed]):
    """Read every message waiting in the pipe: the others go to each feed's queue. Returns (None,
    the close request's (outcome, error), or "died" when the pipe has closed: the twin's process
    died; the rows the twin has woken it for)."""
    synced = 0
    while poll.poll(0):
        try:
            message = conn.recv_bytes()
        except (EOFError, OSError):
            return "died", synced
        tag, body = message[:1], message[1:]
        if tag == WAKE:  # rows to take in, and the others that come before them
            woken_to, others = marshal.loads(body)
            for feed in feeds:
                feed.queue.extend(others)
            synced = max(synced, woken_to)
        elif tag == CLOSE:
            return marshal.loads(body), synced
    return None, synced


class _Clock:
    """CPU seconds of the process and of its main thread since the start, for RecorderStats."""

    def __init__(self) -> None:
        self.cpu0, self.thread0 = time.process_time(), time.thread_time()

    def stats(self, feeds: list[_Feed], later: _Later) -> tuple:
        """RecorderStats' fields: everything the recorder's own threads (this one, the later
        writers') did outside the writers' calls is the recorder's own work; the other threads
        (Rerun's SDK) are the Rerun writer's. Starting the later writers is not counted."""
        cpu_s = time.process_time() - self.cpu0 - later.start_cpu_s
        own_threads_s = time.thread_time() - self.thread0 + later.feed_cpu_s
        by_writer = {feed.writer.kind: feed.in_writer_s for feed in feeds}
        if "rrd" in by_writer:
            by_writer["rrd"] += cpu_s - own_threads_s
        writer_s = sum(by_writer.values())
        frames = max((feed.read for feed in feeds), default=0)
        return (cpu_s, writer_s, frames, tuple(by_writer.items()))


class _Feed:
    """Rows from the ring and the others from the pipe, to one writer in the order the twin made
    them."""

    def __init__(self, ring: FrameRing, sink, writer: Writer) -> None:
        self.ring, self.sink, self.writer = ring, sink, writer
        self.read = 0  # rows taken in (or, after a failure, passed over)
        # (frames before it, kind, pickle)
        self.queue: collections.deque[tuple[int, int, bytes]] = collections.deque()
        self.failure = ""
        self.in_writer_s = 0.0  # CPU seconds of the main thread in this writer's calls

    def timed(self, call, *args):
        """call(*args), a writer's work: its CPU counts as the writer's (RecorderStats)."""
        t0 = time.thread_time()
        try:
            return call(*args)
        finally:
            self.in_writer_s += time.thread_time() - t0

    def due(self, synced: int) -> bool:
        """Whether to take rows in now: a take's worth has gathered (for a writer that takes every
        wake-up: any row, or any other)."""
        if self.writer.take <= 1:
            return synced > self.read or bool(self.queue)
        return synced - self.read >= self.writer.take

    def take(self, written: int, *, final: bool) -> None:
        """Rows [read, written) and the others that come before row `written` (all of them when
        final)."""
        try:
            while self.queue and (final or self.queue[0][0] <= written):
                before, kind, data = self.queue.popleft()
                self._rows(min(before, written))
                if not self.failure:
                    self.timed(getattr(self.sink, _HANDLERS[kind]), unpack_other(kind, data))
            self._rows(written)
        except Exception as err:  # noqa: BLE001 - e.g. a full disk
            self.failure = (
                f"recording stopped by a writer error (what came before is kept): "
                f"{type(err).__name__}: {err}"
            )
            _abandon([self.sink])
        self.read = max(self.read, written)

    def end(self, written: int, ending) -> str:
        """Take rows [read, written) and every other in, then end the writer: finalized with the
        run's (outcome, error), or left unfinalized when `ending` is "died" (the twin's process
        died). Its failure as text, or ''."""
        if self.sink is None:  # it never started
            return self.failure
        self.take(written, final=True)
        self.ring.release(self.writer.reader, self.read)
        if self.failure:
            return self.failure
        if ending == "died":
            _abandon([self.sink])
            return ""
        return self.timed(_close_all, [self.sink], *ending)

    def _rows(self, upto: int) -> None:
        if upto <= self.read:
            return
        if not self.failure:
            for frames in self.ring.runs(self.read, upto):  # views into the ring: writers copy
                self.timed(self.sink.on_frames, frames)
        self.read = upto


def _lower_priority(nice: int) -> None:
    """Give the calling thread (on Linux a thread has its own nice value) `nice` more than it has;
    elsewhere, or where the system refuses, leave it."""
    if sys.platform == "linux":
        tid = threading.get_native_id()
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + nice)


class _NoPandas:
    """An import hook that says pandas is not installed (the recorder process never needs it)."""

    def find_spec(self, name: str, path=None, target=None):
        if name == "pandas" or name.startswith("pandas."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)


def _close_all(sinks: list, outcome: str, error: str) -> str:
    """Finish every writer with the run's outcome; the first failure as text, or ''."""
    failure = close_all(sinks, outcome, error)
    return str(failure) if failure is not None else ""


def _abandon(sinks: list) -> None:
    """Leave every file as a crash would: NAME.partial, unfinalized (the MCAP one recoverable)."""
    for sink in sinks:
        try:
            sink.abandon()
        except Exception:  # noqa: BLE001, S110 - already failing: keep what can be kept
            pass
