"""The charts of a differing golden, as data for the page's chart script (assets/charts.js, which
draws them with uPlot): one diverging field over time (golden and candidate with the allowance
band around the golden; the error against the allowance; the whole run and around the onset), the
paths seen from above, and both runs' events. Long runs are thinned by thin.min_max."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.report.thin import min_max

ZOOM_STEPS = 60  # the zoom shows at least this many steps either side of the onset
MAX_ELEMENTS = 4  # joints or objects drawn per field: the ones that moved most
GOLDEN, CANDIDATE, ALLOWED = "#1f77b4", "#d62728", "rgba(44,160,44,0.22)"
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#8c564b", "#e377c2", "#17becf")
_AXES = "xyz"


@dataclass
class FieldRun:
    """One field of both runs on their common steps (twin.compare.fields.element_series)."""

    name: str
    unit: str  # FIELDS unit: m, rad, "rad|m" (joints: revolute | prismatic), N, "" (discrete)
    t_s: np.ndarray  # (n,)
    golden: np.ndarray  # (n, k, c)
    candidate: np.ndarray  # (n, k, c)
    error: np.ndarray  # (n, k), FIELDS units
    elements: list[str]
    allowance: np.ndarray  # (n,): the larger of the tolerance and the noise floor at each step
    onset_step: int
    onset_t_s: float


def numbers(a: np.ndarray) -> list:
    """Plain numbers for JSON, rounded to 6 significant digits of the largest (far below a pixel),
    None for nan or inf."""
    a = np.asarray(a, dtype=np.float64).ravel()
    finite = np.isfinite(a)
    top = np.abs(a[finite]).max() if finite.any() else 0.0
    digits = 5 - int(np.floor(np.log10(top))) if top > 0 else 0
    rounded = np.round(a, digits).tolist()
    if finite.all():
        return rounded
    return [v if ok else None for v, ok in zip(rounded, finite.tolist(), strict=True)]


def _milli(unit: str) -> tuple[float, str]:
    """How an error is drawn: m and rad in thousandths (the size of what goldens catch)."""
    parts = unit.split("|")
    if unit and all(p in ("m", "rad") for p in parts):
        return 1e3, "|".join("m" + p for p in parts)
    return 1.0, unit


def _chosen(run: FieldRun) -> list[int]:
    """The elements drawn: those whose error is not 0, the largest first, at most MAX_ELEMENTS."""
    worst = run.error.max(axis=0) if len(run.error) else np.zeros(len(run.elements))
    order = [int(k) for k in np.argsort(-worst, kind="stable") if worst[k] > 0]
    return order[:MAX_ELEMENTS] or [0]


def _traces(run: FieldRun, chosen: list[int]) -> list[tuple[str, int, np.ndarray, np.ndarray]]:
    """(label, element, golden (n,), candidate (n,)) per element and coordinate that moved; none
    for orientations (their error, an angle, says it)."""
    c = run.golden.shape[2]
    if c not in (1, 3):
        return []
    out = []
    for k in chosen:
        moved = np.abs(run.golden[:, k] - run.candidate[:, k]).max(axis=0) if len(run.t_s) else [0]
        for j in range(c):
            if c == 3 and moved[j] < 0.25 * max(moved):
                continue  # a coordinate that hardly moved: the others say it
            label = " ".join(x for x in (run.elements[k], _AXES[j] if c == 3 else "") if x)
            out.append((label or run.name, k, run.golden[:, k, j], run.candidate[:, k, j]))
    return out


def _window(run: FieldRun) -> slice:
    n = len(run.t_s)
    at = int(np.searchsorted(run.t_s, run.onset_t_s))
    half = max(ZOOM_STEPS, n // 40)
    return slice(max(0, at - half), min(n, at + half + 1))


def _chart(title: str, t: np.ndarray, columns: list[tuple[dict, np.ndarray]], run: FieldRun,
           y_label: str, bands: list[list]) -> dict:
    x, y = min_max(t, np.column_stack([c for _, c in columns]))
    series = [{**style, "values": numbers(y[:, i])} for i, (style, _) in enumerate(columns)]
    return {"kind": "time", "title": title, "x": numbers(x), "series": series, "bands": bands,
            "onset": {"t": run.onset_t_s, "label": f"onset step {run.onset_step}"},
            "y_label": y_label, "x_label": "simulated time (s)"}


def _values_chart(run: FieldRun, part: slice, traces, title: str) -> dict:
    columns, bands = [], []
    allowance = run.allowance[part]
    for label, k, g, c in traces:
        color = PALETTE[k % len(PALETTE)] if len(traces) > 1 else GOLDEN
        g, c = g[part], c[part]
        base = len(columns) + 1  # uPlot counts series from 1 (0 is x)
        columns += [
            ({"label": f"allowed {label} (upper)", "color": "transparent", "legend": False},
             g + allowance),
            ({"label": f"allowed {label} (lower)", "color": "transparent", "legend": False},
             g - allowance),
            ({"label": f"golden {label}", "color": color}, g),
            ({"label": f"candidate {label}", "color": CANDIDATE if len(traces) == 1 else color,
              "dash": True}, c),
        ]
        bands.append([base, base + 1, ALLOWED])
    return _chart(
        title=title,
        t=run.t_s[part],
        columns=columns,
        run=run,
        y_label=run.unit.replace("|", " | "),
        bands=bands,
    )


def _error_chart(run: FieldRun, part: slice, chosen: list[int], title: str) -> dict:
    scale, unit = _milli(run.unit)
    columns = [
        ({"label": "allowance", "color": "#2ca02c"}, run.allowance[part] * scale),
        ({"label": "zero", "color": "transparent", "legend": False}, np.zeros(len(run.t_s[part]))),
    ]
    for i, k in enumerate(chosen):
        columns.append(
            (
                {
                    "label": f"error {run.elements[k]}".strip(),
                    "color": PALETTE[(k if len(chosen) > 1 else 3) % len(PALETTE)],
                },
                run.error[part, k] * scale,
            )
        )
    return _chart(
        title=title,
        t=run.t_s[part],
        columns=columns,
        run=run,
        y_label=unit.replace("|", " | "),
        bands=[[1, 2, ALLOWED]],
    )


def field_charts(run: FieldRun) -> list[dict]:
    """Whole run and zoom side by side: the values (when they can be drawn), then the error."""
    chosen = _chosen(run)
    traces = _traces(run, chosen)
    whole, zoom = slice(None), _window(run)
    near = f"around the onset, step {run.onset_step} (t = {run.onset_t_s:.3f} s)"
    out = []
    if traces:
        out += [
            _values_chart(run, whole, traces, f"{run.name}: whole run"),
            _values_chart(run, zoom, traces, f"{run.name}: {near}"),
        ]
    out += [
        _error_chart(run, whole, chosen, f"{run.name} error: whole run"),
        _error_chart(run, zoom, chosen, f"{run.name} error: {near}"),
    ]
    return out
