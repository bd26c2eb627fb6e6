"""Replay: rebuild a twin from a recording's metadata alone and feed its Commands back.

A run is a pure function of (configuration, commands): replaying the commands of step s before
the physics step that starts at s reproduces the frames bit for bit on the same machine. What a task
or client says (phases, placement reports, task start/end, log lines) is an `event` Command like any
other input, so a replay says it again at the same step and every event compares. Recordings made
before that was so carry only the twin's own events (REPLAYED_EVENT_KINDS) in replayable form.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from twin.model.config import TwinConfig
from twin.model.errors import RecordingError
from twin.model.images import tracks
from twin.model.recording import Recording
from twin.record.images import recorded_images
from twin.record.tables import RecordingWithTables
from twin.sim.twin import Sink, Twin
from twin.sim.world import engine_versions
from twin.verify.collectors import ColumnCollector, FrameCollector

# Events the twin itself emits while applying commands and stepping (not the task's annotations).
REPLAYED_EVENT_KINDS = frozenset(
    {"attach", "release", "break", "suction_empty", "joint_limit", "key_unknown"}
)


def replayed_event_kinds(rec: Recording) -> frozenset[str] | None:
    """The event kinds a replay of rec reproduces: all (None) when what its task or clients said is
    recorded as `event` Commands, or when it holds only the twin's own events; else (a recording
    from before annotations were Commands) just the twin's own."""
    if any(c.kind == "event" for c in rec.commands) or all(
        e.kind in REPLAYED_EVENT_KINDS for e in rec.events
    ):
        return None
    return REPLAYED_EVENT_KINDS


def replay_run(rec: Recording) -> dict:
    """The run description of a replay of rec: rec's own, plus which file it replays (name and
    hash)."""
    import hashlib

    run = {k: v for k, v in (rec.run or {}).items() if k != "replay_of"}
    source = {"file": Path(rec.path).name if rec.path else "<memory>"}
    if rec.path and Path(rec.path).is_file():
        source["sha256"] = hashlib.sha256(Path(rec.path).read_bytes()).hexdigest()
    return {**run, "replay_of": source}


def collected(
    collector: FrameCollector | ColumnCollector, rec_config, run: dict, *, path: str = ""
) -> RecordingWithTables:
    """An in-memory Recording of what a collector saw."""
    return RecordingWithTables(
        config=rec_config,
        frames=collector.columns(),
        commands=list(collector.commands),
        events=list(collector.events),
        run=dict(run),
        meta={},
        finalized=True,
        path=path,
        cameras=tracks(rec_config.cameras, collector.images),
    )


def replay(rec: Recording, *, sinks: Sequence[Sink] = ()) -> RecordingWithTables:
    """Re-run rec's commands on a fresh twin built from rec.config, up to rec's last step."""
    if len(rec.frames) == 0:
        raise RecordingError(f"recording {rec.path or '<memory>'} has no frames to replay")
    first, last = int(rec.frames.step[0]), int(rec.frames.step[-1])
    if first != 0:
        raise RecordingError(
            f"recording {rec.path or '<memory>'} starts at step {first}; replay needs step 0"
        )
    # stable: keeps the recorded order within a step
    commands = sorted(rec.commands, key=lambda c: c.step)
    if commands and commands[-1].step > last:
        raise RecordingError(
            f"recording {rec.path or '<memory>'} has a command at step {commands[-1].step}, "
            f"after its last frame (step {last})"
        )
    collector = ColumnCollector()
    with _robot_files(rec) as config:
        twin = Twin(config, sinks=[collector, *sinks])
    try:
        i = 0
        while True:
            while i < len(commands) and commands[i].step == twin.step_index:
                twin.apply(commands[i])
                i += 1
            if twin.step_index >= last:
                break
            next_step = commands[i].step if i < len(commands) else last
            twin.step(max(1, min(next_step, last) - twin.step_index))
    finally:
        twin.close()
    return collected(collector, rec.config, rec.run, path="<replay>")


@contextmanager
def _robot_files(rec: Recording) -> Iterator[TwinConfig]:
    """The recording's config; for a user's URDF robot, pointed at the URDF and meshes the recording
    carries (written to a temporary folder), so replay needs nothing outside the file."""
    profile = rec.config.profile
    if not profile.urdf_path or "robot.urdf" not in rec.assets:
        yield rec.config
        return
    with tempfile.TemporaryDirectory(prefix="twin_replay_robot_") as folder:
        root = Path(folder).resolve()
        for name, data in rec.assets.items():
            target = (root / name).resolve()
            if root not in target.parents:  # an attachment name must not escape the folder
                raise RecordingError(
                    f"recording {rec.path or '<memory>'} has an attachment named {name!r}; "
                    "expected a path inside the robot's folder"
                )
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        yield dataclasses.replace(
            rec.config, profile=dataclasses.replace(profile, urdf_path=str(root / "robot.urdf"))
        )


def feed(rec: Recording, sinks: Sequence[Sink]) -> None:
    """Send a recording's frames, pictures, commands and events to sinks, step by step: frame s,
    then the pictures, commands and events stamped s (those happen after frame s, before frame s +
    1)."""
    commands = sorted(rec.commands, key=lambda c: c.step)
    events = sorted(rec.events, key=lambda e: e.step)
    images = recorded_images(rec.config.cameras, rec.cameras, rec.frames.step, rec.frames.pad_pose)
    ci = ei = mi = 0
    steps = rec.frames.step
    for i in range(len(rec.frames)):
        frame = rec.frames.frame(i)
        for s in sinks:
            s.on_frame(frame)
        upto = int(steps[i + 1]) if i + 1 < len(steps) else None
        # pictures come right after their frame
        while mi < len(images) and (upto is None or images[mi].step < upto):
            for s in sinks:
                s.on_image(images[mi])
            mi += 1
        while ci < len(commands) and (upto is None or commands[ci].step < upto):
            for s in sinks:
                s.on_command(commands[ci])
            ci += 1
        while ei < len(events) and (upto is None or events[ei].step < upto):
            for s in sinks:
                s.on_event(events[ei])
            ei += 1


def save(rec: Recording, path: str | os.PathLike, *, rate: int = 1) -> None:
    """Write an in-memory recording to an MCAP file (the same writer as `twin run --record`)."""
    from twin.record import open_recorders

    with open_recorders(
        rec.config, rec.run, mcap_path=path, rate=rate, engine=engine_versions()
    ) as sinks:
        feed(rec, sinks)
