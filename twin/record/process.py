"""Recording on the machine's other core: a sink that batches the twin's stream to recorder
processes, which run the same MCAP and Rerun writers (one process each).

The stepping thread then does one to two microseconds of work a frame (the Frame packed into a
preallocated row buffer, model.rows, and a share of one pipe write per batch) instead of the writers'
encoding and compression; the writers take each batch's rows as columns. (In wall time a step costs
more than that work: the recorder processes share the second core, and slow the first; README.) Files are
byte-for-byte what the in-process writers make, since the same writer code sees the same stream.
If the twin's process dies, the recorder sees the pipe close and leaves the MCAP file unfinalized
(and recoverable, as NAME.partial) with everything that reached it. Ctrl-C, SIGTERM and SIGHUP are
the twin's to handle (it then finalizes the files): the recorder ignores them.
"""

from __future__ import annotations

import marshal
import os
import pickle
import struct
import sys
from pathlib import Path

from twin.errors import RecordingError
from twin.helpers import start_helper
from twin.model.config import TwinConfig
from twin.model.images import CameraImage
from twin.model.rows import FrameRows
from twin.model.sink import Sink, close_all
from twin.model.types import Command, Event, Frame

BATCH_S = 32 / 240  # simulated time per pipe write: 32 frames at 240 Hz
MAX_IN_FLIGHT = 2  # batches sent but not yet taken in by the MCAP writer: bounds what a kill -9 loses
MAX_IN_FLIGHT_VIEW = 16  # the same for the .rrd (about 2 s of simulated time): slack for its bursts
_ACK = b"+"  # the recorder took in one batch
_BATCH, _CLOSE = b"B", b"C"
_COMMAND, _EVENT = 0, 1
_IMAGE = 2  # a camera's picture (model.images.CameraImage), pickled like events
_HANDLERS = {_COMMAND: "on_command", _EVENT: "on_event", _IMAGE: "on_image"}  # item kind -> the sinks' method
_HEAD = struct.Struct("<cI")  # tag, frames in the batch; then their rows, then the marshalled others


class RecorderProcess(Sink):
    """A sink (on_frame/on_command/on_event/on_image) whose writers run in child processes: one for
    the MCAP file, one for the .rrd, each fed the same batches. Apart, a burst of the Rerun writer
    (it sends its columns every 2048 frames) cannot hold the MCAP writer, nor the twin, up."""

    def __init__(self, config: TwinConfig, run: dict, *, urdf: str, meshes: list[Path],
                 mcap_path: str | Path | None, rrd_path: str | Path | None, rate: int) -> None:
        self._rows = FrameRows(len(config.profile.joint_names), len(config.objects))
        self._batch_frames = max(1, round(BATCH_S * 1e9 / config.dt_ns))
        self._buf = bytearray(_HEAD.size + self._batch_frames * self._rows.size)  # the next batch
        self._frames = 0
        self._others: list[tuple[int, int, bytes]] = []  # (frames before it in the batch, kind, pickle)
        self._closed = False
        # Load the writers here, once: every forked recorder inherits them instead of importing anew
        # (rerun alone takes ~0.3 s to import).
        import twin.record.mcap.writer
        if rrd_path is not None:
            import twin.record.rerun.writer  # noqa: F401
        self._children: list[_Child] = []
        writers = [("mcap", mcap_path, MAX_IN_FLIGHT), ("rrd", rrd_path, MAX_IN_FLIGHT_VIEW)]
        starting = None
        try:
            for writer, path, max_in_flight in writers:
                if path is not None:
                    self._children.append(_Child(writer, max_in_flight, self._children, (
                        config, run, urdf, meshes, path, rate)))
            for starting in self._children:  # they start side by side; each says when it is ready
                starting.expect_ok("recording could not start")
        except BaseException:
            for child in self._children:  # as one process with both writers did: the others end as error
                if child is starting:
                    child.stop()
                    continue
                try:
                    child.finish("error", "recording could not start")
                except RecordingError:
                    pass
            raise

    # -- sink -------------------------------------------------------------------------------
    def on_frame(self, frame: Frame) -> None:
        self._rows.pack_into(self._buf, _HEAD.size + self._frames * self._rows.size, frame)
        self._frames += 1
        if self._frames >= self._batch_frames:
            self._send()

    # Commands and events (rare) are pickled one by one: their data comes from tasks and may hold
    # values marshal would silently turn into bytes (anything with a buffer, e.g. numpy scalars).
    def on_command(self, command: Command) -> None:
        self._others.append((self._frames, _COMMAND, pickle.dumps(command, protocol=pickle.HIGHEST_PROTOCOL)))

    def on_event(self, event: Event) -> None:
        self._others.append((self._frames, _EVENT, pickle.dumps(event, protocol=pickle.HIGHEST_PROTOCOL)))

    def on_image(self, image: CameraImage) -> None:
        self._others.append((self._frames, _IMAGE, pickle.dumps(image, protocol=pickle.HIGHEST_PROTOCOL)))

    def _send(self) -> None:
        """One batch to every recorder."""
        end = _HEAD.size + self._frames * self._rows.size
        _HEAD.pack_into(self._buf, 0, _BATCH, self._frames)
        payload = b"".join((memoryview(self._buf)[:end], marshal.dumps(self._others)))
        self._others.clear()
        self._frames = 0
        for child in self._children:
            child.send(payload)

    def close(self, outcome: str = "ok", error: str = "") -> None:
        """Send what is buffered, have the writers finalize, wait for them (the first failure is
        raised once all have finished). Idempotent."""
        if self._closed:
            return
        self._closed = True
        failure: RecordingError | None = None
        try:
            if self._frames or self._others:
                self._send()
        except RecordingError as err:
            failure = err
        for child in self._children:
            try:
                child.finish(outcome, error)
            except RecordingError as err:
                failure = failure or err
        if failure is not None:
            raise failure


class _Child:
    """One recorder process and the twin's end of its pipe. At most `max_in_flight` batches wait in
    the pipe or the writer's intake: for the MCAP file that bounds what a kill -9 loses (a full pipe,
    64 KiB or ~6 batches, would hold ~0.8 s more of simulated time: measured up to 1.8 s lost with
    --rrd when it was not bounded); the view gets more slack, so its bursts do not stall the twin."""

    def __init__(self, writer: str, max_in_flight: int, siblings: list[_Child], args: tuple) -> None:
        self.writer = writer
        self.max_in_flight = max_in_flight
        self.in_flight = 0
        self.conn, self.process = start_helper(self, _serve, (writer, *args), name=f"twin-recorder-{writer}",
                                               other_ends=[s.conn for s in siblings])

    def send(self, payload: bytes) -> None:
        try:
            while self.in_flight >= self.max_in_flight:
                if self.conn.recv_bytes() != _ACK:
                    raise EOFError("unexpected reply")
                self.in_flight -= 1
            self.conn.send_bytes(payload)
            self.in_flight += 1
        except (EOFError, BrokenPipeError, ConnectionResetError, OSError) as err:
            raise RecordingError(f"the recorder process stopped: {self._exit_text()}") from err

    def expect_ok(self, what: str) -> None:
        try:
            reply = self.conn.recv_bytes()
            while reply == _ACK:  # batches taken in before the answer
                reply = self.conn.recv_bytes()
        except (EOFError, OSError) as err:
            raise RecordingError(f"{what}: the recorder process stopped ({self._exit_text()})") from err
        if reply != b"OK":
            self.process.join(timeout=5)
            raise RecordingError(reply.decode(errors="replace"))

    def finish(self, outcome: str, error: str) -> None:
        """Have the writer finalize with the run's outcome and wait for it."""
        try:
            try:
                self.conn.send_bytes(_CLOSE + marshal.dumps((outcome, error)))
            except OSError as err:
                raise RecordingError(f"recording could not be finished: the recorder process stopped "
                                     f"({self._exit_text()})") from err
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


def _serve(conn, writer: str, config: TwinConfig, run: dict, urdf: str, meshes: list[Path],
           path: str | Path, rate: int) -> None:
    """A recorder process: build its writer ("mcap" or "rrd"), feed it each batch, finish on request.

    A writer that fails stops the recording there (what was written is kept, unfinalized, as after a
    crash); the process then waits for the close request and answers it with the failure, so the
    twin reports it as one line instead of losing the run's remaining output."""
    if "pandas" not in sys.modules:  # pyarrow (under rerun) would import it, 0.3 s, only to ask
        sys.meta_path.insert(0, _NoPandas())  # whether arrays are pandas objects: they never are here
    from twin.record.mcap.writer import McapRecorder  # already loaded by the parent
    rows = FrameRows(len(config.profile.joint_names), len(config.objects))

    sinks = []
    try:
        if writer == "mcap":
            sinks.append(McapRecorder(path, config, run, urdf=urdf, meshes=meshes, rate=rate))
        else:
            from twin.record.rerun.writer import RerunRecorder

            sinks.append(RerunRecorder(path, config, urdf))
    except Exception as err:  # noqa: BLE001 - reported to the twin's process as one line
        _close_all(sinks, "error", "recording could not start")
        conn.send_bytes(str(err).encode())
        os._exit(0)
    conn.send_bytes(b"OK")
    failure = ""
    while True:
        try:
            message = conn.recv_bytes()
        except (EOFError, OSError):  # the twin's process died: keep what arrived, unfinalized
            if not failure:
                _abandon(sinks)
            os._exit(0)
        tag, body = message[:1], message[1:]
        if tag == _CLOSE:
            if not failure:
                failure = _close_all(sinks, *marshal.loads(body))
            conn.send_bytes(failure.encode() if failure else b"OK")
            os._exit(0)
        if not failure:  # after a failure: drain until the twin closes, it learns of the failure then
            try:
                _feed(message, rows, sinks)
            except Exception as err:  # noqa: BLE001 - e.g. a full disk
                failure = f"recording stopped by a writer error (what came before is kept): {type(err).__name__}: {err}"
                _abandon(sinks)
        try:
            conn.send_bytes(_ACK)
        except OSError:  # the twin's process died: keep what arrived, unfinalized
            if not failure:
                _abandon(sinks)
            os._exit(0)


def _feed(batch: bytes, rows: FrameRows, sinks: list) -> None:
    """One batch to every sink in the order the twin made it: runs of frames (as rows), and between
    them the commands and events that came after the frames before them."""
    n_frames = _HEAD.unpack_from(batch)[1]
    view = memoryview(batch)
    at = _HEAD.size
    done = 0
    for before, kind, data in [*marshal.loads(view[at + n_frames * rows.size:]), (n_frames, None, b"")]:
        if before > done:
            run = view[at + done * rows.size:at + before * rows.size]
            for sink in sinks:
                sink.on_rows(rows, run)
            done = before
        if kind is not None:
            message = pickle.loads(data)
            for sink in sinks:
                getattr(sink, _HANDLERS[kind])(message)


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

