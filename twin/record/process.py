"""Recording on the machine's other core: a sink that hands the twin's stream to recorder processes,
which run the same MCAP and Rerun writers (one process each).

The stepping thread packs each Frame into a ring of rows in shared memory (twin.record.ring: about a
microsecond, no system call) and every 1/15 s of simulated time publishes how far it got. A recorder
sleeps in poll() until the twin wakes it (a message down the pipe) once a take's worth of rows is
published (TAKE_S for the MCAP writer, RRD_TAKE_S for the Rerun one: the writers take columns, the
bigger the batch the less each frame costs); the wake-up carries the commands, events and pictures
(rare) that come before those rows. The recorder takes the rows in and says how far it read. The
twin waits for a recorder only when it has used all its slack (the MCAP writer's: MAX_AHEAD_S of
simulated time, which bounds what a kill -9 of the whole run loses; the Rerun writer's: the ring).
Files are byte-for-byte what the in-process writers make, since the same writer code sees the same
stream. If the twin's process dies, the recorder sees the pipe close, takes in every row it was
woken for and leaves the MCAP file unfinalized (and recoverable, as NAME.partial). Ctrl-C, SIGTERM
and SIGHUP are the twin's to handle (it then finalizes the files): the recorder ignores them.
"""

from __future__ import annotations

import collections
import marshal
import os
import pickle
import select
import sys
import time
from pathlib import Path
from typing import NamedTuple

from twin.helpers import forking_on, keep_to, split_cpus, start_helper
from twin.model.config import TwinConfig
from twin.model.errors import RecordingError
from twin.model.images import CameraImage
from twin.model.sink import Sink, close_all
from twin.model.types import Command, Event, Frame
from twin.record.outputs import check_target
from twin.record.ring import FrameRing
from twin.record.rows import FrameRows

PUBLISH_S = 16 / 240  # simulated time between the twin's publishes: 16 frames at 240 Hz
# simulated time the MCAP writer may lag behind the twin: bounds what a kill -9 loses
MAX_AHEAD_S = 0.4
# simulated time the ring holds: slack for the Rerun writer's bursts (every 8192 frames)
RING_S = 4096 / 240
# The twin wakes a recorder (a byte down its pipe) once this much simulated time is published since
# it last did: the writers take columns, whose cost is per batch as much as per frame, and a
# recorder asleep in poll() costs nothing. The MCAP writer's is half its slack; the Rerun one's a
# quarter of the ring.
TAKE_S = 48 / 240
RRD_TAKE_S = 1024 / 240
WAIT_S = 0.0002  # the twin's sleep while it waits for a recorder to take rows in
_WAKE, _CLOSE = b"W", b"C"
_DONE = b"OK\0"  # a recorder's last reply: finished, and its RecorderStats
_COMMAND, _EVENT = 0, 1
_IMAGE = 2  # a camera's picture (model.images.CameraImage), pickled like events
# item kind -> the sinks' method
_HANDLERS = {_COMMAND: "on_command", _EVENT: "on_event", _IMAGE: "on_image"}


def check_writable(mcap_path, rrd_path, run: dict) -> None:
    """What the writers would refuse when they start, refused at once: a path whose folder is
    missing or that is a folder, and (MCAP) a run description that is not plain JSON."""
    from twin.record.mcap.metadata import check_run

    for path, expected in ((mcap_path, "an .mcap path"), (rrd_path, "a .rrd file path")):
        if path is not None:
            check_target(path, "recording", expected, error=RecordingError)
    if mcap_path is not None:
        check_run(run)


class RecorderStats(NamedTuple):
    """What a recorder process spent, from its first row to its file finalized (CPU seconds of all
    its threads), and how much of it its writer spent (its calls, and the threads it runs)."""

    cpu_s: float
    writer_cpu_s: float
    frames: int


def _poller(conn) -> select.poll:
    poller = select.poll()
    poller.register(conn.fileno(), select.POLLIN)
    return poller


def _frames(config: TwinConfig, seconds: float) -> int:
    return max(1, round(seconds * 1e9 / config.dt_ns))


class RecorderProcess(Sink):
    """A sink (on_frame/on_command/on_event/on_image) whose writers run in child processes: one for
    the MCAP file, one for the .rrd, both reading the same ring. Apart, a burst of the Rerun writer
    (it sends its columns every 8192 frames) cannot hold the MCAP writer, nor the twin, up."""

    def __init__(
        self,
        config: TwinConfig,
        run: dict,
        *,
        urdf: str,
        meshes: list[Path],
        mcap_path: str | Path | None,
        rrd_path: str | Path | None,
        rate: int,
        engine: dict[str, str] | None = None,
    ) -> None:
        self._rows = FrameRows(len(config.profile.joint_names), len(config.objects))
        self._publish_every = _frames(config, PUBLISH_S)
        mcap_ahead = max(_frames(config, MAX_AHEAD_S), 2 * self._publish_every)
        capacity = max(_frames(config, RING_S), 4 * mcap_ahead)
        # (writer, path, how far ahead the twin may go, how many rows between wake-ups)
        writers = [
            (w, p, ahead, max(1, min(_frames(config, take_s), ahead - 2 * self._publish_every)))
            for w, p, ahead, take_s in [
                ("mcap", mcap_path, mcap_ahead, TAKE_S),
                ("rrd", rrd_path, capacity, RRD_TAKE_S),
            ]
            if p is not None
        ]
        self._ring = FrameRing(self._rows, capacity, len(writers))
        # what on_frame needs, bound once: it runs every step
        self._row_size, self._memory = self._rows.size, self._ring.memory
        # the ring's first and last rows
        self._first, self._last = self._ring.offset(0), self._ring.offset(capacity - 1)
        self._at = self._first  # where the next row goes
        self._written = 0
        # the first publish is the first frame's (the twin's scene is built by then): it waits for
        # the MCAP writer to be ready, so the run's stepping never does
        self._next_publish = 1
        # (frames before it, kind, pickle), from the run's `_others_base`th on: the ones some
        # recorder has not been sent yet
        self._others: list[tuple[int, int, bytes]] = []
        self._others_base = 0
        self._closed = False
        # how often the twin waited for a recorder (tools/bench_record.py reports it)
        self.waits = 0
        # Load the writers here, once: every forked recorder inherits them instead of importing anew
        # (rerun alone takes ~0.3 s to import).
        import twin.record.mcap.writer

        if rrd_path is not None:
            import twin.record.rerun.writer  # noqa: F401
        # what a writer would refuse at its start, refused here, before the run: a bad path or run
        check_writable(mcap_path, rrd_path, run)
        self._children: list[_Child] = []
        # the recorders on the other cores, the twin's thread on its own one until the close
        cpus = split_cpus()
        self._twins_cpus: set[int] | None = None  # the CPUs the twin's thread had before
        try:
            with forking_on(cpus and cpus[1]):
                for reader, (writer, path, ahead, take) in enumerate(writers):
                    self._children.append(
                        _Child(
                            writer,
                            reader,
                            (ahead, take),
                            self._children,
                            (self._ring, config, run, urdf, meshes, path, rate, engine),
                        )
                    )
        except BaseException:
            self._fail_start(None)
            raise
        self._twins_cpus = keep_to(cpus and cpus[0])
        # They start side by side with the twin's scene: the twin hears the MCAP writer is ready at
        # its first publish, the first frame's (it waits for it there), and the Rerun one when it
        # has said so (at the latest at the close), so building the twin does not wait for them.
        self._starting = list(self._children)

    def _check_started(self, wait: tuple[str, ...]) -> None:
        """Read the start reply of the recorders that have sent it, waiting for those of the
        writers in `wait`; a writer that could not start ends the recording, the others as
        error."""
        for child in list(self._starting):
            if child.writer in wait or child.has_reply():
                self._starting.remove(child)
                try:
                    child.expect_ok("recording could not start")
                except RecordingError:
                    self._fail_start(child)
                    raise

    def _fail_start(self, failed: _Child | None) -> None:
        """A writer could not start (or forking failed): the others end as error, nothing waits
        for the failed one; the recording is closed."""
        self._closed = True
        self._free_twins_thread()
        for child in self._children:
            if child is failed:
                child.stop()
                continue
            try:
                child.finish("error", "recording could not start")
            except RecordingError:
                pass

    # -- sink -------------------------------------------------------------------------------
    def on_frame(self, frame: Frame) -> None:
        at = self._at
        self._rows.pack_into(self._memory, at, frame)
        self._at = at + self._row_size if at < self._last else self._first
        self._written += 1
        if self._written == self._next_publish:
            self._publish()

    # Commands and events (rare) are pickled one by one: their data comes from tasks and may hold
    # values marshal would silently turn into bytes (anything with a buffer, e.g. numpy scalars).
    def on_command(self, command: Command) -> None:
        self._others.append(
            (self._written, _COMMAND, pickle.dumps(command, protocol=pickle.HIGHEST_PROTOCOL))
        )

    def on_event(self, event: Event) -> None:
        self._others.append(
            (self._written, _EVENT, pickle.dumps(event, protocol=pickle.HIGHEST_PROTOCOL))
        )

    def on_image(self, image: CameraImage) -> None:
        self._others.append(
            (self._written, _IMAGE, pickle.dumps(image, protocol=pickle.HIGHEST_PROTOCOL))
        )

    def _publish(self) -> None:
        """The rows up to here published, and a recorder woken when a take's worth is waiting for
        it (or waited for, when the twin would pass its slack)."""
        if self._starting:
            self._check_started(("mcap",))
        written = self._written
        reads = self._ring.publish(written)
        # then every publish_every frames from the run's start (16, 32, ...), as before the first
        # publish moved to frame 0: a task whose commands come at steps in step with the publishes
        # would see a killed run keep a frame without the commands of its step
        self._next_publish = (written // self._publish_every + 1) * self._publish_every
        for child, read in zip(self._children, reads, strict=True):
            if self._next_publish - read > child.ahead:
                self.waits += 1
                self._wake(child, written)
                child.wait_until_read(self._ring, self._next_publish - child.ahead)
            elif written - child.woken_at >= child.take:
                self._wake(child, written)
        if self._others:
            self._drop_sent_others()

    def _wake(self, child: _Child, written: int) -> None:
        """Have a recorder take in rows [0, written): the wake-up carries the others it has not had
        yet (all of them come before row `written`), so it wakes once for both."""
        child.wake(written, self._others[child.others_sent - self._others_base :])
        child.others_sent = self._others_base + len(self._others)

    def _drop_sent_others(self) -> None:
        sent = min(child.others_sent for child in self._children) - self._others_base
        if sent:
            del self._others[:sent]
            self._others_base += sent

    def close(self, outcome: str = "ok", error: str = "") -> None:
        """Publish what is left, have the writers finalize, wait for them (the first failure is
        raised once all have finished). Idempotent."""
        if self._closed:
            return
        if self._starting:  # a writer that could not start: the others end as error, and it says
            self._check_started(("mcap", "rrd"))
        self._closed = True
        self._free_twins_thread()
        failure: RecordingError | None = None
        try:
            self._publish_rest()
        except RecordingError as err:
            failure = err
        # every writer finalizes at once (each in its process), then the twin waits for them all
        asked = []
        for child in self._children:
            try:
                child.ask_to_finish(outcome, error)
                asked.append(child)
            except RecordingError as err:
                failure = failure or err
        for child in asked:
            try:
                child.wait_finished()
            except RecordingError as err:
                failure = failure or err
        if failure is not None:
            raise failure

    def _free_twins_thread(self) -> None:
        """The twin's thread may run on every CPU it could before the recording again."""
        keep_to(self._twins_cpus)
        self._twins_cpus = None

    @property
    def stats(self) -> dict[str, RecorderStats]:
        """Each finished recorder's RecorderStats, by writer ("mcap", "rrd"): tools/bench_record.py
        reports them."""
        return {c.writer: c.stats for c in self._children if c.stats is not None}

    def _publish_rest(self) -> None:
        self._ring.publish(self._written)
        for child in self._children:
            self._wake(child, self._written)


class _Child:
    """One recorder process, the twin's end of its pipe, and how far ahead of it the twin may go
    (`ahead` rows: for the MCAP file that bounds what a kill -9 loses; the view gets the whole
    ring)."""

    def __init__(
        self,
        writer: str,
        reader: int,
        ahead_take: tuple[int, int],
        siblings: list[_Child],
        args: tuple,
    ) -> None:
        self.writer = writer
        self.reader = reader
        self.ahead, self.take = ahead_take
        self.wakes = 0  # wake-ups the twin sent it
        self.woken_at = 0  # the rows published when the twin last woke it
        self.others_sent = 0  # the run's others it has been sent
        # what the recorder said of its CPU at the end (RecorderStats), None before
        self.stats: RecorderStats | None = None
        self.conn, self.process = start_helper(
            self,
            _serve,
            (writer, reader, *args),
            name=f"twin-recorder-{writer}",
            other_ends=[s.conn for s in siblings],
        )
        # one poll object for the pipe: Connection.poll builds a selector on every call
        self._poller = _poller(self.conn)

    def send(self, message: bytes) -> None:
        try:
            self.conn.send_bytes(message)
        except OSError as err:
            raise RecordingError(f"the recorder process stopped: {self._exit_text()}") from err

    def has_reply(self) -> bool:
        """True when the recorder has said something (or its end of the pipe has closed)."""
        return bool(self._poller.poll(0))

    def wake(self, written: int, others: list) -> None:
        """Rows [0, written) are published: have the recorder take them in, with `others` (the
        commands, events and pictures that come before them it has not had)."""
        self.woken_at = written
        self.wakes += 1
        self.send(_WAKE + marshal.dumps((written, others)))

    def wait_until_read(self, ring: FrameRing, read: int) -> None:
        """Wait until the recorder (woken) has taken in rows [0, read)."""
        while ring.read(self.reader) < read:
            if self._poller.poll(0):  # it says nothing before the close: this is the pipe's end
                raise RecordingError(f"the recorder process stopped: {self._exit_text()}")
            time.sleep(WAIT_S)

    def expect_ok(self, what: str) -> None:
        try:
            reply = self.conn.recv_bytes()
        except (EOFError, OSError) as err:
            raise RecordingError(
                f"{what}: the recorder process stopped ({self._exit_text()})"
            ) from err
        if reply == b"OK":
            return
        if reply.startswith(_DONE):
            self.stats = RecorderStats(*marshal.loads(reply[len(_DONE) :]))
            return
        self.process.join(timeout=5)
        raise RecordingError(reply.decode(errors="replace"))

    def finish(self, outcome: str, error: str) -> None:
        """Have the writer finalize with the run's outcome and wait for it."""
        self.ask_to_finish(outcome, error)
        self.wait_finished()

    def ask_to_finish(self, outcome: str, error: str) -> None:
        """Have the writer finalize with the run's outcome (wait_finished waits for it)."""
        try:
            self.conn.send_bytes(_CLOSE + marshal.dumps((outcome, error)))
        except OSError as err:
            text = self._exit_text()
            self.stop()
            raise RecordingError(
                f"recording could not be finished: the recorder process stopped ({text})"
            ) from err

    def wait_finished(self) -> None:
        """Wait until the writer has finalized (or failed: RecordingError), and for its process."""
        try:
            self.expect_ok("recording could not be finished")
        finally:
            self.stop()

    def stop(self) -> None:
        self.conn.close()
        self.process.join(timeout=30)

    def _exit_text(self) -> str:
        self.process.join(timeout=1)
        code = self.process.exitcode
        return "still running" if code is None else f"exit code {code}"


def _serve(
    conn,
    writer: str,
    reader: int,
    ring: FrameRing,
    config: TwinConfig,
    run: dict,
    urdf: str,
    meshes: list[Path],
    path: str | Path,
    rate: int,
    engine: dict[str, str] | None,
) -> None:
    """A recorder process: build its writer ("mcap" or "rrd"), feed it what the twin publishes,
    finish on request.

    A writer that fails stops the recording there (what was written is kept, unfinalized, as after a
    crash); the process goes on reading (so the twin never waits for it) until the close request and
    answers it with the failure, so the twin reports it as one line instead of losing the run's
    remaining output."""
    if "pandas" not in sys.modules:  # pyarrow (under rerun) would import it, 0.3 s, only to ask
        # whether arrays are pandas objects: they never are here
        sys.meta_path.insert(0, _NoPandas())
    from twin.record.mcap.writer import McapRecorder  # already loaded by the parent

    sinks = []
    try:
        if writer == "mcap":
            sinks.append(
                McapRecorder(path, config, run, urdf=urdf, meshes=meshes, rate=rate, engine=engine)
            )
        else:
            from twin.record.rerun.writer import RerunRecorder

            sinks.append(RerunRecorder(path, config, urdf))
    except Exception as err:  # noqa: BLE001 - reported to the twin's process as one line
        _close_all(sinks, "error", "recording could not start")
        conn.send_bytes(str(err).encode())
        os._exit(0)
    conn.send_bytes(b"OK")
    feed = _Feed(ring, sinks)
    poller = _poller(conn)
    while True:
        # asleep until the twin wakes it (rows to take in, with the others before them; the close)
        # or the pipe ends
        poller.poll()
        end = _take_messages(conn, poller, feed)
        if end is not None or feed.woken:
            # the rows the twin woke it for: those whose others it has (all, at the close; at the
            # twin's death the rows published after its last wake-up are left out)
            feed.take(feed.synced, final=end is not None)
            ring.release(reader, feed.read)
            feed.woken = False
        if end == "died":  # the twin's process died: keep what arrived, unfinalized
            if not feed.failure:
                _abandon(sinks)
            os._exit(0)
        if end is not None:
            failure = feed.failure or feed.timed(_close_all, sinks, *end)
            conn.send_bytes(failure.encode() if failure else _DONE + marshal.dumps(feed.stats()))
            os._exit(0)


def _take_messages(conn, poller: select.poll, feed: _Feed):
    """Read every message waiting in the pipe: the others go to the feed's queue. Returns None, the
    close request's (outcome, error), or "died" when the pipe has closed (the twin's process
    died)."""
    while poller.poll(0):
        try:
            message = conn.recv_bytes()
        except (EOFError, OSError):
            return "died"
        tag, body = message[:1], message[1:]
        if tag == _WAKE:  # rows to take in, and the others that come before them
            synced, others = marshal.loads(body)
            feed.queue.extend(others)
            feed.synced = max(feed.synced, synced)
            feed.woken = True
        elif tag == _CLOSE:
            return marshal.loads(body)
    return None


class _Feed:
    """Rows from the ring and the others from the pipe, to the writers in the order the twin made
    them."""

    def __init__(self, ring: FrameRing, sinks: list) -> None:
        self.ring, self.sinks = ring, sinks
        self.read = 0  # rows taken in (or, after a failure, passed over)
        # (frames before it, kind, pickle)
        self.queue: collections.deque[tuple[int, int, bytes]] = collections.deque()
        self.failure = ""
        self.woken = False  # the twin asked for the rows to be taken in
        self.synced = 0  # the rows whose others have come: what it may take in
        # CPU seconds: the process's and this thread's at the start, this thread's in the writers
        self._cpu0, self._thread0, self._in_writers_s = time.process_time(), time.thread_time(), 0.0

    def timed(self, call, *args):
        """call(*args), a writer's work: its CPU counts as the writer's (RecorderStats)."""
        t0 = time.thread_time()
        try:
            return call(*args)
        finally:
            self._in_writers_s += time.thread_time() - t0

    def stats(self) -> tuple:
        """RecorderStats' fields: everything else this thread did is the recorder's own work; the
        writers' threads (Rerun's) are the writer's."""
        cpu_s = time.process_time() - self._cpu0
        around_s = time.thread_time() - self._thread0 - self._in_writers_s
        return (cpu_s, cpu_s - around_s, self.read)

    def take(self, written: int, *, final: bool) -> None:
        """Rows [read, written) and the others that come before row `written` (all of them when
        final)."""
        try:
            while self.queue and (final or self.queue[0][0] <= written):
                before, kind, data = self.queue.popleft()
                self._rows(min(before, written))
                if not self.failure:
                    message = pickle.loads(data)
                    for sink in self.sinks:
                        self.timed(getattr(sink, _HANDLERS[kind]), message)
            self._rows(written)
        except Exception as err:  # noqa: BLE001 - e.g. a full disk
            self.failure = (
                f"recording stopped by a writer error (what came before is kept): "
                f"{type(err).__name__}: {err}"
            )
            _abandon(self.sinks)
        self.read = max(self.read, written)

    def _rows(self, upto: int) -> None:
        if upto <= self.read:
            return
        if not self.failure:
            for frames in self.ring.runs(self.read, upto):  # views into the ring: writers copy
                for sink in self.sinks:
                    self.timed(sink.on_frames, frames)
        self.read = upto


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
