"""The other views of a differing golden: the pad's and each object's path seen from above, both
runs' event timelines side by side (moved, missing and extra events marked), and the camera
pictures at the onset with their difference."""

from __future__ import annotations

import base64
import html

import numpy as np

from twin.report.charts import CANDIDATE, GOLDEN, numbers
from twin.report.thin import min_max

_MARKS = {"moved": "#ff7f0e", "missing": "#d62728", "extra": "#9467bd"}


def _xy(steps: np.ndarray, xy: np.ndarray) -> list[list]:
    """A path from above, thinned in time (each bucket keeps its extremes in x and in y)."""
    _, kept = min_max(steps.astype(np.float64), xy)
    return [numbers(kept[:, 0]), numbers(kept[:, 1])]


def paths_charts(golden, candidate, onset_step: int | None) -> list[dict]:
    """Top views (x, y in m) of the pad and each object both runs have, golden and candidate, with
    where each stood at the onset."""
    g, c = golden.frames, candidate.frames
    c_names = [o.name for o in candidate.config.objects]
    views = [("pad", g.pad_pose[:, :2], c.pad_pose[:, :2])]
    for i, o in enumerate(golden.config.objects):
        if o.name in c_names:
            j = c_names.index(o.name)
            views.append((o.name, g.object_poses[:, i, :2], c.object_poses[:, j, :2]))
    charts = []
    for name, gxy, cxy in views:
        marks = []
        if onset_step is not None:
            for xy, steps, color in ((gxy, g.step, GOLDEN), (cxy, c.step, CANDIDATE)):
                at = min(int(np.searchsorted(steps, onset_step)), len(steps) - 1)
                marks.append({"x": float(xy[at, 0]), "y": float(xy[at, 1]), "color": color})
        charts.append({
            "kind": "xy", "title": f"{name} from above", "x_label": "x (m)", "y_label": "y (m)",
            "series": [{"label": "golden", "color": GOLDEN, "xy": _xy(g.step, gxy)},
                       {"label": "candidate", "color": CANDIDATE, "dash": True,
                        "xy": _xy(c.step, cxy)}],
            "marks": marks, "onset_label": "" if onset_step is None else f"at step {onset_step}",
        })
    return charts


def events_chart(golden, candidate, diffs, dt_s: float, onset_step: int | None) -> dict:
    """Both runs' events on one time axis (golden above, candidate below), each labelled by kind;
    moved events joined, missing and extra ones marked on the run that has them."""
    def items(events):
        return [[e.step * dt_s, f"{e.kind} {e.body}".strip(), e.kind in ("phase", "log")]
                for e in events]

    marked = [{"kind": d.kind, "color": _MARKS.get(d.kind, "#000"),
               "golden": None if d.expected_step is None else d.expected_step * dt_s,
               "candidate": None if d.actual_step is None else d.actual_step * dt_s}
              for d in diffs]
    end = max([e.step for e in golden.events + candidate.events] + [1]) * dt_s
    return {"kind": "events", "title": "events: golden above, candidate below (moved, missing and "
            "extra marked)", "golden": items(golden.events), "candidate": items(candidate.events),
            "marked": marked, "end": end, "x_label": "simulated time (s)",
            "onset": None if onset_step is None else {"t": onset_step * dt_s,
                                                       "label": f"onset step {onset_step}"}}


def pictures_html(golden, candidate, onset_step: int | None) -> str:
    """Each camera both runs have: its pictures nearest the onset in each run and their absolute
    difference (brightened), as inline PNGs; "" when the files have none."""
    from twin.pictures import png_bytes, track_rgb

    if onset_step is None:
        return ""
    out = []
    for name, gt in golden.cameras.items():
        ct = candidate.cameras.get(name)
        if ct is None or not len(gt) or not len(ct):
            continue
        gi, ci = _nearest(gt.step, onset_step), _nearest(ct.step, onset_step)
        a, b = track_rgb(gt, gi), track_rgb(ct, ci)
        cells = [(f"golden, step {int(gt.step[gi])}", a),
                 (f"candidate, step {int(ct.step[ci])}", b)]
        if a.shape == b.shape:
            diff = np.abs(a.astype(np.int16) - b.astype(np.int16))
            peak = max(int(diff.max()), 1)
            cells.append((f"difference (x{255 / peak:.3g})",
                           (diff * (255.0 / peak)).clip(0, 255).astype(np.uint8)))
        imgs = "".join(
            f'<figure class="pic"><img alt="{html.escape(cap)}" src="data:image/png;base64,'
            f'{base64.b64encode(png_bytes(rgb)).decode()}"><figcaption>{html.escape(cap)}'
            "</figcaption></figure>"
            for cap, rgb in cells
        )
        out.append(f"<h4>camera {html.escape(name)} at the onset</h4><div class=pics>{imgs}</div>")
    return "".join(out)


def _nearest(steps: np.ndarray, step: int) -> int:
    i = int(np.searchsorted(steps, step))
    if i >= len(steps):
        return len(steps) - 1
    if i > 0 and step - steps[i - 1] <= steps[i] - step:
        return i - 1
    return i
