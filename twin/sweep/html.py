"""`twin sweep compare --html`: the comparison as one self-contained page of the report
(twin.report.page): the verdict, the flips table, the paired interval and McNemar's p, the
definitions' differences, and the success map (sweep.plot's picture, inline) when matplotlib is
installed."""

from __future__ import annotations

import base64
import html
import tempfile
from pathlib import Path

from twin.model.errors import ConfigError
from twin.report.output import write_page
from twin.report.page import Entry, render_page

_FLIP_HEAD = ("scenario", "flip", "values", "before", "now", "placement before (mm)",
              "placement now (mm)")


def _flips_table(p) -> str:
    flips = [("ok -> failed", f) for f in p.worse_flips] + [("failed -> ok", f)
                                                            for f in p.better_flips]
    if not flips:
        return "<p>no scenario flipped</p>"
    head = "".join(f"<th>{h}</th>" for h in _FLIP_HEAD)
    rows = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in (
            f.scenario, kind, ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                                        for k, v in f.values.items()),
            f.reason_before, f.reason_now, _mm(f.placement_before_mm),
            _mm(f.placement_now_mm))) + "</tr>"
        for kind, f in flips)
    more = p.worse + p.better - len(flips)
    tail = f"<p>and {more} more flips (counted, not listed)</p>" if more > 0 else ""
    return f"<table><tr>{head}</tr>{rows}</table>{tail}"


def _mm(x: float | None) -> str:
    return "" if x is None else f"{x:.3f}"


def _interval(p) -> str:
    lo, hi = p.interval
    return (f"<p>success rate {p.reference_rate:.1%} -> {p.new_rate:.1%} over {p.n} scenarios "
            f"(difference {p.difference:+.1%}, Newcombe's paired 95 % interval "
            f"[{lo:+.1%}, {hi:+.1%}], McNemar's exact p = {p.mcnemar_p:.3g})</p>")


def _success_map(new, reference, paired, title: str) -> str:
    """sweep.plot's picture of the new sweep (flips ringed), inline; a line saying why not."""
    from twin.sweep.plot import plot_sweep

    with tempfile.TemporaryDirectory() as folder:
        png = Path(folder) / "map.png"
        try:
            plot_sweep(new, str(png), title, paired, reference)
        except ConfigError as err:
            return f"<p>no success map: {html.escape(str(err))}</p>"
        data = base64.b64encode(png.read_bytes()).decode()
    return (f'<figure><img alt="success map" style="max-width:100%" '
            f'src="data:image/png;base64,{data}"><figcaption>each scenario over the two varied '
            "keys that matter most: ok dots, failed crosses, flips ringed</figcaption></figure>")


def write_compare_page(comparison, path: str) -> None:
    """The page of `twin sweep compare A B --html FILE.html`."""
    name = f"{comparison.new.label} against {comparison.reference.label}"
    verdict = ("worse: " + "; ".join(comparison.problems) if comparison.problems
               else "not worse beyond sampling noise")
    body = [(f"<section class='{'differ' if comparison.problems else 'same'}'>"
            f"<h2>{html.escape(name)}</h2><p class='changed'>{html.escape(verdict)}</p>")]
    if comparison.is_paired:
        body += ["<h3>flips</h3>", _flips_table(comparison.result), _interval(comparison.result)]
    diffs = comparison.differences or ["none"]
    body.append("<h3>definitions differ in</h3><ul>"
                + "".join(f"<li>{html.escape(d)}</li>" for d in diffs) + "</ul>")
    paired = comparison.result if comparison.is_paired else None
    success = _success_map(comparison.new.side, comparison.reference.side, paired, name)
    body += ["<h3>success map</h3>", success,
             (f"<details><summary>the text report</summary><pre>"
             f"{html.escape(comparison.text())}</pre></details></section>")]
    entry = Entry(name, "differ" if comparison.problems else "match", verdict,
                  section="".join(body), text=comparison.text())
    write_page(path, render_page([entry], "twin sweep compare"))


def golden_section(definition: str, summary: str, p, new, reference, report: str) -> str:
    """A paired sweep golden that differs, in twin check's page: what failed, the flips, the
    interval and p, and the success map of the new run (p: paired.Paired of new against the
    golden's results)."""
    return (f"<section class='differ'><h2>{html.escape(definition)}</h2>"
            f"<p class='changed'>{html.escape(summary)}</p><h3>flips</h3>{_flips_table(p)}"
            f"{_interval(p)}<h3>success map</h3>"
            f"{_success_map(new, reference, p, f'{definition}: the new run against its golden')}"
            f"<details><summary>the text report</summary><pre>{html.escape(report)}</pre>"
            "</details></section>")
