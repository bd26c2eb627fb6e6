"""A sweep's journal, `DIR/journal.jsonl`: one JSON line per finished scenario, appended and flushed
as each finishes, so a sweep killed in any way (kill -9, a power cut aside) loses only the
scenarios in flight. Its first line names the definition; `--resume` reads the rows back, checks
they belong to the same definition, and the sweep runs only the scenarios missing. results.parquet
and summary.json are made from the journal's rows.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from twin.model.errors import ConfigError
from twin.model.json_values import load_json_text
from twin.sweep.spec import SweepSpec

JOURNAL = "journal.jsonl"
FORMAT = 1


def identity(spec: SweepSpec) -> dict:
    """What makes two sweeps' scenarios the same: everything but the scenario count (scenario i's
    values depend only on the seed and i), with task and profile files by absolute path."""
    def where(name: str, suffix: str) -> str:
        return os.path.abspath(name) if name.endswith(suffix) and Path(name).is_file() else name

    return {"task": where(spec.task, ".py"), "robot": where(spec.robot, ".toml"), "seed": spec.seed,
            "vary": [list(v) for v in spec.vary], "params": spec.params, "rate_hz": spec.rate_hz,
            "timeout_s": spec.timeout_s}


def same_sweep(out_dir: str | os.PathLike, spec: SweepSpec) -> bool:
    """True if out_dir holds a journal whose first line names this sweep's definition."""
    try:
        with open(Path(out_dir) / JOURNAL, "rb") as f:
            first = f.readline(1 << 20)
        head = load_json_text(first, "journal")
    except (OSError, ConfigError):
        return False
    return (
        isinstance(head, dict)
        and head.get("twin_sweep_journal") == FORMAT
        and head.get("definition") == identity(spec)
    )


class Journal:
    """The journal of one sweep in out_dir. resume=False starts it afresh; resume=True keeps the
    rows of an earlier run of the same definition (`rows`; `done(i)` says whether scenario i has
    one)."""

    def __init__(self, out_dir: str | os.PathLike, spec: SweepSpec, *, resume: bool) -> None:
        self.path = Path(out_dir) / JOURNAL
        self.rows: list[dict] = []
        self._done = bytearray((spec.scenarios + 7) // 8)  # one bit per scenario: 1.25 MB at 10M
        head = {"twin_sweep_journal": FORMAT, "definition": identity(spec)}
        try:
            if resume and self.path.exists():
                end = self._read(spec, head["definition"])
                self._file = open(self.path, "r+b")  # noqa: SIM115 - open while the sweep runs
                self._file.truncate(end)  # a line cut short by a kill is dropped
                self._file.seek(end)
            else:
                self._file = open(self.path, "wb")  # noqa: SIM115
                self._write(head)
        except OSError as err:
            raise ConfigError(
                f"cannot write the sweep's journal {str(self.path)!r}: {err.strerror or err}"
            ) from err

    def _read(self, spec: SweepSpec, definition: dict) -> int:
        """Read the rows an earlier run wrote; the byte offset after the last whole line."""
        text = self.path.read_bytes()
        end = text.rfind(b"\n") + 1
        lines = text[:end].splitlines()
        try:
            head = load_json_text(lines[0], "journal") if lines else None
        except ConfigError:  # not JSON, or nested past what twin reads
            head = None
        if not isinstance(head, dict) or head.get("twin_sweep_journal") != FORMAT:
            raise ConfigError(
                f"--resume: {str(self.path)!r} is not a twin sweep journal; expected one that "
                "twin sweep wrote (or run without --resume to start afresh)"
            )
        if head.get("definition") != definition:
            raise ConfigError(
                f"--resume: {str(self.path)!r} holds a different sweep (task, robot, seed, vary, "
                "params, rate or timeout differ); expected the same definition, or no --resume"
            )
        for number, line in enumerate(lines[1:], start=2):
            try:
                row = load_json_text(line, "journal")
                i = row["scenario"]
            except (ConfigError, TypeError, KeyError):
                raise ConfigError(
                    f"--resume: {str(self.path)!r} line {number} is damaged; expected one "
                    "scenario's row per line"
                ) from None
            if isinstance(i, int) and 0 <= i < spec.scenarios and not self.done(i):
                self._done[i >> 3] |= 1 << (i & 7)
                self.rows.append(row)
        return end

    def done(self, scenario: int) -> bool:
        return bool(self._done[scenario >> 3] >> (scenario & 7) & 1)

    def add(self, row: dict) -> None:
        self._write(row)

    def _write(self, data: dict) -> None:
        try:
            self._file.write(json.dumps(data, separators=(",", ":")).encode() + b"\n")
            self._file.flush()  # in the kernel's hands: a killed process loses nothing written
        except OSError as err:
            raise ConfigError(
                f"cannot write the sweep's journal {str(self.path)!r}: {err.strerror or err}"
            ) from err

    def close(self) -> None:
        self._file.close()
