"""`twin info`: what a recording holds and whether it was finalized, also for a file cut short."""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twin.record.mcap import schemas as S
from twin.record.mcap import strict_json
from twin.record.mcap.reader import block_steps, scan
from twin.record.metadata import parse_config, parse_run


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
    events: dict[str, int]
    commands: int
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[tuple[str, int]] = field(default_factory=list)


def _steps(messages: list) -> np.ndarray:
    parts = [block_steps(m) for m in messages]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def _kind(data: bytes) -> str:
    try:
        value = strict_json.loads(data)
    except ValueError:
        return "(unreadable)"
    return str(value.get("kind", "?"))[:60] if isinstance(value, dict) else "(unreadable)"


def describe(path: str | Path) -> Info:
    """Read as much of the file as is readable and summarize it (RecordingError if nothing is, or if
    its configuration or run description is malformed)."""
    s = scan(path, strict=False)
    topics = s.by_topic()
    steps = _steps(topics.get(S.JOINTS.topic, []))
    kinds = Counter(_kind(m.data) for m in topics.get(S.EVENTS.topic, []))
    counts = Counter(m.channel_id for m in s.messages)
    channels = []
    for cid, channel in sorted(s.channels.items()):
        schema = s.schemas.get(channel.schema_id)
        channels.append((channel.topic, schema.name if schema else "", channel.message_encoding, counts[cid]))
    config = parse_config(s.metadata, repr(s.path)) if S.META_CONFIG in s.metadata else None
    return Info(
        path=s.path, size_bytes=s.size_bytes, intact=s.complete, problem=s.problem,
        finalized=s.complete and S.META_FINALIZED in s.metadata, finished=s.metadata.get(S.META_FINALIZED, {}),
        recovered=s.metadata.get(S.META_RECOVERED, {}), run=parse_run(s.metadata, repr(s.path)),
        robot=config.profile.name if config else "", objects=[o.name for o in config.objects] if config else [],
        dt_ns=config.dt_ns if config else 0, frames=int(steps.size),
        first_step=int(steps[0]) if steps.size else -1, last_step=int(steps[-1]) if steps.size else -1,
        channels=channels, events=dict(sorted(kinds.items())), commands=len(topics.get(S.COMMANDS.topic, [])),
        metadata={k: v for k, v in sorted(s.metadata.items()) if k != S.META_CONFIG},
        attachments=[(a.name, len(a.data)) for a in s.attachments],
    )


def format_info(info: Info) -> list[str]:
    """The human-readable report `twin info` prints."""
    if info.finalized:
        outcome = info.finished.get("outcome", "?")
        state = f"yes (run outcome {outcome}" + (f": {info.finished['error']})" if info.finished.get("error") else ")")
    elif info.recovered:
        state = (f"no - recovered from {info.recovered.get('source', '?')} "
                 f"({info.recovered.get('problem', 'cut short')}); the run's end is missing")
    elif info.intact:
        state = "no - the file is complete but has no finalized marker"
    else:
        state = f"no - {info.problem} (killed or still being written)"
    lines = [f"file: {info.path} ({info.size_bytes:,} bytes)", f"finalized: {state}"]
    params = json.dumps(info.run.get("params", {}), sort_keys=True)
    lines.append(f"run: {info.run.get('source', '')} {info.run.get('task', '')} params {params}")
    replay_of = info.run.get("replay_of")
    if isinstance(replay_of, dict):
        lines.append(f"a replay of {replay_of.get('file', '?')} (sha256 {str(replay_of.get('sha256', '?'))[:12]}...)")
    lines.append(f"robot: {info.robot or '?'}; objects: {', '.join(info.objects) or 'none'}; "
                 f"time step {info.dt_ns:,} ns")
    if info.frames:
        duration_s = info.last_step * info.dt_ns * 1e-9
        lines.append(f"duration: {duration_s:.3f} s simulated; steps {info.first_step}..{info.last_step}, "
                     f"{info.frames:,} frames recorded")
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
        lines.append("attachments: " + ", ".join(f"{name} ({size:,} bytes)" for name, size in info.attachments))
    return lines
