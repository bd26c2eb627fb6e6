"""One differing golden's part of the report, built where both runs are in memory (the process
that checked it): what changed, a plot per diverging field, the paths from above, the events, the
pictures at the onset, the configuration and task differences, and the commands that show it
again. HTML text, so a check's worker hands back a string, not two runs."""

from __future__ import annotations

import html
import json

import numpy as np

from twin.compare.fields import element_series
from twin.compare.report import first_detail, first_line, render_text
from twin.report.charts import FieldRun, field_charts
from twin.report.views import events_chart, paths_charts, pictures_html

MAX_FIELDS = 4  # diverging fields drawn, in the order they diverge (the rest are in the table)
MAX_ROWS = 40  # event differences and list items shown; the rest are counted


def chart_html(spec: dict, css: str = "chart") -> str:
    """A chart's place in the page with its data beside it (assets/charts.js draws it)."""
    data = json.dumps(spec, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    title = html.escape(spec.get("title", ""))
    return (f'<div class="{css}" role="img" aria-label="{title}">'
            f'<script type="application/json">{data}</script></div>')


def onset_text(result) -> str:
    """"step N (t = T s)" of the first divergence, "" when the runs match."""
    d = result.first
    return "" if d is None else f"step {d.step} (t = {d.t_s:.3f} s)"


def changed_text(result) -> str:
    """What changed, in one line: the explanation's headline, else the first divergence."""
    if result.first is None:
        return ""
    if result.explanation is not None and result.explanation.headline:
        return result.explanation.headline
    return f"{first_line(result.first)}: {first_detail(result.first)}"


def field_runs(golden, candidate, result) -> list[FieldRun]:
    """The diverging frame fields (with a unit: physical ones), in the order they diverge."""
    diverged = sorted(
        (f for f in result.fields if f.first is not None and f.unit),
        key=lambda f: (f.first.step, f.name),
    )[:MAX_FIELDS]
    if not diverged:
        return []
    steps, t_ns, series = element_series(golden, candidate)
    by_name = {name: (a, b, err, elements) for name, a, b, err, elements in series}
    floor = result.floor
    out = []
    for f in diverged:
        a, b, err, elements = by_name[f.name]
        allowance = np.full(len(steps), f.tolerance, dtype=np.float64)
        if floor is not None:
            allowance = np.maximum(allowance, floor.at(f.name, steps))
        out.append(
            FieldRun(
                name=f.name,
                unit=f.unit,
                t_s=t_ns * 1e-9,
                golden=a.astype(np.float64),
                candidate=b.astype(np.float64),
                error=err,
                elements=elements,
                allowance=allowance,
                onset_step=f.first.step,
                onset_t_s=f.first.t_s,
            )
        )
    return out


def _more(shown: int, total: int) -> str:
    """ "and N more" under a list or table cut at `shown` rows ("" when it was not cut)."""
    return f"<p>and {total - shown} more</p>" if total > shown else ""


def _list(title: str, items: list[str]) -> str:
    if not items:
        return ""
    lis = "".join(f"<li>{html.escape(i)}</li>" for i in items[:MAX_ROWS])
    return f"<h4>{html.escape(title)}</h4><ul>{lis}</ul>{_more(MAX_ROWS, len(items))}"


def differences_html(result) -> str:
    """The configuration and task differences, the notes, and what else changed."""
    ex = result.explanation
    items = list(ex.configuration) if ex is not None else []
    items += [
        f"{k}: {a} -> {b}" for k, a, b in result.config_differences if f"{k}" not in " ".join(items)
    ]
    if ex is not None and ex.task_file_changed:
        items.append("the task file changed since the golden was recorded")
    items += [
        f"the task's identity at step {d.step}: {d.golden} -> {d.candidate}"
        for d in result.identity
    ]
    out = _list("configuration and task differences", items or ["none"])
    if ex is not None:
        out += _list("also changed", ([ex.shift.text()] if ex.shift else []) + ex.annotations)
    return out + _list("notes", result.notes)


def golden_section(golden, candidate, result, title: str, commands: list[str]) -> str:
    """The section of one differing golden (title: its path), commands: how to see it again."""
    dt_s = result.golden["dt_ns"] * 1e-9
    onset = result.first.step if result.first is not None else None
    parts = [
        f'<section class="differ"><h2>{html.escape(title)}</h2>',
        f'<p class="changed">{html.escape(changed_text(result))}</p>',
    ]
    if result.first is not None:
        parts.append(
            f"<p>first divergence: <b>{html.escape(first_line(result.first))}</b>: "
            f"{html.escape(first_detail(result.first))}</p>"
        )
    runs = field_runs(golden, candidate, result)
    if runs:
        parts.append("<h3>diverging fields</h3>")
    for r in runs:
        charts = "".join(chart_html(c) for c in field_charts(r))
        parts.append(
            f"<h4>{html.escape(r.name)} ({html.escape(r.unit.replace('|', ' | '))}), "
            f"diverges at step {r.onset_step}</h4><div class=grid2>{charts}</div>"
        )
    parts.append("<h3>paths from above</h3><div class=grid3>")
    parts += [chart_html(c, "chart square") for c in paths_charts(golden, candidate, onset)]
    parts.append("</div><h3>events</h3>")
    parts.append(
        chart_html(events_chart(golden, candidate, result.event_diffs, dt_s, onset), "chart wide")
    )
    parts.append(_event_table(result.event_diffs, dt_s))
    # what a camera sees changes where the frames first diverge (a command may differ earlier)
    seen = min(
        (f.first.step for f in result.fields if f.first is not None and f.unit), default=onset
    )
    parts.append(pictures_html(golden, candidate, seen))
    parts.append(differences_html(result))
    cmds = "\n".join(html.escape(c) for c in commands)
    parts.append(f"<h4>see it again</h4><pre>{cmds}</pre>")
    parts.append(
        f"<details><summary>the full text report</summary><pre>"
        f"{html.escape(render_text(result))}</pre></details></section>"
    )
    return "".join(parts)


def commands_for(golden_path: str, kept: list[str]) -> list[str]:
    """The commands that show a checked golden's difference again: from the files --keep wrote,
    or the check that keeps them."""
    rrd = next((k for k in kept if k.endswith(".rrd")), "")
    mcap = next((k for k in kept if k.endswith(".mcap")), "")
    if rrd and mcap:
        return [f"twin diff {golden_path} {mcap}", f"twin view --web {rrd}"]
    stem = golden_path.rsplit("/", 1)[-1].rsplit(".", 1)[0]
    return [
        f"twin check {golden_path} --keep kept",
        f"twin diff {golden_path} kept/{stem}.mcap",
        f"twin view --web kept/{stem}.rrd",
    ]


def _at(step: int | None, dt_s: float) -> str:
    return "" if step is None else f"{step} ({step * dt_s:.3f} s)"


def _event_table(diffs, dt_s: float) -> str:
    if not diffs:
        return "<p>no event moved, missing or extra</p>"
    rows = "".join(
        "<tr>"
        + "".join(
            f"<td>{html.escape(str(x))}</td>"
            for x in (
                d.kind,
                f"{d.event_kind} {d.body}".strip(),
                _at(d.expected_step, dt_s),
                _at(d.actual_step, dt_s),
            )
        )
        + "</tr>"
        for d in diffs[:MAX_ROWS]
    )
    return (
        "<table><tr><th>difference</th><th>event</th><th>golden step</th>"
        f"<th>candidate step</th></tr>{rows}</table>{_more(MAX_ROWS, len(diffs))}"
    )


def diff_entry(golden, candidate, result, name: str, commands: list[str]):
    """A compared pair (twin diff, twin replay) as a report Entry, with its section when the runs
    differ."""
    from twin.compare.report import headline
    from twin.record.machine import machine_text
    from twin.report.page import Entry

    status = "match" if result.match else "differ"
    section = "" if result.match else golden_section(golden, candidate, result, name, commands)
    recorded = machine_text(golden.machine) if golden.machine else ""
    return Entry(
        name=name,
        status=status,
        changed=headline(result),
        onset=onset_text(result),
        section=section,
        text=render_text(result),
        recorded_on=recorded,
    )
