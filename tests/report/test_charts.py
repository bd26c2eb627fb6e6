"""A diverging field of a 10-minute run as chart data: every chart stays within its thinning
budget (so the page's size does not grow with the run), keeps the field's extremes, and marks the
onset; the allowance band is drawn around the golden."""

from __future__ import annotations

import json

import numpy as np

from twin.report.charts import FieldRun, field_charts
from twin.report.thin import BUCKETS


def _run(n: int) -> FieldRun:
    t = np.arange(n) / 240.0
    golden = np.stack([np.sin(t / (k + 1)) for k in range(4)], axis=1)[:, :, None]
    candidate = golden.copy()
    onset = n // 3
    candidate[onset:, 1, 0] += 2e-3  # one joint off by 2 mrad from the onset on
    candidate[n // 2, 2, 0] += 0.5  # and one sample of another far off
    error = np.abs(golden - candidate)[:, :, 0]
    return FieldRun("joints.position", "rad|m", t, golden, candidate, error,
                    ["j1", "j2", "j3", "j4"], np.full(n, 2.5e-4), onset, float(t[onset]))


def test_a_10_minute_field_stays_small_and_keeps_its_extremes():
    run = _run(600 * 240)
    charts = field_charts(run)
    assert [c["title"].split(":")[0] for c in charts] == [
        "joints.position", "joints.position", "joints.position error", "joints.position error"]
    size = len(json.dumps(charts, separators=(",", ":")))
    assert size < 300_000, size  # four charts of a 144,000-step field
    for c in charts:
        assert len(c["x"]) <= 2 * BUCKETS
        assert c["onset"]["label"] == f"onset step {run.onset_step}"
    whole_error = charts[2]
    by_label = {s["label"]: s["values"] for s in whole_error["series"]}
    assert max(by_label["error j3"]) == 500.0  # the one far sample, in mrad, survives thinning
    assert abs(max(by_label["error j2"]) - 2.0) < 1e-6
    values = charts[0]
    bands = values["bands"]
    assert bands and all(color.startswith("rgba(") for _, _, color in bands)
    upper = values["series"][bands[0][0] - 1]  # uPlot counts series from 1
    assert upper["legend"] is False and upper["label"].startswith("allowed ")


def test_the_zoom_is_around_the_onset():
    run = _run(20_000)
    zoom = field_charts(run)[1]
    assert zoom["x"][0] < run.onset_t_s < zoom["x"][-1]
    assert zoom["x"][-1] - zoom["x"][0] < 0.1 * run.t_s[-1]
