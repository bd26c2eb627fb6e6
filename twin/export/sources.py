"""The recordings an export reads: loaded, hashed, and with --verify replayed first.

A recording is verified when `twin replay` would call it an exact match: its commands, fed to a
twin rebuilt from its configuration, give its frames and events bit for bit (tolerance `exact`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from twin.errors import TwinError
from twin.model.recording import Recording


@dataclass
class Source:
    """One input recording and what is known of it: `replay` is "exact", "within numerical noise (...)", "differs: ...", or
    "not checked" (no --verify); `verified` True, False or None (not checked)."""

    path: str
    rec: Recording
    sha256: str
    replay: str = "not checked"
    verified: bool | None = None

    def provenance(self) -> dict:
        """The sidecar's entry: the file by name (no absolute path), its hash, what replay said."""
        return {"file": Path(self.path).name, "sha256": self.sha256, "robot": self.rec.config.profile.name,
                "task": str(self.rec.run.get("task", "")), "source": str(self.rec.run.get("source", "")),
                "frames": len(self.rec.frames), "rate_steps": self.rec.rate_steps, "outcome": self.rec.outcome,
                "verified": self.verified, "replay": self.replay}


def load_source(path: str) -> Source:
    """Load and hash one recording (RecordingError, exit 2, for a missing or damaged file)."""
    from twin.record.mcap.reader import load

    rec = load(path)
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return Source(path, rec, digest.hexdigest())


def verify(source: Source) -> Source:
    """Replay the recording and compare it as `twin replay` does (the default `noise` verdict: bits, or
    within the replay's measured noise floor on another machine); sets replay and verified."""
    from twin.compare.report import first_line, noise_summary
    from twin.compare.tolerances import DEFAULT, Tolerances
    from twin.verify.noise import judge
    from twin.verify.replay import replay, replayed_event_kinds

    try:
        again = replay(source.rec)
        result = judge(source.rec, again, Tolerances.from_preset(DEFAULT), replay, source=source.rec,
                       event_kinds=replayed_event_kinds(source.rec))
    except TwinError as err:  # not replayable (no step 0, a malformed command, not comparable)
        source.replay, source.verified = f"not replayable: {err}", False
        return source
    if result.match:
        summary = noise_summary(result)
        source.replay, source.verified = "exact" if summary == "bit-identical" else summary, True
    else:
        source.replay, source.verified = f"differs: {first_line(result.first)}", False
    return source
