"""`twin recover`: rewrite the readable part of a recording cut short (crash, kill -9) as a complete file.

Reads up to the first damaged record, keeps only the frames all three block channels hold (a
chunk may end between them), drops commands and events after the last kept frame, and writes
everything else unchanged (but the finalization record of a file cut short: its run did not end
there), plus a `twin.recovered` metadata record.

A killed run leaves `NAME.mcap.partial` (recordings are renamed into place only when finalized):
`recover("NAME.mcap")` finds it when NAME.mcap does not exist, and then writes NAME.mcap.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from twin.errors import ConfigError, RecordingError
from twin.record.mcap import schemas as S
from twin.record.mcap.reader import Scan, block_steps, parse_command, parse_event, recording_from_scan, scan
from twin.record.metadata import parse_config
from twin.record.outputs import check_output, final_path, partial_path, publish

BLOCK_TOPICS = tuple(S.BLOCK_TOPICS.values())


@dataclass
class RecoverReport:
    source: str
    output: str
    asked: str  # the path the user named (source may be the .partial file found beside it)
    was_complete: bool
    problem: str
    messages_kept: int
    messages_dropped: int
    frames: int
    last_step: int
    duration_s: float

    def lines(self) -> list[str]:
        state = "was already complete" if self.was_complete else f"was cut short ({self.problem})"
        found = [] if self.asked == self.source else [
            (f"{self.asked} does not exist; using {self.source}, the unfinished file of a run that was killed "
             "(it is kept)")]
        return [
            *found,
            f"{self.source} {state}",
            (f"wrote {self.output}: {self.frames:,} frames, steps 0..{self.last_step}, {self.duration_s:.3f} s "
             f"simulated; {self.messages_kept:,} messages kept, {self.messages_dropped:,} dropped past the last "
             "whole frame"),
        ]


def _last_common_step(s: Scan, steps: dict[int, np.ndarray]) -> int:
    """The last step every block channel holds (blocks hold whole runs of frames)."""
    topics = s.by_topic()
    last = None
    for topic in BLOCK_TOPICS:
        ends = [int(steps[id(m)].max()) for m in topics.get(topic, []) if steps[id(m)].size]
        end = max(ends) if ends else -1
        last = end if last is None else min(last, end)
    return -1 if last is None else last


def _keep(s: Scan, message, steps: dict[int, np.ndarray], last_step: int, dt_ns: int) -> bool:
    topic = s.topic_of(message)
    if topic in BLOCK_TOPICS:
        block = steps[id(message)]
        return bool(block.size) and int(np.max(block)) <= last_step
    if topic == S.COMMANDS.topic:
        return parse_command(message.data, s.path).step <= last_step  # RecordingError if malformed
    if topic == S.EVENTS.topic:
        return parse_event(message.data, s.path).step <= last_step
    return message.log_time <= max(0, last_step) * dt_ns


def find_source(path: str | Path) -> Path:
    """The file to recover for `path`: itself, or, when it does not exist, the `.partial` file a
    killed run left beside it."""
    p = Path(path)
    partial = partial_path(p)
    return partial if not p.exists() and partial.is_file() else p


def default_output(source: Path) -> Path:
    """Where to write when no -o is given: the recording a `.partial` file was meant to become, if
    that does not exist (a killed run); never over an existing file."""
    target = final_path(source)
    if target is None or target.exists():
        why = f"{str(target)!r} exists" if target is not None else f"{str(source)!r} is no .partial file"
        raise ConfigError(f"name the restored file with -o FIXED.mcap ({why})")
    return target


def recover(source: str | Path, output: str | Path | None = None) -> RecoverReport:
    """Write the readable, consistent part of `source` (or the .partial file beside it, see
    find_source) to `output` (default: see default_output), a complete MCAP file put in place whole."""
    asked, source = str(source), find_source(source)
    if not source.exists() and not source.is_symlink():
        raise RecordingError(f"recording {asked!r} does not exist, nor does {str(partial_path(asked))!r}; "
                             "expected a recording or the .partial file a killed run left")
    output = default_output(source) if output is None else output
    out_path = check_output(output, ".mcap", inputs=[source], option="output")
    s = scan(source, strict=False)
    if S.META_CONFIG not in s.metadata:
        raise RecordingError(f"{str(source)!r} holds no readable twin configuration ({s.problem or 'not a twin file'});"
                             " nothing to recover")
    dt_ns = parse_config(s.metadata, repr(str(source))).dt_ns  # a damaged config is a RecordingError
    steps = {id(m): block_steps(m) for m in s.messages if s.topic_of(m) in BLOCK_TOPICS}  # decoded once
    last_step = _last_common_step(s, steps)
    kept = [m for m in s.messages if _keep(s, m, steps, last_step, dt_ns)]
    writing = out_path.with_name(out_path.name + ".recovering")  # not .partial: that may be the source
    try:
        try:
            with open(writing, "wb") as f:
                _write(f, s, kept, last_step)
            recording = recording_from_scan(scan(writing, strict=True))  # the result must load
            publish(writing, out_path)
        except OSError as err:
            raise RecordingError(f"cannot write {str(output)!r}: {err.strerror or err}") from err
    finally:
        writing.unlink(missing_ok=True)
    return RecoverReport(
        source=str(source), output=str(output), asked=asked, was_complete=s.complete, problem=s.problem,
        messages_kept=len(kept), messages_dropped=len(s.messages) - len(kept), frames=len(recording.frames),
        last_step=last_step, duration_s=max(0, last_step) * dt_ns * 1e-9,
    )


def _write(f, s: Scan, kept: list, last_step: int) -> None:
    writer = Writer(f, compression=CompressionType.ZSTD)
    writer.start(profile="", library=S.LIBRARY)
    schema_ids = {sid: writer.register_schema(x.name, x.encoding, x.data) for sid, x in sorted(s.schemas.items())}
    channel_ids = {
        cid: writer.register_channel(c.topic, c.message_encoding, schema_ids.get(c.schema_id, 0), dict(c.metadata))
        for cid, c in sorted(s.channels.items())
    }
    for name, record in s.metadata.items():  # a file cut short loses its finalization too: what followed the
        if name != S.META_RECOVERED and (s.complete or name != S.META_FINALIZED):  # kept frames is gone
            writer.add_metadata(name, record)
    writer.add_metadata(S.META_RECOVERED, {
        "source": Path(s.path).name, "problem": s.problem if not s.complete else "none (the source was complete)",
        "last_step": str(last_step), "source_bytes": str(s.size_bytes),
    })
    for a in s.attachments:
        writer.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
    for m in kept:
        writer.add_message(channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
    writer.finish()
