"""Recording a run: `open_recorders(...)` gives the sinks (MCAP, optionally Rerun) and ends them
cleanly."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from twin.model.config import TwinConfig
from twin.model.errors import TwinError, exception_text
from twin.model.sink import close_all
from twin.robot.urdf import mesh_paths, urdf_text
from twin.signals import Terminated


@contextmanager
def open_recorders(
    config: TwinConfig,
    run: dict,
    *,
    mcap_path: str | Path | None = None,
    rrd_path: str | Path | None = None,
    rate: int = 1,
    background: bool = True,
    engine: dict[str, str] | None = None,
) -> Iterator[list]:
    """Yield the sinks to pass to Twin(..., sinks=...). On exit every file is closed; the MCAP file
    is finalized with run_outcome ok, or error/interrupted (and the message) when the block raised
    (interrupted: Ctrl-C, SIGTERM or SIGHUP). Files are written as NAME.partial and renamed into
    place when finalized; the folders must exist.

    background: the writers run in a recorder process on the other core (the same files, byte for
    byte, at a fraction of the stepping thread's time); False keeps them in this process.
    engine: the simulation's versions the MCAP file names (sim.world.engine_versions())."""
    from twin.record.mcap.writer import McapRecorder

    urdf = urdf_text(config.profile)
    meshes = mesh_paths(config.profile)
    sinks: list = []
    try:
        if background and (mcap_path is not None or rrd_path is not None):
            from twin.record.process import RecorderProcess

            sinks.append(
                RecorderProcess(
                    config,
                    run,
                    urdf=urdf,
                    meshes=meshes,
                    mcap_path=mcap_path,
                    rrd_path=rrd_path,
                    rate=rate,
                    engine=engine,
                )
            )
        elif mcap_path is not None:
            sinks.append(
                McapRecorder(
                    mcap_path, config, run, urdf=urdf, meshes=meshes, rate=rate, engine=engine
                )
            )
        if rrd_path is not None and not background:
            from twin.record.rerun.writer import RerunRecorder

            sinks.append(RerunRecorder(rrd_path, config, urdf))
    except BaseException as err:
        _note(err, close_all(sinks, "error", "recording could not start"))
        raise
    try:
        yield sinks
    except (KeyboardInterrupt, Terminated) as err:
        why = str(err) if isinstance(err, Terminated) else "KeyboardInterrupt"  # SIGTERM, SIGHUP
        _note(err, close_all(sinks, "interrupted", why))
        raise
    except BaseException as err:
        _note(err, close_all(sinks, "error", _error_text(err)))
        raise
    # a task error the caller suppressed: the MCAP writer says error
    failure = close_all(sinks, "ok", "")
    if failure is not None:
        raise failure


def _error_text(err: BaseException) -> str:
    """The exception as the finalized marker's one line, its type named unless it is one of ours."""
    text = exception_text(err)
    return text if isinstance(err, TwinError) else f"{type(err).__name__}: {text}"


def _note(err: BaseException, failure: Exception | None) -> None:
    """The run's own exception stays the one raised; a failure to close rides along as a note."""
    if failure is not None:
        err.add_note(f"while closing the recordings: {failure}")
