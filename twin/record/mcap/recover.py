"""`twin recover`: rewrite the readable part of a recording cut short (crash, kill -9) as a complete
file.

Reads up to the first damaged record, keeps only the frames all three block channels hold (a
chunk may end between them), drops commands and events after the last kept frame, and writes
everything else unchanged (but the finalization record of a file cut short: its run did not end
there), plus a `twin.recovered` metadata record.

Two passes over the source, neither keeping a message: the first finds the last whole frame (and
checks every command and event), the second writes what is kept as it reads it.

A killed run leaves `NAME.mcap.partial` (recordings are renamed into place only when finalized):
`recover("NAME.mcap")` finds it when NAME.mcap does not exist, and then writes NAME.mcap.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from twin.model.errors import ConfigError, RecordingError
from twin.record.mcap import schemas as S
from twin.record.mcap.metadata import parse_config
from twin.record.mcap.reader import (
    Message,
    Scan,
    block_steps,
    load,
    parse_command,
    parse_event,
    scan,
)
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
        found = (
            []
            if self.asked == self.source
            else [
                (
                    f"{self.asked} does not exist; using {self.source}, the unfinished "
                    f"file of a run that was killed "
                    "(it is kept)"
                )
            ]
        )
        return [
            *found,
            f"{self.source} {state}",
            (
                f"wrote {self.output}: {self.frames:,} frames, steps "
                f"0..{self.last_step}, {self.duration_s:.3f} s "
                f"simulated; {self.messages_kept:,} messages kept, "
                f"{self.messages_dropped:,} dropped past the last "
                "whole frame"
            ),
        ]


class _Ends:
    """The first pass: the last step each block channel reaches; every command and event parsed (a
    malformed one is a RecordingError: a recovered file must load)."""

    TOPICS = frozenset((*BLOCK_TOPICS, S.COMMANDS.topic, S.EVENTS.topic))

    def __init__(self) -> None:
        self.last = dict.fromkeys(BLOCK_TOPICS, -1)

    def take(self, s: Scan, topic: str, message: Message) -> None:
        if topic in self.last:
            block = block_steps(message)
            if block.size:
                self.last[topic] = max(self.last[topic], int(block.max()))
        elif topic == S.COMMANDS.topic:
            parse_command(message.data, s.path)
        else:
            parse_event(message.data, s.path)

    def last_common_step(self) -> int:
        """The last step every block channel holds (blocks hold whole runs of frames)."""
        return min(self.last.values())


class _Enough(Exception):
    """The second pass has written every message the first one read (a file still being written
    grows)."""


class _Copy:
    """The second pass: each message the first pass read is written at once if it is kept."""

    def __init__(
        self, writer: Writer, channel_ids: dict[int, int], read: int, last_step: int, dt_ns: int
    ) -> None:
        self.writer, self.channel_ids, self.left, self.last_step, self.dt_ns = (
            writer,
            channel_ids,
            read,
            last_step,
            dt_ns,
        )
        self.kept = 0

    def take(self, s: Scan, topic: str, m: Message) -> None:
        if self.left <= 0:
            raise _Enough
        self.left -= 1
        if _keep(s.path, topic, m, self.last_step, self.dt_ns):
            self.writer.add_message(
                self.channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence
            )
            self.kept += 1


def _keep(where: str, topic: str, message: Message, last_step: int, dt_ns: int) -> bool:
    if topic in BLOCK_TOPICS:
        block = block_steps(message)
        return bool(block.size) and int(np.max(block)) <= last_step
    if topic == S.COMMANDS.topic:
        return parse_command(message.data, where).step <= last_step  # RecordingError if malformed
    if topic == S.EVENTS.topic:
        return parse_event(message.data, where).step <= last_step
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
        why = (
            f"{str(target)!r} exists"
            if target is not None
            else f"{str(source)!r} is no .partial file"
        )
        raise ConfigError(f"name the restored file with -o FIXED.mcap ({why})")
    return target


def recover(
    source: str | Path, output: str | Path | None = None, *, force: bool = False
) -> RecoverReport:
    """Write the readable, consistent part of `source` (or the .partial file beside it, see
    find_source) to `output` (default: see default_output), a complete MCAP file put in place
    whole; an existing `output` is replaced only with force (else a ConfigError, before any
    work)."""
    asked, source = str(source), find_source(source)
    if not source.exists() and not source.is_symlink():
        raise RecordingError(
            f"recording {asked!r} does not exist, nor does {str(partial_path(asked))!r}; "
            "expected a recording or the .partial file a killed run left"
        )
    output = default_output(source) if output is None else output
    out_path = check_output(output, ".mcap", inputs=[source], option="output", force=force)
    ends = _Ends()
    s = scan(source, strict=False, topics=ends.TOPICS, consume=ends.take)
    if S.META_CONFIG not in s.metadata:
        raise RecordingError(
            f"{str(source)!r} holds no readable twin configuration "
            f"({s.problem or 'not a twin file'});"
            " nothing to recover"
        )
    # a damaged config is a RecordingError
    dt_ns = parse_config(s.metadata, repr(str(source))).dt_ns
    last_step = ends.last_common_step()
    # not .partial: that may be the source
    writing = out_path.with_name(out_path.name + ".recovering")
    try:
        try:
            with open(writing, "wb") as f:
                kept = _write(f, s, source, last_step, dt_ns)
            recording = load(writing)  # the result must load
            publish(writing, out_path)
        except OSError as err:
            raise RecordingError(f"cannot write {str(output)!r}: {err.strerror or err}") from err
    finally:
        writing.unlink(missing_ok=True)
    return RecoverReport(
        source=str(source),
        output=str(output),
        asked=asked,
        was_complete=s.complete,
        problem=s.problem,
        messages_kept=kept,
        messages_dropped=s.message_count - kept,
        frames=len(recording.frames),
        last_step=last_step,
        duration_s=max(0, last_step) * dt_ns * 1e-9,
    )


def _write(f, s: Scan, source: Path, last_step: int, dt_ns: int) -> int:
    """The recovered file: the first pass's schemas, channels, metadata (and the recovered marker)
    and attachments, then the kept messages of a second pass over the source. Returns how many were
    kept."""
    writer = Writer(f, compression=CompressionType.ZSTD)
    writer.start(profile="", library=S.LIBRARY)
    schema_ids = {
        sid: writer.register_schema(x.name, x.encoding, x.data)
        for sid, x in sorted(s.schemas.items())
    }
    channel_ids = {
        cid: writer.register_channel(
            c.topic, c.message_encoding, schema_ids.get(c.schema_id, 0), dict(c.metadata)
        )
        for cid, c in sorted(s.channels.items())
    }
    # a file cut short loses its finalization too: what followed the kept frames is gone
    for name, record in s.metadata.items():
        if name != S.META_RECOVERED and (s.complete or name != S.META_FINALIZED):
            writer.add_metadata(name, record)
    writer.add_metadata(
        S.META_RECOVERED,
        {
            "source": Path(s.path).name,
            "problem": s.problem if not s.complete else "none (the source was complete)",
            "last_step": str(last_step),
            "source_bytes": str(s.size_bytes),
        },
    )
    for a in s.attachments:
        writer.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
    copy = _Copy(writer, channel_ids, s.message_count, last_step, dt_ns)
    try:
        scan(source, strict=False, consume=copy.take)
    except _Enough:
        pass
    writer.finish()
    return copy.kept
