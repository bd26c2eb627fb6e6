"""`twin info`: what a recording holds and whether it was finalized, also for a file cut short.

It reads what it can and says what it could not: `problems` lists every part that is unreadable (the
configuration, the run, events, commands, blocks, the robot description) or foreign (no twin
configuration); `twin info` prints the report and then exits 2 when there is any, or when the file
is cut short. Messages are taken as they are read: counted by channel, events kept (for --events),
nothing per message of any other channel.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from twin.model.config import TwinConfig
from twin.model.errors import RecordingError
from twin.model.types import Event
from twin.record.machine import machine_text
from twin.record.mcap import schemas as S
from twin.record.mcap.metadata import parse_config, parse_run
from twin.record.mcap.reader import (
    Message,
    Scan,
    block_steps,
    parse_command,
    parse_event,
    parse_robot_description,
    scan,
)


@dataclass
class Info:
    path: str
    size_bytes: int
    intact: bool  # the file ends with an MCAP footer
    problem: str
    finalized: bool
    finished: dict[str, str]  # the finalized marker (outcome, error, last_step, ...)
    recovered: dict[str, str]
    run: dict
    robot: str
    objects: list[str]
    dt_ns: int
    frames: int
    first_step: int
    last_step: int
    channels: list[tuple[str, str, str, int]]  # topic, schema, encoding, messages
    events: dict[str, int]  # readable events by kind
    commands: int  # readable commands
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[tuple[str, int]] = field(default_factory=list)
    config: TwinConfig | None = None  # what the run was: robot, scene, pad, cameras
    event_list: list[Event] = field(default_factory=list)  # every readable event, in file order
    machine: dict[str, str] = field(default_factory=dict)  # where it was made; empty in older files
    # what is unreadable or foreign: twin info exits 2
    problems: list[str] = field(default_factory=list)


# unreadable messages of one topic counted one by one; past that, reading it stops
MAX_UNREADABLE = 1000
MAX_KINDS = 1000  # distinct event kinds counted by name; any more are counted together


class _Reading:
    """Takes the messages twin info describes as the scan reads them: the joint blocks' steps, the
    events (kept only for --events), the commands and the robot description; counts the unreadable
    ones with the first reason. Nothing is kept per message but the events asked for."""

    TOPICS = frozenset(
        (S.JOINTS.topic, S.EVENTS.topic, S.COMMANDS.topic, S.ROBOT_DESCRIPTION.topic)
    )

    def __init__(self, keep_events: bool) -> None:
        self.keep_events = keep_events
        self.frames, self.first_step, self.last_step = 0, -1, -1
        self.events: list[Event] = []
        self.kinds: Counter[str] = Counter()
        self.commands = 0
        self.unreadable: dict[str, list] = {}  # topic -> [count, first reason]

    def take(self, s: Scan, topic: str, m: Message) -> None:
        try:
            if topic == S.JOINTS.topic:
                steps = block_steps(m)
                if not steps.size:
                    raise RecordingError("a block holds no frame")
                self.frames += int(steps.size)
                self.first_step = int(steps[0]) if self.first_step < 0 else self.first_step
                self.last_step = int(steps[-1])
            elif topic == S.EVENTS.topic:
                event = parse_event(m.data, s.path)
                kind = event.kind[:60]
                self.kinds[
                    "(other kinds)"
                    if kind not in self.kinds and len(self.kinds) >= MAX_KINDS
                    else kind
                ] += 1
                if self.keep_events:
                    self.events.append(event)
            elif topic == S.COMMANDS.topic:
                parse_command(m.data, s.path)
                self.commands += 1
            elif topic == S.ROBOT_DESCRIPTION.topic:
                s.stop_keeping(topic)  # the first one is the robot's (twin writes one)
                parse_robot_description(m.data, s.path)
        except RecordingError as err:
            entry = self.unreadable.setdefault(
                topic, [0, str(err).removeprefix(f"recording {s.path!r}: ")]
            )
            entry[0] += 1
            if entry[0] >= MAX_UNREADABLE:
                s.stop_keeping(topic)

    def problems(self, s: Scan) -> list[str]:
        out = []
        for topic, (count, reason) in self.unreadable.items():
            total = s.message_count_of(topic)
            what = "message" if total == 1 else "messages"
            at_least = (
                f"at least {count:,} (then reading them stopped)"
                if count >= MAX_UNREADABLE
                else f"{count:,}"
            )
            out.append(
                f"{at_least} of its {total:,} {topic} {what} "
                f"{'is' if count == 1 else 'are'} unreadable "
                f"(the first: {reason[:160]})"
            )
        return out


def read_info(path: str | Path, *, keep_events: bool = True) -> Info:
    """Read as much of the file as is readable and summarize it (RecordingError if it is not an MCAP
    file at all); what is unreadable or foreign is listed in `problems`. keep_events: keep every
    readable event in `event_list` (else only their counts by kind)."""
    reading = _Reading(keep_events)
    s = scan(path, strict=False, topics=_Reading.TOPICS, consume=reading.take)
    problems = []
    config = None
    if S.META_CONFIG in s.metadata:
        try:
            config = parse_config(s.metadata, repr(s.path))
        except RecordingError as err:
            problems.append(str(err).removeprefix(f"{s.path!r}: "))
    else:
        problems.append(
            f"it has no {S.META_CONFIG} metadata: it was not written by twin"
            + (f" (written by {s.library[:60]!r})" if s.library and s.library != S.LIBRARY else "")
        )
    try:
        run = parse_run(s.metadata, repr(s.path))
    except RecordingError as err:
        problems.append(str(err).removeprefix(f"{s.path!r}: "))
        run = {}
    problems += reading.problems(s)
    channels = []
    for cid, channel in sorted(s.channels.items()):
        schema = s.schemas.get(channel.schema_id)
        channels.append(
            (
                channel.topic,
                schema.name if schema else "",
                channel.message_encoding,
                s.counts.get(cid, 0),
            )
        )
    return Info(
        path=s.path,
        size_bytes=s.size_bytes,
        intact=s.complete,
        problem=s.problem,
        finalized=s.complete and S.META_FINALIZED in s.metadata,
        finished=s.metadata.get(S.META_FINALIZED, {}),
        recovered=s.metadata.get(S.META_RECOVERED, {}),
        run=run,
        robot=config.profile.name if config else "",
        objects=[o.name for o in config.objects] if config else [],
        dt_ns=config.dt_ns if config else 0,
        frames=reading.frames,
        first_step=reading.first_step,
        last_step=reading.last_step,
        channels=channels,
        events=dict(sorted(reading.kinds.items())),
        commands=reading.commands,
        metadata={k: v for k, v in sorted(s.metadata.items()) if k != S.META_CONFIG},
        attachments=[(a.name, len(a.data)) for a in s.attachments],
        config=config,
        event_list=reading.events,
        machine=dict(s.metadata.get(S.META_MACHINE, {})),
        problems=[" ".join(p.split()) for p in problems],  # one line each
    )


def format_info(info: Info, *, all_events: bool = False) -> list[str]:
    """The human-readable report `twin info` prints; with all_events, every event with its time and
    data."""
    if info.finalized:
        outcome = info.finished.get("outcome", "?")
        state = f"yes (run outcome {outcome}" + (
            f": {info.finished['error']})" if info.finished.get("error") else ")"
        )
    elif info.recovered:
        state = (
            f"no - recovered from {info.recovered.get('source', '?')} "
            f"({info.recovered.get('problem', 'cut short')}); the run's end is missing"
        )
    elif info.intact:
        state = "no - the file is complete but has no finalized marker"
    else:
        state = f"no - {info.problem} (killed or still being written)"
    lines = [f"file: {info.path} ({info.size_bytes:,} bytes)", f"finalized: {state}"]
    params = json.dumps(info.run.get("params", {}), sort_keys=True)
    lines.append(f"run: {info.run.get('source', '')} {info.run.get('task', '')} params {params}")
    replay_of = info.run.get("replay_of")
    if isinstance(replay_of, dict):
        lines.append(
            f"a replay of {replay_of.get('file', '?')} (sha256 "
            f"{str(replay_of.get('sha256', '?'))[:12]}...)"
        )
    lines.append(
        f"robot: {info.robot or '?'}; objects: {', '.join(info.objects) or 'none'}; "
        f"time step {info.dt_ns:,} ns"
    )
    lines.append(f"machine: {machine_text(info.machine) if info.machine else 'not recorded'}")
    if info.frames:
        duration_s = info.last_step * info.dt_ns * 1e-9
        lines.append(
            f"duration: {duration_s:.3f} s simulated; steps {info.first_step}..{info.last_step}, "
            f"{info.frames:,} frames recorded"
        )
    else:
        lines.append("duration: no frames")
    lines.append("channels:")
    width = max((len(c[0]) for c in info.channels), default=0)
    for topic, schema, encoding, count in info.channels:
        lines.append(f"  {topic:<{width}}  {count:>7,} messages  {schema} ({encoding})")
    events = ", ".join(f"{k} {v}" for k, v in info.events.items()) or "none"
    lines.append(f"events: {events}")
    lines.append(f"commands: {info.commands}")
    lines.append("metadata:")
    for name, record in info.metadata.items():
        text = ", ".join(f"{k}={v}" for k, v in sorted(record.items()))
        lines.append(f"  {name}: {text if len(text) <= 160 else text[:157] + '...'}")
    if info.attachments:
        lines.append(
            "attachments: "
            + ", ".join(f"{name} ({size:,} bytes)" for name, size in info.attachments)
        )
    if info.config is not None:
        lines += setup_lines(info.config, info.run)
    lines += [f"problem: {problem}" for problem in info.problems]
    if all_events:
        lines.append(
            f"all events ({len(info.event_list)}):" if info.event_list else "all events: none"
        )
        lines += [f"  {event_line(e)}" for e in info.event_list]
    return lines


def setup_lines(config: TwinConfig, run: dict) -> list[str]:
    """What the run was: the robot, each scene object with its mass, size, start pose and colour,
    the pad's strength and limits, the cameras, the task and its parameters."""
    p, pad = config.profile, config.suction
    lines = [
        "setup:",
        f"  robot {p.name}: links {p.link1_m:g} + {p.link2_m:g} m, Z stroke {p.z_stroke_m:g} m, "
        f"joints {', '.join(p.joint_names)}" + (f" ({p.description})" if p.description else ""),
    ]
    for o in config.objects:
        x, y, z = o.pos_m
        lines.append(
            f"  object {o.name}: {o.mass_kg:g} kg, {' x '.join(f'{s:g}' for s in o.size_m)} m, at "
            f"({x:g}, {y:g}, {z:g}) m, yaw {math.degrees(o.yaw_rad):g} deg, "
            f"friction {o.friction:g}, colour rgba ({', '.join(f'{c:g}' for c in o.rgba)})"
        )
    strength = (
        "infinite strength"
        if pad.infinite_strength
        else f"breaks past pull {pad.max_pull_force_n:g} N, shear {pad.max_shear_force_n:g} N, "
        f"peel {pad.max_peel_torque_nm:g} N·m"
    )
    lines.append(
        f"  pad: {strength}; sensor {pad.sensor_range_m * 1000:g} mm long, "
        f"{pad.sensor_offset_m * 1000:g} mm below the pad root"
    )
    for c in config.cameras:
        lines.append(
            f"  camera {c.name}: {c.width_px}x{c.height_px} {c.format} at {c.rate_hz:g} Hz, "
            f"{c.fov_deg:g} deg field of view, mounted on the {c.mount}"
        )
    params = json.dumps(run.get("params", {}), sort_keys=True)
    lines.append(
        f"  task {run.get('task', '') or '(none)'} ({run.get('source', '?')}), parameters {params}"
    )
    return lines


def event_line(e: Event) -> str:
    """One event: time, step, kind, body, message and its data as JSON."""
    try:
        data = f" {json.dumps(e.data, sort_keys=True)}" if e.data else ""
    except RecursionError:  # as deep as the file's JSON parser allowed: printing it recurses again
        data = " (data nested too deeply to show)"
    return (
        f"t={e.t_ns * 1e-9:9.3f} s  step {e.step:>7}  {e.kind:<14} {e.body:<6} {e.message}{data}"
    ).rstrip()
