"""Recording on the machine's other core: a sink that hands the twin's stream to a recorder process,
which runs the same MCAP and Rerun writers (both in one process: twin.record.recorder).

The stepping thread packs each Frame into a ring of rows in shared memory (twin.record.ring: about a
microsecond, no system call) and every 1/15 s of simulated time publishes how far it got. The
recorder sleeps in poll() until the twin wakes it (a message down the pipe): just after each frame
at which the MCAP writer flushes its file (every 0.5 s of simulated time), or, without an MCAP
file, once the Rerun writer's take (RRD_TAKE_S) has gathered (twin.record.wakes says why so
seldom). The wake-up carries the commands, events and pictures (rare) that come before those rows.
The MCAP writer takes in every row it is woken for, the Rerun one every RRD_TAKE_S (the writers
take columns: the bigger the batch, the less each frame costs); each says how far it read. The twin
waits for the recorder only when it would go MAX_AHEAD_S of simulated time past a flush frame the
MCAP writer has not taken in (which bounds what a kill -9 of the whole run loses), or past what the
ring holds. Files are byte-for-byte what the in-process writers make, since the same writer code
sees the same stream. If the twin's process dies, the recorder sees the pipe close, takes in every
published row whose commands, events and pictures it was sent, and leaves the MCAP file
unfinalized (and recoverable, as NAME.partial). Ctrl-C, SIGTERM and SIGHUP are the twin's to
handle (it then finalizes the files): the recorder ignores them.

One process for both writers rather than one each (measured on 2 cores): it forks once (at the
twin's first Frame, its scene built), the MCAP writer starts with the other core to itself and the
Rerun writer in a thread beside it while the first is fed, and one wake-up feeds both. The twin
does not wait for either to start: it reads their start replies as they come, and stops the run at
the first failure.
"""

from __future__ import annotations

import contextlib
import marshal
import os
import time
from pathlib import Path

from twin.helpers import forking_on, keep_to, split_cpus, start_helper
from twin.model.config import TwinConfig
from twin.model.errors import RecordingError
from twin.model.images import CameraImage
from twin.model.sink import Sink
from twin.model.types import Command, Event, Frame
from twin.record.machine import machine
from twin.record.mcap.metadata import versions
from twin.record.mcap.writer import flush_steps
from twin.record.outputs import check_target
from twin.record.recorder import (
    CLOSE,
    COMMAND,
    DONE,
    EVENT,
    IMAGE,
    STARTED,
    WAKE,
    RecorderStats,
    Writer,
    pack_other,
    poller,
    serve,
)
from twin.record.ring import NO_ROW, FrameRing
from twin.record.rows import FrameRows
from twin.record.wakes import WakeSchedule

PUBLISH_S = 16 / 240  # simulated time between the twin's publishes: 16 frames at 240 Hz
# simulated time the twin may step past a flush frame the MCAP writer has not taken in: with the
# flush interval, bounds what a kill -9 loses
MAX_AHEAD_S = 0.4
# simulated time the ring holds: slack for the Rerun writer's bursts (every 8192 frames)
RING_S = 4096 / 240
# the Rerun writer takes rows in once this much has gathered: a quarter of the ring
RRD_TAKE_S = 1024 / 240
# pictures waiting for a wake-up this large wake the recorder at once (a camera's run)
OTHERS_WAKE_BYTES = 1 << 20
WAIT_S = 0.0002  # the twin's sleep while it waits for the recorder to take rows in


def check_writable(mcap_path, rrd_path, run: dict) -> None:
    """What the writers would refuse when they start, refused at once: a path whose folder is
    missing or that is a folder, and (MCAP) a run description that is not plain JSON."""
    from twin.record.mcap.metadata import check_run

    for path, expected in ((mcap_path, "an .mcap path"), (rrd_path, "a .rrd file path")):
        if path is not None:
            check_target(path, "recording", expected, error=RecordingError)
    if mcap_path is not None:
        check_run(run)


def _frames(config: TwinConfig, seconds: float) -> int:
    return max(1, round(seconds * 1e9 / config.dt_ns))


class RecorderProcess(Sink):
    """A sink (on_frame/on_command/on_event/on_image) whose writers run in a child process, both
    reading the same ring, each at its own pace."""

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
        self._capacity = capacity = max(_frames(config, RING_S), 4 * mcap_ahead)
        rrd_take = max(1, min(_frames(config, RRD_TAKE_S), capacity // 4))
        # (kind, path, how many rows it lets gather), MCAP first: ring reader 0
        wanted = [
            (kind, path, gather)
            for kind, path, gather in [("mcap", mcap_path, 1), ("rrd", rrd_path, rrd_take)]
            if path is not None
        ]
        writers = [Writer(k, path, i, gather) for i, (k, path, gather) in enumerate(wanted)]
        flushes = None
        if mcap_path is not None:
            flushes = flush_steps(config.dt_ns, rate)
            # read here, once per process, for the recorder forked from it: the MCAP writer's start
            # there went from 14.8 to 8 ms, while the twin steps toward its first wait
            versions(engine)
            machine()
        self._wakes = WakeSchedule(flushes, gather=rrd_take, ahead=mcap_ahead)
        self._ring = FrameRing(self._rows, capacity, len(writers))
        # what on_frame needs, bound once: it runs every step
        self._row_size, self._memory = self._rows.size, self._ring.memory
        # the ring's first and last rows
        self._first, self._last = self._ring.offset(0), self._ring.offset(capacity - 1)
        self._at = self._first  # where the next row goes
        self._written = 0
        # the first publish is the first frame's: the writers' start replies are read from there on
        # as they come (the twin does not wait for them: rows gather in the ring meanwhile)
        self._next_publish = 1
        # (frames before it, kind, pickle): the ones the recorder has not been sent yet
        self._others: list[tuple[int, int, bytes]] = []
        self._others_bytes = 0
        self._closed = False
        # how often the twin waited for the recorder (tools/bench_record.py reports it)
        self.waits = 0
        # Load the writers here, once: the forked recorder inherits them instead of importing anew
        # (rerun alone takes ~0.3 s to import; the MCAP writer comes with this module).
        if rrd_path is not None:
            import twin.record.rerun.writer  # noqa: F401
        # what a writer would refuse at its start, refused here, before the run: a bad path or run
        check_writable(mcap_path, rrd_path, run)
        self._child: _Child | None = None  # forked at the twin's first Frame (_fork)
        self._child_args = (writers, (self._ring, config, run, urdf, meshes, rate, engine))
        self._twins_cpus: set[int] | None = None  # the CPUs the twin's thread had before

    def _fork(self) -> None:
        """Fork the recorder, onto the other cores, and keep the twin's thread to its own one until
        the close. At the twin's first Frame, once its scene is built: after a fork, every page
        either process writes is copied first, and a scene built after it cost ~3,000 such copies
        (page faults: 32-41 ms instead of 6 ms for Twin()), its steps after it ~150."""
        cpus = split_cpus()
        try:
            with forking_on(cpus and cpus[1]):
                self._child = _Child(*self._child_args)
        except BaseException:
            self._fail_start()
            raise
        self._twins_cpus = keep_to(cpus and cpus[0])

    @property
    def _children(self) -> list[_Child]:
        """The recorder process, as a list (none before the first Frame or once forking failed)."""
        return [self._child] if self._child is not None else []

    def _check_started(self, wait: tuple[str, ...]) -> None:
        """Read the start replies the recorder has sent, waiting for those of the writers in
        `wait`; a writer that could not start ends the recording (the recorder ends the others as
        error)."""
        child = self._child
        while child.starting and (child.starting[0] in wait or child.has_reply()):
            child.starting.pop(0)
            try:
                child.expect_ok("recording could not start")
            except RecordingError:
                self._fail_start()
                raise

    def _fail_start(self) -> None:
        """A writer could not start (or forking failed): the recording is closed; the recorder
        ends the writers that started as error, then itself."""
        self._closed = True
        self._free_twins_thread()
        if self._child is not None:
            self._child.stop()

    # -- sink -------------------------------------------------------------------------------
    def on_frame(self, frame: Frame) -> None:
        at = self._at
        self._rows.pack_into(self._memory, at, frame)
        self._at = at + self._row_size if at < self._last else self._first
        self._written += 1
        if self._written == self._next_publish:
            self._publish(frame.step)

    # Commands, events and pictures (rare) are packed one by one (recorder.pack_other says how).
    def on_command(self, command: Command) -> None:
        self._keep_other(COMMAND, command)

    def on_event(self, event: Event) -> None:
        self._keep_other(EVENT, event)

    def on_image(self, image: CameraImage) -> None:
        self._keep_other(IMAGE, image)

    def _keep_other(self, kind: int, other: Command | Event | CameraImage) -> None:
        """Keep a command, event or picture for the next wake-up (the ring first says that rows
        from here on have one the recorder has not been sent)."""
        if not self._others:
            self._ring.mark_others(self._written)
        data = pack_other(kind, other)
        self._others.append((self._written, kind, data))
        self._others_bytes += len(data)

    def _publish(self, step: int) -> None:
        """The rows up to here (the last one step `step`'s) published, and the recorder woken when
        the schedule says so (twin.record.wakes), or waited for when the twin would pass its
        slack."""
        if self._child is None:
            self._fork()
        child = self._child
        if child.starting:
            self._check_started(())
        written = self._written
        reads = self._ring.publish(written)
        # then every publish_every frames from the run's start (16, 32, ...), as before the first
        # publish moved to frame 0: a task whose commands come at steps in step with the publishes
        # would see a killed run keep a frame without the commands of its step
        self._next_publish = (written // self._publish_every + 1) * self._publish_every
        wake = self._wakes.passed(written, step) or self._others_bytes >= OTHERS_WAKE_BYTES
        # a writer the ring would pass, and the MCAP writer behind a flush frame by its slack
        behind = [
            (reader, self._next_publish - self._capacity)
            for reader, read in enumerate(reads)
            if self._next_publish - read > self._capacity
        ]
        if child.writers[0] == "mcap":
            due = self._wakes.mcap_due(reads[0], self._next_publish)
            if due is not None:
                behind.append((0, due))
        if behind:
            self.waits += 1
            self._wake(written)
            for reader, read in behind:
                self._wait_until_read(reader, read)
        elif wake:
            self._wake(written)

    def _wait_until_read(self, reader: int, read: int) -> None:
        """Wait until the recorder (woken) has taken rows [0, read) in as ring reader `reader`."""
        child = self._child
        while self._ring.read(reader) < read:
            if not child.has_reply():
                time.sleep(WAIT_S)
            elif child.starting:  # the Rerun writer says it started (or could not)
                self._check_started(())
            else:  # it says nothing else before the close: this is the pipe's end
                raise RecordingError(f"the recorder process stopped: {child.exit_text()}")

    def _wake(self, written: int) -> None:
        """Have the recorder take in rows [0, written): the wake-up carries the others it has not
        had yet (all of them come before row `written`), so it wakes once for both."""
        self._child.wake(written, self._others)
        self._wakes.woken(written)
        if self._others:
            self._ring.mark_others(NO_ROW)
            self._others, self._others_bytes = [], 0

    def close(self, outcome: str = "ok", error: str = "") -> None:
        """Publish what is left, have the writers finalize, wait for them (the first failure is
        raised once all have finished). Idempotent."""
        if self._closed:
            return
        if self._child is None:  # no Frame came: the files still say how the run ended
            self._fork()
        if self._child.starting:  # a start failure already said: the others end as error
            self._check_started(())
        self._closed = True
        self._free_twins_thread()
        child = self._child
        child.spread()  # the twin waits from here on: the recorder may use its core too
        self._ring.publish(self._written)
        # a recorder that has stopped cannot be woken: finish says why (a start failure it said
        # first, else that it stopped)
        with contextlib.suppress(RecordingError):
            self._wake(self._written)
        child.finish(outcome, error)

    def _free_twins_thread(self) -> None:
        """The twin's thread may run on every CPU it could before the recording again."""
        keep_to(self._twins_cpus)
        self._twins_cpus = None

    @property
    def stats(self) -> RecorderStats | None:
        """The finished recorder's RecorderStats (None before): tools/bench_record.py reports
        them."""
        return self._child.stats if self._child is not None else None


class _Child:
    """The recorder process and the twin's end of its pipe."""

    def __init__(self, writers: list[Writer], args: tuple) -> None:
        self.writers = [w.kind for w in writers]  # by ring reader
        self.starting = list(self.writers)  # the writers whose start reply is yet to come
        self.wakes = 0  # wake-ups the twin sent it
        # what the recorder said of its CPU at the end (RecorderStats), None before
        self.stats: RecorderStats | None = None
        self.conn, self.process = start_helper(self, serve, (writers, *args), name="twin-recorder")
        self._poller = poller(self.conn)

    def send(self, message: bytes) -> None:
        try:
            self.conn.send_bytes(message)
        except OSError as err:
            raise RecordingError(f"the recorder process stopped: {self.exit_text()}") from err

    def has_reply(self) -> bool:
        """True when the recorder has said something (or its end of the pipe has closed)."""
        return bool(self._poller.poll(0))

    def wake(self, written: int, others: list) -> None:
        """Rows [0, written) are published: have the recorder take them in, with `others` (the
        commands, events and pictures that come before them it has not had)."""
        self.wakes += 1
        self.send(WAKE + marshal.dumps((written, others)))

    def spread(self) -> None:
        """Let the recorder run on every CPU the twin's process may use (it was kept off the
        twin's): each of its threads, since an affinity is a thread's own (the Rerun writer's
        thread and the Rerun SDK's as well as its main one)."""
        pid = self.process.pid
        try:
            cpus = os.sched_getaffinity(0)
        except (AttributeError, OSError):  # the system does not say
            return
        try:
            threads = [int(tid) for tid in os.listdir(f"/proc/{pid}/task")]
        except OSError:  # gone, or no /proc: the process's own (main thread's) affinity
            threads = [pid]
        for tid in threads:
            with contextlib.suppress(OSError):  # a thread that has ended
                os.sched_setaffinity(tid, cpus)

    def expect_ok(self, what: str) -> None:
        try:
            reply = self.conn.recv_bytes()
        except (EOFError, OSError) as err:
            raise RecordingError(
                f"{what}: the recorder process stopped ({self.exit_text()})"
            ) from err
        if reply == STARTED:
            return
        if reply.startswith(DONE):
            self.stats = RecorderStats(*marshal.loads(reply[len(DONE) :]))
            return
        self.process.join(timeout=5)
        raise RecordingError(reply.decode(errors="replace"))

    def finish(self, outcome: str, error: str) -> None:
        """Have the writers finalize with the run's outcome and wait for them (or their failure:
        RecordingError), not for the process's exit. The start replies still due come first (a
        writer that could not start: the recorder ends the others as error)."""
        try:
            self.conn.send_bytes(CLOSE + marshal.dumps((outcome, error)))
            sent: OSError | None = None
        except OSError as err:
            sent = err
        try:
            while self.starting:
                self.starting.pop(0)
                self.expect_ok("recording could not start")
            if sent is not None:
                raise RecordingError(
                    f"recording could not be finished: the recorder process stopped "
                    f"({self.exit_text()})"
                ) from sent
            self.expect_ok("recording could not be finished")
        except RecordingError:
            self.stop()
            raise
        # the files are finalized: the process's exit (2-6 ms to unmap what it shares with this
        # one) is not waited for, nor is a thread started to wait for it (1.6-4.8 ms, the other
        # core busy with that exit): multiprocessing reaps it at the next process it starts, or at
        # this one's exit
        self.conn.close()

    def stop(self) -> None:
        self.conn.close()
        self.process.join(timeout=30)

    def exit_text(self) -> str:
        self.process.join(timeout=1)
        code = self.process.exitcode
        return "still running" if code is None else f"exit code {code}"
