"""Two runs of the same scenarios compared scenario by scenario: a paired experiment. Scenario
i's values depend only on (seed, i), and each run is deterministic, so a reference and a new run
of one definition (or of two robots, codes or pad settings over the same seed and keys) differ
only by what changed. The sides are read as columns (pyarrow, numpy), never as Python rows; only
the flips are turned into rows, to be named.

What is reported (new minus reference throughout):
- the flips, ok->failed ("worse") and failed->ok ("better"), each with its scenario, values and
  reason;
- the paired difference in success rate with Newcombe's paired 95 % interval (stats.py);
- McNemar's exact test on the flips;
- the paired shift of the placement error: the median of the per-scenario differences with its
  sign-test (order-statistic) 95 % interval, over the scenarios that placed in both runs;
- the smallest drop in success rate the verdict detects at this size (twin.sweep.power): at 80 %
  power under "significant", one flip under "strict".

`problems` turns a comparison into a verdict by a rule: "significant" (fail on a significant drop
in success rate, McNemar p < ALPHA with more ok->failed, or a significant increase of the placement
error larger than the shift tolerance) or "strict" (fail on any flip, or any scenario whose
placement error moved by more than the shift tolerance).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from stat import S_ISREG

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from twin.model.errors import ConfigError
from twin.sweep import power
from twin.sweep.stats import mcnemar_exact, median_ci, newcombe_paired

RESULT_COLUMNS = ("scenario", "outcome", "error", "placement_error_mm")
NOT_VARIED = frozenset((*RESULT_COLUMNS, "seed", "attach", "release", "break", "suction_empty",
                        "sim_s", "wall_s"))
ALPHA = power.ALPHA  # the significance level of the "significant" rule (intervals are 95 %)
RULES = ("significant", "strict")
LISTED = 20  # flips named one by one in a report; the rest are counted
MAX_RESULTS_BYTES = 2**30  # a results file read for pairing: 10M scenarios fit


@dataclass
class Side:
    """One run's columns: scenario numbers (sorted), ok flags, placement errors (NaN: nothing
    placed), and the table they came from (its varied-key columns and error lines)."""

    label: str
    scenario: np.ndarray
    ok: np.ndarray
    placement_mm: np.ndarray
    table: pa.Table
    keys: list[str]

    @property
    def n(self) -> int:
        return len(self.scenario)


def side_from_table(table: pa.Table, label: str) -> Side:
    """A Side from a results table (a sweep's results.parquet, a golden's
    NAME.results.parquet)."""
    missing = [c for c in RESULT_COLUMNS if c not in table.column_names]
    if missing:
        raise ConfigError(f"results {label!r} lack column {missing[0]!r}; expected a sweep's "
                          "results.parquet")
    keys = [c for c in table.column_names if c not in NOT_VARIED]
    table = table.select([*RESULT_COLUMNS, *keys])
    check_columns(table, label)
    table = table.take(pc.sort_indices(table, [("scenario", "ascending")]))
    scenario = table.column("scenario").to_numpy()
    if len(scenario) > 1 and not (np.diff(scenario) > 0).all():
        i = int(np.flatnonzero(np.diff(scenario) == 0)[0])
        raise ConfigError(f"results {label!r} column 'scenario': scenario {scenario[i]} is in two "
                          "rows; expected one row per scenario")
    ok = pc.equal(table.column("outcome"), "ok").fill_null(False).to_numpy(zero_copy_only=False)
    placement = table.column("placement_error_mm").cast(pa.float64())
    placement_mm = placement.to_numpy(zero_copy_only=False).astype(float)  # null -> NaN
    return Side(
        label=label, scenario=scenario, ok=ok, placement_mm=placement_mm, table=table, keys=keys
    )


OUTCOMES = ("ok", "error")  # what a sweep's worker writes


def check_columns(table: pa.Table, label: str) -> None:
    """The result columns hold what a sweep writes, checked as columns (10M rows stay fast):
    scenario whole numbers >= 0, outcome one of OUTCOMES, error text or null, placement_error_mm a
    finite number >= 0 or null. ConfigError naming the file, the column and the first bad row
    (row 1 is the file's first)."""

    def bad(column: str, mask, expected: str) -> ConfigError:
        row = int(np.flatnonzero(np.asarray(mask))[0]) if mask is not None else 0
        value = table.column(column)[row].as_py()
        shown = repr(value) if not isinstance(value, str) else repr(value[:40])
        return ConfigError(
            f"results {label!r} column {column!r} row {row + 1} holds {shown}; expected {expected}"
        )

    def nulls(column: str):
        return pc.is_null(table.column(column)).to_numpy(zero_copy_only=False)

    if table.num_rows == 0:
        return
    kinds = {c: table.schema.field(c).type for c in RESULT_COLUMNS}
    if not pa.types.is_integer(kinds["scenario"]):
        raise bad("scenario", None, "whole numbers (an integer column)")
    scenario = table.column("scenario")
    wrong = nulls("scenario") | pc.fill_null(pc.less(scenario, 0), False).to_numpy(
        zero_copy_only=False
    )
    if wrong.any():
        raise bad("scenario", wrong, "a whole number >= 0")
    if not (pa.types.is_string(kinds["outcome"]) or pa.types.is_large_string(kinds["outcome"])):
        raise bad("outcome", None, f"text: {' or '.join(OUTCOMES)}")
    known = pc.is_in(table.column("outcome"), value_set=pa.array(OUTCOMES))
    wrong = ~pc.fill_null(known, False).to_numpy(zero_copy_only=False)
    if wrong.any():
        raise bad("outcome", wrong, f"one of {', '.join(OUTCOMES)}")
    if not (
        pa.types.is_string(kinds["error"])
        or pa.types.is_large_string(kinds["error"])
        or pa.types.is_null(kinds["error"])
    ):
        raise bad("error", None, "text or null")
    kind = kinds["placement_error_mm"]
    if not (pa.types.is_floating(kind) or pa.types.is_integer(kind) or pa.types.is_null(kind)):
        raise bad("placement_error_mm", None, "millimetres (a number column)")
    mm = table.column("placement_error_mm").cast(pa.float64()).to_numpy(zero_copy_only=False)
    with np.errstate(invalid="ignore"):
        wrong = ~nulls("placement_error_mm") & ~(np.isfinite(mm) & (mm >= 0))
    if wrong.any():
        raise bad("placement_error_mm", wrong, "a finite number of millimetres >= 0, or null")


def read_side(path: str | os.PathLike, label: str | None = None) -> Side:
    """The result columns of a results file (only those: a large sweep's other columns stay on
    disk). ConfigError (one line) when it is not a regular file, too large or not Parquet."""
    path = Path(path)
    label = label or str(path)
    try:
        st = os.stat(path)
        if not S_ISREG(st.st_mode):
            raise ConfigError(
                f"results {str(path)!r} is not a regular file; expected a .parquet file"
            )
        if st.st_size > MAX_RESULTS_BYTES:
            raise ConfigError(
                f"results {str(path)!r} hold {st.st_size} bytes; expected at most "
                f"{MAX_RESULTS_BYTES}"
            )
        schema = pq.read_schema(path)
        table = pq.read_table(
            path, columns=[c for c in schema.names if c in RESULT_COLUMNS or c not in NOT_VARIED]
        )
    except FileNotFoundError:
        raise ConfigError(f"results {str(path)!r} do not exist") from None
    except (OSError, pa.ArrowException) as err:
        why = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise ConfigError(f"results {str(path)!r} cannot be read as Parquet: {why}") from err
    return side_from_table(table, label)


@dataclass
class Flip:
    """One scenario whose outcome changed: its values, and the reasons before and now."""

    scenario: int
    values: dict
    reason_before: str
    reason_now: str
    placement_before_mm: float | None
    placement_now_mm: float | None

    def as_dict(self) -> dict:
        return {
            "scenario": self.scenario,
            "values": self.values,
            "reason_before": self.reason_before,
            "reason_now": self.reason_now,
            "placement_before_mm": self.placement_before_mm,
            "placement_now_mm": self.placement_now_mm,
        }


@dataclass
class Paired:
    """The paired comparison of `new` against `reference` on their common scenarios."""

    reference: str
    new: str
    n: int  # scenarios in both
    only_reference: int
    only_new: int
    both_ok: int
    worse: int  # ok -> failed
    better: int  # failed -> ok
    neither_ok: int
    difference: float  # new rate - reference rate
    interval: tuple[float, float]  # Newcombe's paired 95 %
    mcnemar_p: float
    shift: tuple[float, float, float] | None  # median placement difference, its 95 % interval
    shift_count: int  # scenarios that placed in both runs
    placed_changed: int  # scenarios that placed in one run only
    largest_move: tuple[int, float] | None  # (scenario, new - reference mm) of the largest |move|
    values_moved: dict[str, int] = field(default_factory=dict)  # key -> scenarios it differs in
    worse_flips: list[Flip] = field(default_factory=list)  # the first LISTED of each
    better_flips: list[Flip] = field(default_factory=list)
    moved: np.ndarray | None = None  # per common scenario: new - reference placement (NaN: none)
    common: np.ndarray | None = None  # the common scenario numbers
    flip_kind: np.ndarray | None = None  # per common scenario: -1 worse, +1 better, 0 unchanged
    # the smallest drop (percentage points) "significant" finds at 80 % power (None: n < 6)
    detectable_drop_pct: float | None = None

    @property
    def reference_rate(self) -> float:
        return (self.both_ok + self.worse) / self.n if self.n else 0.0

    @property
    def new_rate(self) -> float:
        return (self.both_ok + self.better) / self.n if self.n else 0.0

    def as_dict(self) -> dict:
        out = {
            "kind": "paired",
            "reference": self.reference,
            "new": self.new,
            "scenarios": self.n,
            "only_in_reference": self.only_reference,
            "only_in_new": self.only_new,
            "reference_ok": self.both_ok + self.worse,
            "new_ok": self.both_ok + self.better,
            "reference_success_rate": self.reference_rate,
            "new_success_rate": self.new_rate,
            "ok_to_failed": self.worse,
            "failed_to_ok": self.better,
            "difference": self.difference,
            "newcombe_paired95": list(self.interval),
            "mcnemar_exact_p": self.mcnemar_p,
            "detectable_drop_pct": self.detectable_drop_pct,
            "placement_shift_mm": None
            if self.shift is None
            else {
                "median": self.shift[0],
                "ci95": [self.shift[1], self.shift[2]],
                "method": "sign-test order statistics",
                "count": self.shift_count,
            },
            "placed_in_one_run_only": self.placed_changed,
            "largest_placement_move": None
            if self.largest_move is None
            else {"scenario": self.largest_move[0], "mm": self.largest_move[1]},
            "values_moved": self.values_moved,
            "ok_to_failed_scenarios": [f.as_dict() for f in self.worse_flips],
            "failed_to_ok_scenarios": [f.as_dict() for f in self.better_flips],
        }
        return out


def pair(reference: Side, new: Side) -> Paired:
    """Compare new with reference on the scenarios both hold."""
    common, ir, inew = np.intersect1d(
        reference.scenario, new.scenario, assume_unique=True, return_indices=True
    )
    ok_r, ok_n = reference.ok[ir], new.ok[inew]
    worse_mask, better_mask = ok_r & ~ok_n, ~ok_r & ok_n
    both, worse, better = int((ok_r & ok_n).sum()), int(worse_mask.sum()), int(better_mask.sum())
    n = len(common)
    neither = n - both - worse - better
    moved = new.placement_mm[inew] - reference.placement_mm[ir]
    placed = ~np.isnan(moved)
    diffs = moved[placed]
    largest = None
    if diffs.size:
        k = int(np.argmax(np.abs(np.where(placed, moved, 0.0))))
        largest = (int(common[k]), float(moved[k]))
    values_moved = {}
    for key in reference.keys:
        if key in new.keys:
            a = reference.table.column(key).take(pa.array(ir))
            b = new.table.column(key).take(pa.array(inew))
            differs = _differs(a, b)
            if differs:
                values_moved[key] = differs
    kind = np.zeros(n, dtype=np.int8)
    kind[worse_mask], kind[better_mask] = -1, 1
    return Paired(
        reference=reference.label,
        new=new.label,
        n=n,
        only_reference=reference.n - n,
        only_new=new.n - n,
        both_ok=both,
        worse=worse,
        better=better,
        neither_ok=neither,
        difference=(better - worse) / n if n else 0.0,
        interval=newcombe_paired(both, better, worse, neither),
        mcnemar_p=mcnemar_exact(worse, better),
        shift=median_ci(diffs),
        shift_count=int(diffs.size),
        placed_changed=int(
            (np.isnan(reference.placement_mm[ir]) != np.isnan(new.placement_mm[inew])).sum()
        ),
        largest_move=largest,
        values_moved=values_moved,
        worse_flips=_flips(reference, new, ir, inew, np.flatnonzero(worse_mask)[:LISTED]),
        better_flips=_flips(reference, new, ir, inew, np.flatnonzero(better_mask)[:LISTED]),
        moved=moved,
        common=common,
        flip_kind=kind,
        detectable_drop_pct=power.detectable_drop_pct(n, worse + better),
    )


def first_moved(reference: Side, new: Side) -> tuple[str, int] | None:
    """The first varied key (in reference's order) whose value differs in a scenario both hold, and
    the first such scenario; None when every shared scenario has the same values."""
    common, ir, inew = np.intersect1d(
        reference.scenario, new.scenario, assume_unique=True, return_indices=True
    )
    for key in reference.keys:
        if key not in new.keys:
            continue
        a = reference.table.column(key).take(pa.array(ir))
        b = new.table.column(key).take(pa.array(inew))
        if a.type != b.type:
            return key, int(common[0])
        same = pc.or_(pc.equal(a, b).fill_null(False), pc.and_(pc.is_null(a), pc.is_null(b)))
        differ = ~same.to_numpy(zero_copy_only=False)
        if differ.any():
            return key, int(common[np.flatnonzero(differ)[0]])
    return None


def _differs(a: pa.ChunkedArray, b: pa.ChunkedArray) -> int:
    """In how many rows two columns of values differ (a type change: all of them)."""
    if a.type != b.type:
        return len(a)
    same = pc.equal(a, b)
    both_null = pc.and_(pc.is_null(a), pc.is_null(b))
    return len(a) - int(pc.sum(pc.or_(same.fill_null(False), both_null)).as_py() or 0)


def _flips(
    reference: Side, new: Side, ir: np.ndarray, inew: np.ndarray, where: np.ndarray
) -> list[Flip]:
    """The flips at positions `where` (of the common scenarios) as rows: a few, never all."""
    if where.size == 0:
        return []
    old_rows = reference.table.take(pa.array(ir[where])).to_pylist()
    new_rows = new.table.take(pa.array(inew[where])).to_pylist()
    out = []
    for old, now in zip(old_rows, new_rows, strict=True):
        out.append(
            Flip(
                scenario=now["scenario"],
                values={k: now[k] for k in new.keys},
                reason_before=old["error"] or "",
                reason_now=now["error"] or "",
                placement_before_mm=old["placement_error_mm"],
                placement_now_mm=now["placement_error_mm"],
            )
        )
    return out


def problems(p: Paired, rule: str, shift_mm: float) -> list[str]:
    """What fails the verdict under rule ("significant" or "strict"), one line each."""
    out = []
    if rule == "strict":
        if p.worse or p.better:
            out.append(
                f"{p.worse + p.better} scenarios flipped (strict: any flip fails): {flip_text(p)}"
            )
        if p.placed_changed:
            out.append(f"{p.placed_changed} scenarios placed in one run only")
        if p.largest_move is not None and abs(p.largest_move[1]) > shift_mm:
            beyond = int((np.abs(np.nan_to_num(p.moved)) > shift_mm).sum())
            out.append(
                f"placement error moved beyond {shift_mm:g} mm in {beyond} scenarios "
                f"(largest {p.largest_move[1]:+.3f} mm, scenario {p.largest_move[0]})"
            )
        return out
    if p.worse > p.better and p.mcnemar_p < ALPHA:
        out.append(f"success rate dropped significantly: {rate_text(p)}; {flip_text(p)}")
    if p.shift is not None and p.shift[1] > 0 and p.shift[0] > shift_mm:
        out.append(
            f"placement error grew significantly: paired median shift {p.shift[0]:+.3f} mm "
            f"(95 % {p.shift[1]:+.3f} to {p.shift[2]:+.3f}), beyond {shift_mm:g} mm"
        )
    return out


def warnings(p: Paired, rule: str, success_drop_pct: float | None) -> list[str]:
    """What the verdict says without failing, one line each: the drop the definition cares about
    (success_drop_pct, points) when it is below what the verdict detects, and a measured drop
    beyond it that "significant" does not fail (not significant: it may be the flips' noise)."""
    if success_drop_pct is None or p.n == 0:
        return []
    out = []
    warning = power.threshold_warning(
        success_drop_pct, p.n, p.worse + p.better, p.detectable_drop_pct, rule
    )
    if warning:
        out.append(warning)
    measured_pct = -100.0 * p.difference
    if rule != "strict" and measured_pct > success_drop_pct and p.mcnemar_p >= ALPHA:
        out.append(
            f"the measured drop, {measured_pct:.2f} points, is beyond success_drop_pct "
            f"{success_drop_pct:g} but not significant (McNemar exact p = "
            f"{p.mcnemar_p:.3g}): it does not fail the significant rule"
        )
    return out


def rate_text(p: Paired) -> str:
    lo, hi = p.interval
    return (
        f"{100 * p.reference_rate:.2f} % -> {100 * p.new_rate:.2f} %, paired difference "
        f"{100 * p.difference:+.2f} points (Newcombe 95 % {100 * lo:+.2f} to {100 * hi:+.2f}), "
        f"McNemar exact p = {p.mcnemar_p:.3g}"
    )


def flip_text(p: Paired, most: int = 5) -> str:
    """ok->failed and failed->ok counts with their first scenario numbers."""

    def some(flips: list[Flip], count: int) -> str:
        shown = ", ".join(str(f.scenario) for f in flips[:most])
        return shown + (", ..." if count > most else "")

    parts = []
    if p.worse:
        parts.append(f"ok->failed {p.worse} ({some(p.worse_flips, p.worse)})")
    if p.better:
        parts.append(f"failed->ok {p.better} ({some(p.better_flips, p.better)})")
    return ", ".join(parts) or "no flips"


def rerun_hint(p: Paired, definition: str) -> str:
    first = (p.worse_flips or p.better_flips or [None])[0]
    if first is None:
        return ""
    return f"twin sweep {definition} --only {first.scenario} --out runs/s{first.scenario}"


def _values_text(values: dict) -> str:
    return ", ".join(f"{k}={_short(v)}" for k, v in values.items())


def _short(v: object) -> str:
    return f"{v:.5g}" if isinstance(v, float) else str(v)


def _mm(v: float | None) -> str:
    return "none" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.2f} mm"


def report_text(p: Paired, definition: str | None = None, rule: str = "significant") -> str:
    """The paired comparison as text (twin check -v, twin sweep compare)."""
    lines = [f"paired on {p.n} scenarios: reference {p.reference}, new {p.new}"]
    if p.only_reference or p.only_new:
        lines.append(
            f"  not paired: {p.only_reference} scenarios only in the reference, "
            f"{p.only_new} only in the new run"
        )
    lines.append(
        f"  ok->failed {p.worse}, failed->ok {p.better}, unchanged "
        f"{p.both_ok + p.neither_ok} ({p.both_ok} ok, {p.neither_ok} failed in both)"
    )
    lines.append(f"  success rate {rate_text(p)}")
    lines.append(f"  {power.detectable_text(p.n, p.detectable_drop_pct, rule)}")
    if p.shift is not None:
        med, lo, hi = p.shift
        lines.append(
            f"  placement error, paired shift (new - reference) over {p.shift_count} "
            f"scenarios: median {med:+.3f} mm (95 % {lo:+.3f} to {hi:+.3f}, sign test)"
            + (
                f"; largest move {p.largest_move[1]:+.3f} mm (scenario {p.largest_move[0]})"
                if p.largest_move and p.largest_move[1]
                else ""
            )
        )
    if p.placed_changed:
        lines.append(f"  placed in one run only: {p.placed_changed} scenarios")
    if p.values_moved:
        lines.append(
            "  varied values that differ between the runs: "
            + ", ".join(f"{k} ({c} of {p.n} scenarios)" for k, c in p.values_moved.items())
        )
    for title, flips, count, before in (
        ("ok->failed", p.worse_flips, p.worse, False),
        ("failed->ok", p.better_flips, p.better, True),
    ):
        if not count:
            continue
        lines.append(f"  {title}:")
        for f in flips:
            why = f"was: {f.reason_before}" if before else f"now: {f.reason_now}"
            lines.append(f"    scenario {f.scenario}: {_values_text(f.values)}; {why}")
        if count > len(flips):
            lines.append(f"    ... and {count - len(flips)} more")
    if definition and (p.worse or p.better):
        lines.append(f"  re-run one, recorded: {rerun_hint(p, definition)}")
    return "\n".join(lines) + "\n"


def report_markdown(p: Paired, definition: str | None = None, rule: str = "significant") -> str:
    lo, hi = p.interval
    rows = [
        ("scenarios paired", str(p.n)),
        ("success rate", f"{100 * p.reference_rate:.2f} % -> {100 * p.new_rate:.2f} %"),
        ("ok -> failed / failed -> ok", f"{p.worse} / {p.better}"),
        (
            "paired difference (Newcombe 95 %)",
            f"{100 * p.difference:+.2f} points ({100 * lo:+.2f} to {100 * hi:+.2f})",
        ),
        ("McNemar exact p", f"{p.mcnemar_p:.3g}"),
    ]
    if p.shift is not None:
        rows.append(
            (
                "placement shift, median (95 %, sign test)",
                f"{p.shift[0]:+.3f} mm ({p.shift[1]:+.3f} to {p.shift[2]:+.3f})",
            )
        )
    lines = [
        f"# Paired comparison: {p.new} vs {p.reference}",
        "",
        "| statistic | value |",
        "|---|---|",
        *(f"| {a} | {b} |" for a, b in rows),
        "",
        f"The verdict {power.detectable_text(p.n, p.detectable_drop_pct, rule)}.",
        "",
    ]
    for title, flips, count, before in (
        ("ok -> failed", p.worse_flips, p.worse, False),
        ("failed -> ok", p.better_flips, p.better, True),
    ):
        if not count:
            continue
        lines += [f"## {title} ({count})", "", "| scenario | values | reason |", "|---|---|---|"]
        lines += [
            f"| {f.scenario} | {_values_text(f.values)} | "
            f"{(f.reason_before if before else f.reason_now).replace('|', '/')} |"
            for f in flips
        ]
        if count > len(flips):
            lines.append(f"| ... | {count - len(flips)} more | |")
        lines.append("")
    if definition and (p.worse or p.better):
        lines += [f"Re-run one, recorded: `{rerun_hint(p, definition)}`", ""]
    return "\n".join(lines)
