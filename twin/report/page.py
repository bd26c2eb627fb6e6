"""The report as one self-contained HTML page (styles, plots and pictures inline: it opens from
the file system and as a CI artifact, and asks no host for anything) and the job summary in
Markdown (the table and the what-changed lines, no pictures) for GitHub's $GITHUB_STEP_SUMMARY."""

from __future__ import annotations

import html
import re
from dataclasses import dataclass
from functools import cache
from pathlib import Path

ASSETS = Path(__file__).resolve().parent / "assets"

SUMMARY_LIMIT_BYTES = 1024 * 1024  # GitHub takes at most 1 MiB of summary per step
PASSING = ("match", "updated")

_STYLE = """
body{font:14px/1.45 system-ui,sans-serif;margin:1.5em auto;max-width:1100px;color:#222;
padding:0 1em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:3px 8px;
text-align:left;vertical-align:top}th{background:#f2f2f2}.s-match,.s-updated{color:#1a7f37}
.s-differ,.s-refused,.s-error{color:#cf222e;font-weight:bold}section.differ{border-top:3px solid
#cf222e;margin-top:2em}p.changed{font-size:16px;font-weight:600}figure{margin:.5em 0}
figure.plot svg{max-width:100%;height:auto}.pics{display:flex;gap:1em;flex-wrap:wrap}
.pic img{image-rendering:pixelated;border:1px solid #ccc}pre{background:#f6f8fa;padding:.6em;
overflow-x:auto}.grid2{display:grid;grid-template-columns:1fr 1fr;gap:.5em 1em}
.grid3{display:grid;grid-template-columns:repeat(auto-fill,minmax(320px,1fr));gap:1em}
div.chart{min-height:120px}div.chart.wide{width:100%}.u-legend{font-size:11px}
.u-legend .u-series{padding:0 4px}.u-title{font-size:13px!important}
"""


@cache
def _scripts() -> str:
    """uPlot (its MIT licence kept in assets/uPlot.LICENSE) and the chart script, inline once."""
    css = (ASSETS / "uPlot.min.css").read_text()
    # its banner names the project's address; the page names no host, so it says who instead
    banner = "/*! uPlot 1.6.32, MIT licence, Copyright (c) 2022 Leon Sorokin */"
    uplot = re.sub(r"^/\*!.*?\*/", banner, (ASSETS / "uPlot.iife.min.js").read_text(), count=1)
    charts = (ASSETS / "charts.js").read_text()
    return f"<style>{css}</style><script>{uplot}</script><script>{charts}</script>"


@dataclass
class Entry:
    """One golden (or comparison) in the report."""

    name: str
    status: str  # match, differ, updated, refused, error
    changed: str  # what changed in one line (or how the runs stand, on a match)
    onset: str = ""  # "step N (t = T s)" of the first divergence
    section: str = ""  # its HTML section (a differing recording golden)
    text: str = ""  # its text report, shown when it has no section (sweep and search goldens)
    recorded_on: str = ""  # the machine the golden was recorded on

    @property
    def passed(self) -> bool:
        return self.status in PASSING


def entry_of(outcome) -> Entry:
    """A check's Outcome (twin.verify.check) as an Entry."""
    return Entry(
        name=outcome.path,
        status=outcome.status,
        changed=outcome.summary,
        onset=getattr(outcome, "onset", ""),
        section=getattr(outcome, "section", ""),
        text=outcome.report,
        recorded_on=getattr(outcome, "recorded_on", ""),
    )


def _cell(text: str) -> str:
    return f"<td>{html.escape(text)}</td>"


def _table(entries: list[Entry]) -> str:
    rows = "".join(
        f"<tr><td><a href='#g{i}'>{html.escape(e.name)}</a></td>"
        f"<td class='s-{e.status}'>{e.status}</td>"
        + _cell("pass" if e.passed else "FAIL")
        + _cell(e.onset)
        + _cell(e.changed)
        + "</tr>"
        for i, e in enumerate(entries)
    )
    return (
        "<table><tr><th>golden</th><th>status</th><th>verdict</th><th>onset</th>"
        f"<th>what changed</th></tr>{rows}</table>"
    )


def counts_line(entries: list[Entry]) -> str:
    """ "12 match, 1 differ" (or "every golden matched")."""
    statuses = ("match", "differ", "updated", "refused", "error")
    if entries and all(e.status == "match" for e in entries):
        return f"every golden matched ({len(entries)} of {len(entries)})"
    return (
        ", ".join(
            f"{sum(e.status == s for e in entries)} {s}"
            for s in statuses
            if any(e.status == s for e in entries)
        )
        or "nothing checked"
    )


def _machines(entries: list[Entry], checked_on: str) -> str:
    recorded = sorted({e.recorded_on for e in entries if e.recorded_on})
    lines = [f"<li>checked on: {html.escape(checked_on)}</li>"] if checked_on else []
    lines += [f"<li>recorded on: {html.escape(m)}</li>" for m in recorded]
    return f"<ul>{''.join(lines)}</ul>" if lines else ""


def _body(entries: list[Entry]) -> str:
    parts, matched = [], []
    for i, e in enumerate(entries):
        if e.section:
            parts.append(f"<div id='g{i}'>{e.section}</div>")
        elif not e.passed:
            parts.append(
                f"<div id='g{i}'><section class='differ'><h2>{html.escape(e.name)}</h2>"
                f"<p class='changed'>{html.escape(e.changed)}</p>"
                f"<pre>{html.escape(e.text)}</pre></section></div>"
            )
        else:
            matched.append(
                f"<li id='g{i}'>{html.escape(e.name)}: {e.status}, {html.escape(e.changed)}</li>"
            )
    if matched:
        parts.append(f"<h2>matching goldens</h2><ul class='matched'>{''.join(matched)}</ul>")
    return "".join(parts)


def render_page(entries: list[Entry], title: str, checked_on: str = "") -> str:
    """The whole page: the table, the machines, each differing golden's section, then one line per
    golden that matched."""
    return (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<title>{html.escape(title)}</title><style>{_STYLE}</style>"
        + (_scripts() if any(e.section for e in entries) else "")
        + "</head><body>"
        f"<h1>{html.escape(title)}: {html.escape(counts_line(entries))}</h1>"
        f"{_table(entries)}{_machines(entries, checked_on)}{_body(entries)}</body></html>\n"
    )


def _md(text: str) -> str:
    """Text in a Markdown table cell: pipes escaped, one line, no tag GitHub would take as HTML."""
    return text.replace("<", "&lt;").replace("|", "\\|").replace("\n", " ")


def _code(text: str) -> str:
    """Text in a code span of a table cell (taken literally there): pipes escaped, one line."""
    return text.replace("|", "\\|").replace("\n", " ").replace("`", "'")


def render_summary(entries: list[Entry], title: str) -> str:
    """The job summary: a heading with the counts, the table, and under 1 MiB (rows past what
    fits are counted, not listed)."""
    head = f"## {_md(title)}: {counts_line(entries)}\n\n"
    lines = ["| golden | status | verdict | onset | what changed |", "|---|---|---|---|---|"]
    size = len(head.encode()) + sum(len(x.encode()) + 1 for x in lines) + 200
    for n, e in enumerate(entries):
        row = (
            f"| `{_code(e.name)}` | {e.status} | {'pass' if e.passed else '**FAIL**'} | "
            f"{_md(e.onset)} | {_md(e.changed)} |"
        )
        size += len(row.encode()) + 1
        if size > SUMMARY_LIMIT_BYTES:
            lines.append(f"| ... and {len(entries) - n} more | | | | |")
            break
        lines.append(row)
    return head + "\n".join(lines) + "\n"
