"""Recording a run: `open_recorders(...)` gives the sinks (MCAP, optionally Rerun) and ends them cleanly."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from twin.errors import TwinError
from twin.model.config import TwinConfig
from twin.model.sink import Sink
from twin.robot.urdf import mesh_paths, urdf_text
from twin.signals import Terminated


@contextmanager
def open_recorders(config: TwinConfig, run: dict, *, mcap_path: str | Path | None = None,
                   rrd_path: str | Path | None = None, rate: int = 1, background: bool = True) -> Iterator[list]:
    """Yield the sinks to pass to Twin(..., sinks=...). On exit every file is closed; the MCAP file is
    finalized with run_outcome ok, or error/interrupted (and the message) when the block raised
    (interrupted: Ctrl-C, SIGTERM or SIGHUP). Files are written as NAME.partial and renamed into place
    when finalized; the folders must exist.

    background: the writers run in a recorder process on the other core (the same files, byte for
    byte, at a fraction of the stepping thread's time); False keeps them in this process."""
    from twin.record.mcap.writer import McapRecorder

    urdf = urdf_text(config.profile)
    meshes = mesh_paths(config.profile)
    sinks: list = []
    try:
        if background and (mcap_path is not None or rrd_path is not None):
            from twin.record.process import RecorderProcess

            sinks.append(RecorderProcess(config, run, urdf=urdf, meshes=meshes,
                                         mcap_path=mcap_path, rrd_path=rrd_path, rate=rate))
        elif mcap_path is not None:
            sinks.append(McapRecorder(mcap_path, config, run, urdf=urdf, meshes=meshes,
                                      rate=rate))
        if rrd_path is not None and not background:
            from twin.record.rerun.writer import RerunRecorder

            sinks.append(RerunRecorder(rrd_path, config, urdf))
    except BaseException as err:
        _note(err, _close_all(sinks, "error", "recording could not start"))
        raise
    said = _TaskErrors()
    sinks.append(said)
    try:
        yield sinks
    except (KeyboardInterrupt, Terminated) as err:
        why = str(err) if isinstance(err, Terminated) else "KeyboardInterrupt"  # SIGTERM, SIGHUP
        _note(err, _close_all(sinks, "interrupted", why))
        raise
    except BaseException as err:
        _note(err, _close_all(sinks, "error", _error_text(err)))
        raise
    failure = _close_all(sinks, *said.outcome())  # a task error the caller suppressed is still an error
    if failure is not None:
        raise failure


class _TaskErrors(Sink):
    """A sink that remembers the first task_error, so a run whose task raised is never finalized as ok,
    even when the caller caught the exception (twin check records a crashing task as a run to compare)."""

    def __init__(self) -> None:
        self.error = ""

    def on_frame(self, frame) -> None:
        pass

    def on_command(self, command) -> None:
        pass

    def on_event(self, event) -> None:
        if event.kind == "task_error" and not self.error:
            self.error = event.message or "task error"

    def outcome(self) -> tuple[str, str]:
        return ("error", self.error) if self.error else ("ok", "")


def _error_text(err: BaseException) -> str:
    """The exception as the finalized marker's one line; even one whose __str__ itself raises."""
    try:
        text = str(err)
    except Exception as inner:  # noqa: BLE001 - a user's exception class may be broken
        text = f"<unprintable: its __str__ raised {type(inner).__name__}>"
    return text if isinstance(err, TwinError) else f"{type(err).__name__}: {text}"


def _close_all(sinks: list, outcome: str, error: str) -> Exception | None:
    """Close every sink even if one fails; return the first failure."""
    first: Exception | None = None
    for sink in sinks:  # every sink closes the same way (model.sink.Sink)
        try:
            sink.close(outcome=outcome, error=error)
        except Exception as err:  # noqa: BLE001 - keep closing the others
            first = first or err
    return first


def _note(err: BaseException, failure: Exception | None) -> None:
    """The run's own exception stays the one raised; a failure to close rides along as a note."""
    if failure is not None:
        err.add_note(f"while closing the recordings: {failure}")
