"""The recordings an export reads: loaded, hashed, and with --verify replayed first.

A recording is verified when `twin replay` would call it an exact match: its commands, fed to a
twin rebuilt from its configuration, give its frames and events bit for bit (tolerance `exact`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from twin.model.errors import RecordingError, TwinError
from twin.model.recording import Recording
from twin.model.types import COMMAND_ARGS
from twin.pictures import check_track


@dataclass
class Source:
    """One input recording and what is known of it: `replay` is "exact", "within numerical noise
    (...)", "differs: ...", or "not checked" (no --verify); `verified` True, False or None (not
    checked)."""

    path: str
    rec: Recording
    sha256: str
    replay: str = "not checked"
    verified: bool | None = None

    def provenance(self) -> dict:
        """The sidecar's entry: the file by name (no absolute path), its hash, what replay said."""
        return {
            "file": Path(self.path).name,
            "sha256": self.sha256,
            "robot": self.rec.config.profile.name,
            "task": str(self.rec.run.get("task", "")),
            "source": str(self.rec.run.get("source", "")),
            "frames": len(self.rec.frames),
            "rate_steps": self.rec.rate_steps,
            "outcome": self.rec.outcome,
            "verified": self.verified,
            "replay": self.replay,
        }


def load_source(path: str) -> Source:
    """Load and hash one recording (RecordingError, exit 2, for a missing or damaged file)."""
    from twin.record.mcap.reader import load

    rec = load(path)
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return Source(path, rec, digest.hexdigest())


def check_commands(rec: Recording) -> None:
    """RecordingError (exit 2) for a command `twin replay` refuses (Twin.apply): an unknown kind,
    other arguments than the kind's (model.types.COMMAND_ARGS), or, for what an export reads of them
    (the suction.command column), a signal name or key that is no dictionary key or a value int()
    refuses."""
    for c in rec.commands:
        expected = COMMAND_ARGS.get(c.kind)
        if expected is None:
            raise RecordingError(
                f"recording {rec.path!r}: unknown command kind {c.kind!r:.40} at step {c.step}; "
                f"expected one of {sorted(COMMAND_ARGS)}"
            )
        if not isinstance(c.args, dict) or sorted(c.args) != sorted(expected):
            raise RecordingError(
                f"recording {rec.path!r}: {c.kind} command at step {c.step} has arguments "
                f"{c.args!r:.80}; expected {', '.join(expected)}"
            )
        try:
            if c.kind == "signal":
                hash(c.args["name"])
                if c.args["value"] is not None:
                    int(c.args["value"])
            elif c.kind == "key":
                hash(c.args["key"])
        except (TypeError, ValueError, OverflowError) as err:
            raise RecordingError(
                f"recording {rec.path!r}: {c.kind} command at step {c.step} is malformed: "
                f"{str(err)[:80]}"
            ) from None


def check_pictures(rec: Recording) -> None:
    """RecordingError (exit 2) unless every camera picture's header declares the camera's format and
    configured size (headers only: nothing is decoded); the tracks name rec's file from now on."""
    for track in rec.cameras.values():
        track.source = track.source or rec.path
        check_track(track)


def check_recording(rec: Recording, fps: int | None = None) -> None:
    """What an export refuses in a recording before any work: malformed commands, bad pictures,
    frame times that are not their steps', and (for a dataset at fps) fps above its physics rate."""
    from twin.export.episodes import check_fps, check_times

    check_commands(rec)
    check_pictures(rec)
    check_times(rec)
    if fps is not None:
        check_fps(rec, fps)


def verify(source: Source) -> Source:
    """Replay the recording and compare it as `twin replay` does (the default `noise` verdict: bits,
    or within the replay's measured noise floor on another machine); sets replay and verified."""
    from twin.compare.report import first_line, noise_summary
    from twin.compare.tolerances import DEFAULT, Tolerances
    from twin.verify.noise import judge
    from twin.verify.replay import replay, replayed_event_kinds

    try:
        again = replay(source.rec)
        result = judge(
            source.rec,
            again,
            Tolerances.from_preset(DEFAULT),
            replay,
            source=source.rec,
            event_kinds=replayed_event_kinds(source.rec),
        )
    except TwinError as err:  # not replayable (no step 0, a malformed command, not comparable)
        source.replay, source.verified = f"not replayable: {err}", False
        return source
    if result.match:
        summary = noise_summary(result)
        source.replay, source.verified = "exact" if summary == "bit-identical" else summary, True
    else:
        source.replay, source.verified = f"differs: {first_line(result.first)}", False
    return source
