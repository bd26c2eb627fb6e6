"""Rendering a DiffResult: text for the terminal, Markdown, JSON and JUnit XML for CI.

Every format leads with the verdict and the first divergence (step, simulated time, channel,
field, expected, actual, difference, tolerance), then per-field worst error and RMS, the event
differences and the final object poses.
"""

from __future__ import annotations

import json
import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

from twin.compare.identity import identity_summary
from twin.compare.result import DiffResult, Divergence, FieldStat
from twin.model.errors import ConfigError, OutputError

FORMATS = {".md": "markdown", ".json": "json", ".xml": "junit", ".txt": "text"}


def fmt(x: float, unit: str = "") -> str:
    """A number for people: inf/nan spelled out, 4 significant digits (an exact 0 only for a true
    zero: 2.85e-51 stays 2.85e-51), unit appended."""
    if isinstance(x, float) and math.isinf(x):
        text = "inf"
    elif isinstance(x, float) and math.isnan(x):
        text = "nan"
    elif isinstance(x, int):
        text = str(x)
    else:
        text = "0" if x == 0 else f"{x:.4g}"
    return f"{text} {unit}".rstrip() if unit else text


def fmt_values(values: list) -> str:
    """Exact values (repr), so bit-level differences stay visible."""
    if len(values) == 1:
        return "none" if values[0] is None else repr(values[0])
    return "(" + ", ".join(repr(v) for v in values) + ")"


def verdict(result: DiffResult) -> str:
    return "MATCH" if result.match else "MISMATCH"


def first_line(d: Divergence) -> str:
    element = f" [{d.element}]" if d.element else ""
    return f"step {d.step} (t = {d.t_s:.6f} s): {d.name}{element}"


def first_detail(d: Divergence) -> str:
    if d.channel == "commands":
        what = "annotation" if d.field == "annotations" else "command"
        return (
            f"the golden's {what} #{d.element.split()[0][1:]} is {d.expected[0] or 'absent'}; "
            f"the candidate's is {d.actual[0] or 'absent'}"
        )
    if d.channel == "events":
        if d.field == "missing":
            return f"the golden has it at step {d.expected[0]}; the candidate has no such event"
        if d.field == "extra":
            return f"the candidate has it at step {d.actual[0]}; the golden has no such event"
        return (
            f"expected at step {d.expected[0]}, actual at step {d.actual[0]}: moved "
            f"{fmt(d.difference, 'steps')}, "
            f"more than the event window"
        )
    text = (
        f"expected {fmt_values(d.expected)}, actual {fmt_values(d.actual)}, "
        f"difference {fmt(d.difference, d.unit)}, tolerance {fmt(d.tolerance, d.unit)}"
    )
    if d.floor > 0:
        text += f", noise floor {fmt(d.floor, d.unit)}"
    return text


def allowance_text(d: Divergence) -> str:
    """How far a divergence passed what was allowed there: "3.2x the allowance (noise floor F,
    tolerance T)"; "" for a field without a unit (commands, outcome) or an allowance of 0."""
    limit = max(d.tolerance, d.floor)
    if not d.unit or not limit > 0:
        return ""
    return (
        f"{d.difference / limit:.3g}x the allowance (noise floor {fmt(d.floor, d.unit)}, "
        f"tolerance {fmt(d.tolerance, d.unit)})"
    )


def noise_summary(result: DiffResult) -> str:
    """One line on how the candidate stands to the golden: bit-identical; within numerical noise
    (the largest difference against what was allowed there); or changed (how much, where, how many
    times the allowance: the larger of the tolerance and the measured noise floor)."""
    if result.first is not None:
        d = result.first
        if not d.unit:
            return f"changed at step {d.step} ({d.name})"
        what = f"changed: {fmt(d.difference, d.unit)} at step {d.step} ({d.name}" + (
            f" [{d.element}])" if d.element else ")"
        )
        allowance = allowance_text(d) if result.floor is not None else ""
        return f"{what}, {allowance}" if allowance else what
    moved = [
        f
        for f in result.fields
        if not f.identical and f.worst > 0 and f.unit and math.isfinite(f.worst)
    ]
    if not moved:
        return "bit-identical"
    if result.tolerances.preset == "outcome":
        return _same_outcome(result)
    worst = max(moved, key=lambda f: f.worst / max(f.floor, f.tolerance, 1e-300))
    unit = worst.unit.split("|")[0]
    if result.floor is None:  # judged by tolerances alone: no noise was measured
        return (
            f"within tolerance (max {fmt(worst.worst, unit)} in {worst.name}; tolerance "
            f"{fmt(worst.tolerance, unit)})"
        )
    return (
        f"within numerical noise (max {fmt(worst.worst, unit)} in {worst.name}; noise floor "
        f"{fmt(worst.floor, unit)}, tolerance {fmt(worst.tolerance, unit)})"
    )


def _same_outcome(result: DiffResult) -> str:
    """A match under `outcome`: where the objects ended against where the golden's did."""
    if not result.final_poses:
        return "same outcome"
    far = max(result.final_poses, key=lambda p: p.distance_m)
    limit = result.tolerances["final.position"]
    within = f", within {limit * 1e3:g} mm" if math.isfinite(limit) else ""
    return f"same outcome; {far.name} {far.distance_m * 1e3:.1f} mm from the golden's place{within}"


def headline(result: DiffResult) -> str:
    """The one line a check prints for a golden: on a mismatch what changed, both values and by
    how much (twin.compare.explain), else how the runs stand (noise_summary)."""
    if result.first is None:
        return noise_summary(result) + identity_summary(result.identity, result.match)
    explained = result.explanation.headline if result.explanation is not None else ""
    text = explained or first_line(result.first)
    if result.floor is not None and allowance_text(result.first):
        text += f" [{allowance_text(result.first)}]"
    return text


def _run_line(info: dict) -> str:
    run = info.get("run") or {}
    what = run.get("task") or run.get("source") or "?"
    params = json.dumps(run.get("params", {}), sort_keys=True)
    return (
        f"{info.get('path') or '<memory>'} ({info['profile']}, {run.get('source', '?')} "
        f"{what} {params}, "
        f"{info['frames']} frames, steps {info['first_step']}..{info['last_step']})"
    )


def _field_row(f: FieldStat) -> list[str]:
    status = (
        "off"
        if f.tolerance == math.inf
        else ("FAIL" if not f.ok else "identical" if f.identical else "ok")
    )
    where = f"{f.worst_step}" + (f" [{f.worst_element}]" if f.worst_element else "")
    return [
        f.name,
        f.unit,
        fmt(f.tolerance),
        fmt(f.floor),
        fmt(f.worst),
        where,
        fmt(f.rms),
        str(f.steps_over),
        status,
    ]


_FIELD_HEAD = [
    "field",
    "unit",
    "tolerance",
    "noise floor",
    "worst",
    "at step",
    "rms",
    "steps over",
    "status",
]


def _window_text(result: DiffResult) -> str:
    w = result.tolerances.event_window_steps
    return "events not paired" if w is None else f"event window {w} steps"


def _event_lines(result: DiffResult, dt_s: float) -> list[str]:
    counts = "; counts: " + ", ".join(
        f"{f.name.split('.')[1]} {'ok' if f.ok else 'FAIL'}"
        for f in result.fields
        if f.name.startswith("counts.")
    )
    if not result.events_compared:
        return ["events: not paired one by one under these tolerances" + counts]
    lines = [
        f"events: {result.events_matched} matched ({result.events_shifted} shifted within "
        f"{result.tolerances.event_window_steps} steps), "
        + ", ".join(
            f"{sum(d.kind == k for d in result.event_diffs)} {k}"
            for k in ("missing", "extra", "moved")
        )
    ]
    for d in result.event_diffs:
        where = ", ".join(
            f"{side} step {s} (t = {s * dt_s:.3f} s)"
            for side, s in (("expected", d.expected_step), ("actual", d.actual_step))
            if s is not None
        )
        lines.append(f"  {d.kind:<8} {d.event_kind} {d.body}".rstrip() + f": {where}")
    return lines


def _cause_lines(result: DiffResult) -> list[str]:
    """The first command difference (when it is not itself the first divergence) and the likely
    cause."""
    lines = []
    fc = result.first_command
    if fc is not None and fc is not result.first:
        lines.append(f"first command difference: {first_line(fc)}: {first_detail(fc)}")
    configuration = result.explanation.configuration if result.explanation is not None else []
    if configuration and result.first is not None:
        lines.append("likely cause: " + "; ".join(configuration))
    elif result.likely_cause and (fc is None or fc is not result.first):
        lines.append(
            f"likely cause: the golden's last command at or before step {result.first.step}: "
            f"{result.likely_cause}"
        )
    elif result.explanation is not None and result.explanation.task_file_changed:
        lines.append("likely cause: the task file changed since the golden was recorded")
    fa = result.first_annotation
    if fa is not None and fa is result.first:
        lines.append(
            "annotations only: the runs do not diverge physically (what the tasks said differs; "
            "--tol commands.annotations=inf leaves it out)"
        )
    elif fa is not None:
        lines.append(
            f"annotations differ too (apart from the physical divergence): {first_line(fa)}: "
            f"{first_detail(fa)}"
        )
    return lines


def _final_lines(result: DiffResult) -> list[str]:
    lines = ["final object poses:"]
    for p in result.final_poses:
        e, a = p.expected, p.actual
        lines.append(
            f"  {p.name}: expected ({e[0]:+.5f}, {e[1]:+.5f}, {e[2]:+.5f}) m, actual ({a[0]:+.5f}, "
            f"{a[1]:+.5f}, {a[2]:+.5f}) m, distance {p.distance_m * 1e3:.4g} mm, angle "
            f"{p.angle_rad * 1e3:.4g} mrad  [{'ok' if p.ok else 'FAIL'}]"
        )
    return lines


def render_text(result: DiffResult) -> str:
    dt_s = result.golden["dt_ns"] * 1e-9
    t = result.tolerances
    lines = [
        f"{verdict(result)} (tolerance {t.preset}"
        + (f", {' '.join(t.overrides)}" if t.overrides else "")
        + f", {_window_text(result)})",
        f"  golden:    {_run_line(result.golden)}",
        f"  candidate: {_run_line(result.candidate)}",
    ]
    lines += [f"  note: {n}" for n in result.notes]
    if result.config_differences:
        lines.append(
            "  configuration differences: "
            + "; ".join(f"{k} {a} -> {b}" for k, a, b in result.config_differences[:8])
            + (
                f"; and {len(result.config_differences) - 8} more"
                if len(result.config_differences) > 8
                else ""
            )
        )
    if result.floor is not None:
        lines.append(
            f"  noise floor: measured on a run with {result.floor.perturbation}, times "
            f"{result.floor.margin:g}"
        )
    lines.append(f"  {noise_summary(result)}")
    if result.first is not None and result.explanation is not None:
        lines.append(f"  what changed: {result.explanation.headline}")
    if result.first is None:
        lines.append(f"no divergence over {result.steps_compared} common steps")
    else:
        lines += [
            f"first divergence: {first_line(result.first)}",
            f"  {first_detail(result.first)}",
        ]
        lines += [f"  {line}" for line in _cause_lines(result)]
    rows = [_FIELD_HEAD] + [_field_row(f) for f in result.fields]
    widths = [max(len(r[i]) for r in rows) for i in range(len(_FIELD_HEAD))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    lines += _event_lines(result, dt_s) + _final_lines(result)
    return "\n".join(lines) + "\n"


def render_markdown(result: DiffResult) -> str:
    dt_s = result.golden["dt_ns"] * 1e-9
    t = result.tolerances
    out = [
        f"# twin diff: {verdict(result)}",
        "",
        f"- tolerance: `{t.preset}`"
        + (f" with `{' '.join(t.overrides)}`" if t.overrides else "")
        + f", {_window_text(result)}",
        f"- golden: `{_run_line(result.golden)}`",
        f"- candidate: `{_run_line(result.candidate)}`",
    ]
    out += [f"- note: {n}" for n in result.notes]
    out += [f"- configuration differs: `{k}` {a} → {b}" for k, a, b in result.config_differences]
    out.append("")
    out += [f"**{noise_summary(result)}**", ""]
    if result.first is not None and result.explanation is not None:
        out += [f"What changed: {result.explanation.headline}", ""]
    if result.first is None:
        out.append(f"No divergence over {result.steps_compared} common steps.")
    else:
        out += [
            "## First divergence",
            "",
            f"**{first_line(result.first)}**",
            "",
            first_detail(result.first),
        ]
        out += ["", *(f"- {line}" for line in _cause_lines(result))] if _cause_lines(result) else []
    out += [
        "",
        "## Fields",
        "",
        "| " + " | ".join(_FIELD_HEAD) + " |",
        "|" + "---|" * len(_FIELD_HEAD),
    ]
    out += [
        "| " + " | ".join(c.replace("|", "\\|") for c in _field_row(f)) + " |"
        for f in result.fields
    ]
    out += ["", "## Events", ""] + [f"- {line.strip()}" for line in _event_lines(result, dt_s)]
    out += ["", "## Final object poses", ""] + [
        f"- {line.strip()}" for line in _final_lines(result)[1:]
    ]
    return "\n".join(out) + "\n"


def render_json(result: DiffResult) -> str:
    return json.dumps(result.to_dict(), indent=2, sort_keys=True) + "\n"


def render_junit(result: DiffResult, suite: str = "twin diff") -> str:
    """One testcase per field (the final poses among them), one for the events; failures carry the
    details."""
    cases = []
    for f in result.fields:
        msg = None if f.ok else f"{first_line(f.first)}: {first_detail(f.first)}"
        cases.append(
            (
                f.name,
                msg,
                f"worst {fmt(f.worst, f.unit)} at step {f.worst_step}, rms {fmt(f.rms, f.unit)}",
            )
        )
    ev_lines = _event_lines(result, result.golden["dt_ns"] * 1e-9)
    cases.append(("events", "; ".join(ev_lines[1:]) if result.event_diffs else None, ev_lines[0]))
    suite_el = ET.Element(
        "testsuite",
        name=suite,
        tests=str(len(cases)),
        failures=str(sum(m is not None for _, m, _ in cases)),
        errors="0",
    )
    props = ET.SubElement(suite_el, "properties")
    for key in ("golden", "candidate"):
        ET.SubElement(props, "property", name=key, value=_run_line(getattr(result, key)))
    ET.SubElement(
        props,
        "property",
        name="first_divergence",
        value="none" if result.first is None else first_line(result.first),
    )
    classname = Path(result.golden.get("path") or "golden").stem
    for name, msg, info in cases:
        case = ET.SubElement(suite_el, "testcase", classname=classname, name=name)
        if msg is not None:
            ET.SubElement(case, "failure", message=msg).text = msg
        ET.SubElement(case, "system-out").text = info
    if not result.match:  # the whole report once, for the suite, not once per failing case
        ET.SubElement(suite_el, "system-out").text = render_text(result)
    return _junit_document(suite_el)


def render_check_junit(outcomes: list, suite: str = "twin check") -> str:
    """JUnit XML for `twin check`: one testcase per golden (check.Outcome), the text report on
    failure."""
    suite_el = ET.Element(
        "testsuite",
        name=suite,
        tests=str(len(outcomes)),
        failures=str(sum(o.status in ("differ", "refused") for o in outcomes)),
        errors=str(sum(o.status == "error" for o in outcomes)),
        time=f"{sum(o.seconds for o in outcomes):.3f}",
    )
    for o in outcomes:
        case = ET.SubElement(
            suite_el,
            "testcase",
            classname="goldens",
            name=Path(o.path).name,
            time=f"{o.seconds:.3f}",
        )
        if o.status in ("differ", "refused"):
            ET.SubElement(case, "failure", message=o.summary).text = o.report
        elif o.status == "error":
            ET.SubElement(case, "error", message=o.summary)
        elif o.status == "updated":
            ET.SubElement(case, "system-out").text = o.summary
    return _junit_document(suite_el)


def _junit_document(suite: ET.Element) -> str:
    """One test suite as a JUnit XML document."""
    root = ET.Element("testsuites")
    root.append(suite)
    ET.indent(root)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


RENDERERS = {
    "text": render_text,
    "markdown": render_markdown,
    "json": render_json,
    "junit": render_junit,
}


def report_format(path: str | os.PathLike) -> str:
    """The format a report path asks for, by its extension."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise ConfigError(
            f"report file {str(path)!r} has an unknown extension {suffix!r}; "
            f"expected one of {', '.join(FORMATS)}"
        )
    return FORMATS[suffix]


def render_report(result: DiffResult, path: str | os.PathLike) -> str:
    """The report in the format the extension of `path` names (.md, .json, .xml JUnit, .txt)."""
    return RENDERERS[report_format(path)](result)


def write_report(result: DiffResult, path: str | os.PathLike) -> None:
    """Write the report in the format the extension names (.md, .json, .xml JUnit, .txt)."""
    text = render_report(result, path)
    try:
        Path(path).write_text(text)
    except OSError as err:
        raise OutputError(f"cannot write report {str(path)!r}: {err.strerror}") from err
