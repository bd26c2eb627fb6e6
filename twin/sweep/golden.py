"""Statistical goldens: a sweep definition `NAME.toml` with its expected summary `NAME.summary.json`
beside it. Checking re-runs the sweep and judges it by statistics, not bytes: the success rate
must lie in the golden's Wilson 95 % interval, and the placement-error percentiles (p50, p95, max)
within the definition's tolerances (`[tolerance]`, else spec.TOLERANCES).

A golden that also keeps its per-scenario results beside it (`NAME.results.parquet`: scenario,
the varied values, outcome, error, placement_error_mm; no wall-clock columns) is judged paired
instead (twin.sweep.paired): the new run's scenarios against the same scenarios of the golden,
by the definition's `[tolerance]` rule `paired` ("significant", the default, or "strict") and
`placement_shift_mm`. A golden without results checks by its summary, as before.

`update` rewrites the summary and the results when they changed at all (atomically: a temporary
file beside each, renamed into place). A golden's files are read only when regular files of at
most MAX_BYTES (the results: paired.MAX_RESULTS_BYTES), and its summary is validated before it
judges anything: a NaN or an infinite interval would otherwise pass every run."""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from twin.model.errors import ConfigError, OutputError, TwinError
from twin.model.golden_files import regular_text, summary_path
from twin.model.json_values import load_json_text
from twin.record.outputs import atomic_path, write_atomic
from twin.sweep import paired, power
from twin.sweep.results import summary, summary_text, table
from twin.sweep.runner import run_sweep
from twin.sweep.spec import SweepSpec, load_spec, prepare
from twin.sweep.worker import Job
from twin.verify.check import Outcome

PERCENTILES = (
    ("p50", "placement_p50_mm"),
    ("p95", "placement_p95_mm"),
    ("max", "placement_max_mm"),
)
# what makes a .toml a sweep definition (a robot profile has none)
MAX_BYTES = 4 * 2**20  # the largest definition or summary read: a golden is a few kB


def results_path(definition: str | os.PathLike) -> Path:
    path = Path(definition)
    return path.with_name(path.stem + ".results.parquet")


META_KEY = b"twin.sweep"  # the results' schema metadata: the seed and varied keys that made them


def golden_table(spec: SweepSpec, rows: list[dict]) -> pa.Table:
    """A golden's per-scenario results: scenario, the varied keys, outcome, error and
    placement_error_mm of each scenario (no seed column: it is in the metadata with the varied
    keys; no counts or times)."""
    full = table(spec, rows)
    keys = [k for k, _ in spec.vary]
    out = full.select(["scenario", *keys, "outcome", "error", "placement_error_mm"])
    return out.replace_schema_metadata({META_KEY: json.dumps(_meta(spec)).encode()})


def _meta(spec: SweepSpec) -> dict:
    return {"seed": spec.seed, "vary": [list(v) for v in spec.vary]}


def _read_results(path: Path) -> tuple[paired.Side, dict]:
    """A golden's results as a paired.Side, with the seed and varied keys that made them."""
    side = paired.read_side(path, path.name)
    try:
        raw = (pq.read_schema(path).metadata or {}).get(META_KEY)
        meta = json.loads(raw) if raw else None
    except (ValueError, OSError, pa.ArrowException):
        meta = None
    if not isinstance(meta, dict) or not isinstance(meta.get("seed"), int):
        raise ConfigError(
            f"sweep golden results {str(path)!r} lack their seed (schema metadata "
            f"{META_KEY.decode()!r}); expected a file `twin check --update` wrote"
        )
    return side, meta


def judge(golden: dict, new: dict, tolerances: dict[str, float]) -> list[str]:
    """What moved beyond its tolerance, one line each naming the statistic and by how much."""
    problems = []
    if new["scenarios"] != golden.get("scenarios"):
        problems.append(
            f"scenarios {new['scenarios']} differ from the golden's {golden.get('scenarios')}"
        )
    rate, g_rate = new["success_rate"], golden.get("success_rate", 0.0)
    lo, hi = golden.get("wilson95", [0.0, 1.0])
    if not lo <= rate <= hi:
        problems.append(
            f"success_rate {rate:.4f} is outside the golden's Wilson 95 % interval "
            f"[{lo:.4f}, {hi:.4f}] "
            f"(golden {g_rate:.4f}, moved {rate - g_rate:+.4f})"
        )
    g_pe, pe = golden.get("placement_error_mm", {}), new["placement_error_mm"]
    for stat, tol_name in PERCENTILES:
        before, now = g_pe.get(stat), pe[stat]
        if (before is None) != (now is None):
            problems.append(f"placement_error_mm.{stat} was {before} and is {now} now")
        elif before is not None and not abs(now - before) <= tolerances[tol_name]:
            # a NaN moved too
            problems.append(
                f"placement_error_mm.{stat} moved {now - before:+.3f} mm (golden {before:.3f}, now "
                f"{now:.3f}; tolerance {tolerances[tol_name]:g} mm)"
            )
    return problems


def check_sweep(
    definition: str, executor, *, update: bool = False, keep: str | None = None,
    html: bool = False,
) -> Outcome:
    """Re-run one sweep golden on executor and judge it; an Outcome as verify.check gives for a
    recording. Paired when the golden keeps its results, else by its summary. keep (DIR/NAME): a
    golden that differs leaves its report and the new run's summary (and results) there. html: a
    paired golden that differs carries its section of the HTML report (flips, interval, map)."""
    t0 = time.perf_counter()
    expected_path, scenarios_path = summary_path(definition), results_path(definition)
    try:
        spec = load_spec(definition)
        prepare(spec)
        golden = _read(expected_path) if expected_path.exists() else None
        if golden is None and not update:
            raise ConfigError(
                f"sweep golden {definition!r} has no {expected_path.name} beside it; "
                f"`twin check --update {definition}` writes it"
            )
        reference = _read_results(scenarios_path) if scenarios_path.exists() else None
        done = run_sweep(Job(spec, None, "none"), range(spec.scenarios), executor)
        if done.stopped_by is not None:
            raise done.stopped_by
        new = summary(spec, done.rows)
        new_table = golden_table(spec, done.rows)
        notes = []  # said after the verdict, failing nothing: what a paired verdict detects
        if reference is not None:
            problems, report, within, notes = _judge_paired(definition, spec, reference, new_table)
            report += "\n" + _report(golden, new)
        elif golden is not None:
            problems, report = judge(golden, new, spec.tolerances()), _report(golden, new)
            within = "" if new == golden else "within tolerance: " + _moves(golden, new)
            notes = [f"judged by its summary only (no {scenarios_path.name})"]
        else:
            problems, report, within = ["no golden summary yet"], _report(golden, new), ""
        seconds = time.perf_counter() - t0
        wrote = _update(
            spec=spec,
            golden=golden,
            new=new,
            reference=reference,
            new_table=new_table,
            definition=definition,
        ) if update else []
        if wrote:
            was = "; ".join(problems) or "within tolerance"
            status, line = "updated", f"rewrote {', '.join(wrote)}; was: {was}"
        elif not problems:
            status, line = "match", "; ".join([within or "matches", *notes])
        else:
            status, line = "differ", "; ".join(problems + notes)
        outcome = Outcome(
            path=definition,
            status=status,
            exit_code=1 if status == "differ" else 0,
            summary=line,
            report=report,
            frames=spec.scenarios,
            seconds=seconds,
        )
        if status == "differ" and keep is not None:
            outcome.kept = _keep(keep, outcome, new, new_table if reference is not None else None)
        if status == "differ" and html and reference is not None:
            outcome.section = _section(definition, outcome, reference, new_table)
        return outcome
    except TwinError as err:
        return Outcome.of_error(definition, err, time.perf_counter() - t0)


def _section(definition: str, outcome: Outcome, reference, new_table) -> str:
    """A paired golden that differs, as its section of the HTML report (flips, interval, map)."""
    from twin.sweep.html import golden_section

    now = paired.side_from_table(new_table, "now")
    return golden_section(
        definition=definition,
        summary=outcome.summary,
        p=paired.pair(reference[0], now),
        new=now,
        reference=reference[0],
        report=outcome.report,
    )


def _update(spec, golden, new, reference, new_table, definition) -> list[str]:
    """--update: the names of the golden's files rewritten, the summary and the results, each when
    it changed at all."""
    expected_path, scenarios_path = summary_path(definition), results_path(definition)
    wrote = []
    if new != golden:
        _write_atomically(expected_path, new)
        wrote.append(expected_path.name)
    if (
        reference is None
        or reference[1] != _meta(spec)
        or not reference[0].table.equals(paired.side_from_table(new_table, "now").table)
    ):
        with atomic_path(scenarios_path) as tmp:
            pq.write_table(new_table, tmp)
        wrote.append(scenarios_path.name)
    return wrote


def _keep(base: str, outcome: Outcome, new: dict, new_table: pa.Table | None) -> list[str]:
    """--keep for a sweep golden that differs: DIR/NAME.md (the report), the new run's
    DIR/NAME.summary.json and, for a paired golden, DIR/NAME.results.parquet."""
    from twin.verify.keep import outcome_markdown, staging

    with staging(base) as staged:
        staged.write_text(".md", outcome_markdown(outcome, f"sweep golden {Path(base).name}"))
        staged.write_text(".summary.json", _summary_text(Path(base).name + ".summary.json", new))
        if new_table is not None:
            try:
                pq.write_table(new_table, staged.temp(".results.parquet"))
            except (OSError, pa.ArrowException) as err:
                why = getattr(err, "strerror", None) or err
                where = base + ".results.parquet"
                raise OutputError(f"cannot write {where!r}: {why}") from err
        return staged.publish()


def _judge_paired(
    definition: str, spec: SweepSpec, reference: tuple[paired.Side, dict], new_table: pa.Table
) -> tuple[list[str], str, str, list[str]]:
    """Problems, the report, a within-tolerance note ("" when nothing moved) and the notes that
    fail nothing (the drop the verdict detects, warnings) of the new run paired with the golden's
    results. Another seed or set of scenarios is a problem of its own: those scenarios are not the
    same ones."""
    side, meta = reference
    problems = []
    if meta["seed"] != spec.seed:
        problems.append(
            f"the definition's seed {spec.seed} is not the one of {side.label} "
            f"({meta['seed']}): its scenarios are others; `twin check --update "
            f"{definition}` after an intended change"
        )
    p = paired.pair(side, paired.side_from_table(new_table, "now"))
    if p.only_reference or p.only_new:
        problems.append(
            f"the golden's results hold {side.n} scenarios and the run "
            f"{spec.scenarios} ({p.n} in both)"
        )
    if p.values_moved:
        problems.append(
            "varied values differ from the golden's: "
            + ", ".join(f"{k} in {c} scenarios" for k, c in p.values_moved.items())
        )
    rule = spec.tolerance.get("paired", "significant")
    problems += paired.problems(p, rule, spec.tolerances()["placement_shift_mm"])
    if problems and (p.worse or p.better):
        problems.append(f"re-run: {paired.rerun_hint(p, definition)}")
    within = ""
    if p.worse or p.better or p.placed_changed or (p.largest_move and p.largest_move[1] != 0):
        within = f"within tolerance ({rule}): {paired.flip_text(p)}; {paired.rate_text(p)}"
        if p.shift is not None:
            within += f"; paired placement shift median {p.shift[0]:+.3f} mm"
    notes = [power.detectable_text(p.n, p.detectable_drop_pct, rule)]
    notes += [
        f"warning: {w}" for w in paired.warnings(p, rule, spec.tolerance.get("success_drop_pct"))
    ]
    report = paired.report_text(p, definition, rule)
    report += "".join(f"  {note}\n" for note in notes[1:])
    return problems, report, within, notes


def _read(path: Path) -> dict:
    """A golden summary, validated (check_summary)."""
    try:
        text = regular_text(path, MAX_BYTES)
    except ValueError as err:
        raise ConfigError(f"sweep golden summary {str(path)!r} {err}") from err
    # also too deep: one line
    data = load_json_text(text, f"sweep golden summary {str(path)!r} is not valid JSON")
    return check_summary(data, str(path))


def check_summary(data: object, where: str) -> dict:
    """data when it is a sweep summary that can judge a run: whole counts that add up, a finite
    success_rate in [0, 1] inside its finite wilson95 interval, finite ordered placement-error
    percentiles (all null when count is 0) and failures_by_reason counting the failures. Else a
    one-line ConfigError naming where, the field, its value and what was expected."""

    def bad(name: str, value: object, expected: str) -> ConfigError:
        shown = json.dumps(value) if not isinstance(value, str) else repr(value)
        return ConfigError(
            f"sweep golden summary {where!r}: {name} {shown[:80]} is invalid; expected {expected}"
        )

    if not isinstance(data, dict):
        raise bad("the summary", type(data).__name__, "a JSON object (a sweep's summary.json)")
    for name in ("scenarios", "ok", "failed"):
        if not _whole(data.get(name)):
            raise bad(name, data.get(name), "a whole number >= 0")
    n, ok, failed = data["scenarios"], data["ok"], data["failed"]
    if ok + failed != n:
        raise bad("ok + failed", ok + failed, f"scenarios ({n})")
    rate = data.get("success_rate")
    if not _finite(rate) or not 0 <= rate <= 1:
        raise bad("success_rate", rate, "a finite number 0..1")
    if n and abs(rate - ok / n) > 1e-9:
        raise bad("success_rate", rate, f"ok / scenarios = {ok}/{n}")
    lo_hi = data.get("wilson95")
    if not (isinstance(lo_hi, list) and len(lo_hi) == 2 and all(_finite(v) for v in lo_hi)):
        raise bad("wilson95", lo_hi, "[lo, hi], two finite numbers")
    if not 0 <= lo_hi[0] <= rate <= lo_hi[1] <= 1:
        raise bad("wilson95", lo_hi, f"0 <= lo <= success_rate ({rate}) <= hi <= 1")
    pe = data.get("placement_error_mm")
    if not isinstance(pe, dict):
        raise bad("placement_error_mm", pe, "an object with count, p50, p95 and max")
    count = pe.get("count")
    if not _whole(count) or count > n:
        raise bad("placement_error_mm.count", count, f"a whole number 0..scenarios ({n})")
    for stat_name, _ in PERCENTILES:
        value = pe.get(stat_name)
        if count == 0 and value is not None:
            raise bad(f"placement_error_mm.{stat_name}", value, "null (count is 0)")
        if count > 0 and not _finite(value):
            raise bad(
                f"placement_error_mm.{stat_name}",
                value,
                f"a finite number of mm (count is {count})",
            )
    if count > 0 and not pe["p50"] <= pe["p95"] <= pe["max"]:
        raise bad("placement_error_mm", {s: pe[s] for s, _ in PERCENTILES}, "p50 <= p95 <= max")
    reasons = data.get("failures_by_reason")
    if not (isinstance(reasons, dict) and all(_whole(v) for v in reasons.values())):
        raise bad("failures_by_reason", reasons, "an object of reason -> whole number")
    if sum(reasons.values()) != failed:
        raise bad("failures_by_reason", reasons, f"counts adding up to failed ({failed})")
    return data


def _whole(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _finite(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _write_atomically(path: Path, data: dict) -> None:
    """Write the summary to a temporary file beside path and rename it into place: an interrupted
    --update leaves the old golden or the new one, never half of one."""
    text = _summary_text(path.name, data)
    write_atomic(path, text)


def _summary_text(name: str, data: dict) -> str:
    """A new summary's text, refused (ConfigError) with a non-finite number or over MAX_BYTES."""
    try:
        text = summary_text(data)
    except ValueError as err:  # a NaN or infinity from the task's placements
        raise ConfigError(
            f"the new summary of {name} holds a non-finite number ({err}); not written"
        ) from err
    if len(text.encode()) > MAX_BYTES:
        raise ConfigError(
            f"the new summary of {name} would hold {len(text.encode())} bytes; "
            f"expected at most "
            f"{MAX_BYTES}; not written"
        )
    return text


def _moves(golden: dict, new: dict) -> str:
    pe, g_pe = new["placement_error_mm"], golden["placement_error_mm"]
    parts = [f"success_rate {new['success_rate'] - golden['success_rate']:+.4f}"]
    parts += [
        f"{stat} {pe[stat] - g_pe[stat]:+.3f} mm"
        for stat, _ in PERCENTILES
        if pe[stat] is not None and g_pe.get(stat) is not None
    ]
    return ", ".join(parts)


def _report(golden: dict | None, new: dict) -> str:
    """Golden and new statistics side by side (`twin check -v`)."""

    def row(name: str, g: object, n: object) -> str:
        return f"  {name:<26} {g!s:>22} {n!s:>22}"

    g = golden or {}
    g_pe, pe = g.get("placement_error_mm", {}), new["placement_error_mm"]
    lines = [
        row("statistic", "golden", "now"),
        row("scenarios", g.get("scenarios"), new["scenarios"]),
        row("success_rate", g.get("success_rate"), new["success_rate"]),
        row("wilson95", g.get("wilson95"), [round(v, 4) for v in new["wilson95"]]),
    ]
    lines += [row(f"placement_error_mm.{s}", g_pe.get(s), pe[s]) for s, _ in PERCENTILES]
    lines.append(
        row(
            "failures_by_reason",
            json.dumps(g.get("failures_by_reason")),
            json.dumps(new["failures_by_reason"]),
        )
    )
    return "\n".join(lines) + "\n"
