"""Statistical goldens: a sweep definition `NAME.toml` with its expected summary `NAME.summary.json`
beside it. Checking re-runs the sweep and judges it by statistics, not bytes: the success rate
must lie in the golden's Wilson 95 % interval, and the placement-error percentiles (p50, p95, max)
within the definition's tolerances (`[tolerance]`, else spec.TOLERANCES). `update` rewrites the
summary when it changed at all."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from pathlib import Path

from twin.errors import ConfigError, TwinError
from twin.sweep.results import summary, summary_text
from twin.sweep.runner import run_sweep
from twin.sweep.spec import load_spec, prepare
from twin.sweep.worker import Job
from twin.verify.check import Outcome

PERCENTILES = (("p50", "placement_p50_mm"), ("p95", "placement_p95_mm"), ("max", "placement_max_mm"))


def summary_path(definition: str | os.PathLike) -> Path:
    path = Path(definition)
    return path.with_name(path.stem + ".summary.json")


def split_paths(paths: Sequence[str]) -> tuple[list[str], list[str]]:
    """The arguments of `twin check` split into what verify.check expands (.mcap files and folders
    of them) and sweep definitions (.toml files, and the .toml files of a folder). A folder without
    .toml files goes to the first list as it is (so an empty one is still reported there)."""
    recordings, sweeps = [], []
    for p in paths:
        path = Path(p)
        if p.endswith(".toml"):
            if not path.is_file():
                raise ConfigError(f"sweep definition {p!r} does not exist")
            sweeps.append(p)
        elif path.is_dir() and any(path.glob("*.toml")):
            sweeps += sorted(str(t) for t in path.glob("*.toml"))
            if any(path.glob("*.mcap")):
                recordings.append(p)
        else:
            recordings.append(p)
    return recordings, sweeps


def judge(golden: dict, new: dict, tolerances: dict[str, float]) -> list[str]:
    """What moved beyond its tolerance, one line each naming the statistic and by how much."""
    problems = []
    if new["scenarios"] != golden.get("scenarios"):
        problems.append(f"scenarios {new['scenarios']} differ from the golden's {golden.get('scenarios')}")
    rate, g_rate = new["success_rate"], golden.get("success_rate", 0.0)
    lo, hi = golden.get("wilson95", [0.0, 1.0])
    if not lo <= rate <= hi:
        problems.append(f"success_rate {rate:.4f} is outside the golden's Wilson 95 % interval [{lo:.4f}, {hi:.4f}] "
                        f"(golden {g_rate:.4f}, moved {rate - g_rate:+.4f})")
    g_pe, pe = golden.get("placement_error_mm", {}), new["placement_error_mm"]
    for stat, tol_name in PERCENTILES:
        before, now = g_pe.get(stat), pe[stat]
        if (before is None) != (now is None):
            problems.append(f"placement_error_mm.{stat} was {before} and is {now} now")
        elif before is not None and abs(now - before) > tolerances[tol_name]:
            problems.append(f"placement_error_mm.{stat} moved {now - before:+.3f} mm (golden {before:.3f}, now "
                            f"{now:.3f}; tolerance {tolerances[tol_name]:g} mm)")
    return problems


def check_sweep(definition: str, executor, *, update: bool = False) -> Outcome:
    """Re-run one sweep golden on executor and judge it; an Outcome as verify.check gives for a recording."""
    t0 = time.perf_counter()
    expected_path = summary_path(definition)
    try:
        spec = load_spec(definition)
        prepare(spec)
        golden = _read(expected_path) if expected_path.exists() else None
        if golden is None and not update:
            raise ConfigError(f"sweep golden {definition!r} has no {expected_path.name} beside it; "
                              f"`twin check --update {definition}` writes it")
        done = run_sweep(Job(spec, None, "none"), range(spec.scenarios), executor)
        if done.stopped_by is not None:
            raise done.stopped_by
        new = summary(spec, done.rows)
        report = _report(golden, new)
        problems = judge(golden, new, spec.tolerances()) if golden is not None else ["no golden summary yet"]
        seconds = time.perf_counter() - t0
        if update and new != golden:
            expected_path.write_text(summary_text(new))
            return Outcome(definition, "updated", 0, "rewritten; was: " + ("; ".join(problems) or "within tolerance"),
                           report, spec.scenarios, seconds)
        if problems:
            return Outcome(definition, "differ", 1, "; ".join(problems), report, spec.scenarios, seconds)
        detail = "matches" if new == golden else "within tolerance: " + _moves(golden, new)
        return Outcome(definition, "match", 0, detail, report, spec.scenarios, seconds)
    except TwinError as err:
        return Outcome(definition, "error", err.exit_code, str(err), "", 0, time.perf_counter() - t0)


def _read(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ConfigError(f"sweep golden summary {str(path)!r} is unreadable: {err}") from err
    if not isinstance(data, dict) or not isinstance(data.get("placement_error_mm"), dict):
        raise ConfigError(f"sweep golden summary {str(path)!r} is not a sweep summary")
    return data


def _moves(golden: dict, new: dict) -> str:
    pe, g_pe = new["placement_error_mm"], golden["placement_error_mm"]
    parts = [f"success_rate {new['success_rate'] - golden['success_rate']:+.4f}"]
    parts += [f"{stat} {pe[stat] - g_pe[stat]:+.3f} mm" for stat, _ in PERCENTILES
              if pe[stat] is not None and g_pe.get(stat) is not None]
    return ", ".join(parts)


def _report(golden: dict | None, new: dict) -> str:
    """Golden and new statistics side by side (`twin check -v`)."""
    def row(name: str, g: object, n: object) -> str:
        return f"  {name:<26} {g!s:>22} {n!s:>22}"

    g = golden or {}
    g_pe, pe = g.get("placement_error_mm", {}), new["placement_error_mm"]
    lines = [row("statistic", "golden", "now"), row("scenarios", g.get("scenarios"), new["scenarios"]),
             row("success_rate", g.get("success_rate"), new["success_rate"]),
             row("wilson95", g.get("wilson95"), [round(v, 4) for v in new["wilson95"]])]
    lines += [row(f"placement_error_mm.{s}", g_pe.get(s), pe[s]) for s, _ in PERCENTILES]
    lines.append(row("failures_by_reason", json.dumps(g.get("failures_by_reason")), json.dumps(new["failures_by_reason"])))
    return "\n".join(lines) + "\n"
