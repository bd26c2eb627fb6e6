"""A sweep's files: `results.parquet` (one row per scenario, pyarrow), `summary.json` and the
definition `sweep.toml`, each written to NAME.partial and renamed into place."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from twin.record.outputs import atomic_path, write_atomic
from twin.sweep.spec import SweepSpec, dump_spec
from twin.sweep.stats import summarize
from twin.sweep.worker import COUNTED

RESULTS, SUMMARY, DEFINITION = "results.parquet", "summary.json", "sweep.toml"
LEADING = ("scenario", "seed")
TRAILING = ("outcome", "error", "placement_error_mm", *COUNTED, "sim_s", "wall_s")
_TYPES = {
    "scenario": pa.int64(),
    "seed": pa.int64(),
    "outcome": pa.string(),
    "error": pa.string(),
    "placement_error_mm": pa.float64(),
    **dict.fromkeys(COUNTED, pa.int64()),
    "sim_s": pa.float64(),
    "wall_s": pa.float64(),
}


def table(spec: SweepSpec, rows: list[dict]) -> pa.Table:
    """The rows (sorted by scenario) as a table: scenario, seed, one column per varied key named as
    the key, outcome, error, placement_error_mm, the event counts, sim_s, wall_s."""
    rows = sorted(rows, key=lambda r: r["scenario"])
    columns = {}
    for name in (*LEADING, *(k for k, _ in spec.vary), *TRAILING):
        values = [r.get(name) for r in rows]
        columns[name] = (
            pa.array(values, type=_TYPES.get(name)) if name in _TYPES else _varied(values)
        )
    return pa.table(columns)


def _varied(values: list) -> pa.Array:
    """A varied key's column: numbers, booleans or text as they come; mixed kinds as their JSON
    text."""
    try:
        return pa.array(values)
    except (pa.ArrowInvalid, pa.ArrowTypeError):
        return pa.array([json.dumps(v) for v in values], type=pa.string())


def summary(spec: SweepSpec, rows: list[dict], *, planned: int | None = None) -> dict:
    """summary.json's content: the definition's task, robot and seed, then the statistics; planned
    (when the sweep was stopped part-way) is the number of scenarios asked for."""
    names = {
        k: Path(v).name if v.endswith((".py", ".toml")) else v
        for k, v in (("task", spec.task), ("robot", spec.robot))
    }
    # a file by its name: no folder, no absolute path
    out = {**names, "seed": spec.seed, **summarize(rows)}
    if planned is not None and planned != len(rows):
        out["interrupted"] = True
        out["planned"] = planned
    return out


def summary_text(data: dict) -> str:
    """summary.json as written: in the order above, indented, finite numbers only."""
    return json.dumps(data, indent=2, allow_nan=False) + "\n"


def write_results(
    out_dir: str | os.PathLike, spec: SweepSpec, rows: list[dict], *, planned: int | None = None
) -> dict:
    """Write results.parquet and summary.json into out_dir; returns the summary."""
    out = Path(out_dir)
    data = summary(spec, rows, planned=planned)
    with atomic_path(out / RESULTS) as tmp:
        pq.write_table(table(spec, rows), tmp)
    write_atomic(out / SUMMARY, summary_text(data))
    return data


def write_definition(out_dir: str | os.PathLike, spec: SweepSpec) -> None:
    """DIR/sweep.toml: the definition that made the results (copy it to recordings/sweeps/ as a
    golden). A task or profile file is named relative to DIR, as load_spec finds it."""
    for name in ("task", "robot"):
        path = getattr(spec, name)
        if path.endswith((".py", ".toml")) and Path(path).is_file():
            spec = dataclasses.replace(
                spec, **{name: os.path.relpath(os.path.abspath(path), os.path.abspath(out_dir))}
            )
    text = dump_spec(spec)
    write_atomic(Path(out_dir) / DEFINITION, text)
