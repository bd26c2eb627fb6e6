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


MAX_LOOKED_AT = 600  # picture pairs compared after the onset to find the first that differs


def _first_differing(gt, ct, step: int):
    """The indices (golden, candidate) of the first pair of pictures at one step, at or after
    `step`, that differ (within MAX_LOOKED_AT pairs), and their pixels; the pair nearest `step`
    when none does."""
    from twin.pictures import track_rgb

    gi = _nearest(gt.step, step)
    first = None
    for i in range(gi, min(len(gt), gi + MAX_LOOKED_AT)):
        j = _nearest(ct.step, int(gt.step[i]))
        if int(ct.step[j]) != int(gt.step[i]):
            continue
        a, b = track_rgb(gt, i), track_rgb(ct, j)
        first = first or (i, j, a, b)
        if a.shape != b.shape or not np.array_equal(a, b):
            return i, j, a, b
    if first is None:
        j = _nearest(ct.step, step)
        return gi, j, track_rgb(gt, gi), track_rgb(ct, j)
    return first


def pictures_html(golden, candidate, onset_step: int | None) -> str:
    """Each camera both runs have: the first pictures at or after onset_step that differ between
    the runs (the ones at the onset when none does), and their absolute difference (brightened),
    as inline PNGs; "" when the files have none."""
    from twin.pictures import png_bytes

    if onset_step is None:
        return ""
    out = []
    for name, gt in golden.cameras.items():
        ct = candidate.cameras.get(name)
        if ct is None or not len(gt) or not len(ct):
            continue
        gi, ci, a, b = _first_differing(gt, ct, onset_step)
        cells = [(f"golden, step {int(gt.step[gi])}", a),
                 (f"candidate, step {int(ct.step[ci])}", b)]
        if a.shape == b.shape:
            diff = np.abs(a.astype(np.int16) - b.astype(np.int16))
            peak = int(diff.max())
            what = (f"difference (brightened x{255 / peak:.3g})" if peak
                    else "difference: none, the pictures are the same")
            cells.append((what, (diff * (255.0 / max(peak, 1))).clip(0, 255).astype(np.uint8)))
        imgs = "".join(
            f'<figure class="pic"><img alt="{html.escape(cap)}" src="data:image/png;base64,'
            f'{base64.b64encode(png_bytes(rgb)).decode()}"><figcaption>{html.escape(cap)}'
            "</figcaption></figure>"
            for cap, rgb in cells
        )
        out.append(f"<h4>camera {html.escape(name)}: the first pictures after the onset (step "
                   f"{onset_step}) that differ</h4><div class=pics>{imgs}</div>")
    return "".join(out)


def _nearest(steps: np.ndarray, step: int) -> int:
    i = int(np.searchsorted(steps, step))
    if i >= len(steps):
        return len(steps) - 1
    if i > 0 and step - steps[i - 1] <= steps[i] - step:
        return i - 1
    return i
