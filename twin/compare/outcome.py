"""The outcome of the runs, judged on the result alone: their length, the objects' final poses,
the task's outcome, how often the counted events happened, and the camera pictures."""

from __future__ import annotations

import numpy as np

from twin.compare.fields import common_objects
from twin.compare.metrics import quat_angle
from twin.compare.result import Divergence, FieldStat, FinalPose, values
from twin.compare.tolerances import COUNTED_EVENTS, FIELDS, INF
from twin.model.recording import Recording
from twin.pictures import track_rgb


def length_stat(length: tuple[int, int], tolerance: float, dt_ns: int) -> FieldStat:
    diff = abs(length[0] - length[1])
    stat = FieldStat(
        name="run.length",
        unit="steps",
        tolerance=tolerance,
        worst=float(diff),
        worst_step=min(length),
        worst_element="",
        rms=float(diff),
        steps_over=int(diff > tolerance),
    )
    if diff > tolerance:
        step = min(length) + 1
        stat.first = Divergence(
            step=step,
            t_s=step * dt_ns * 1e-9,
            channel="run",
            field="length",
            element="",
            expected=[length[0]],
            actual=[length[1]],
            difference=float(diff),
            tolerance=tolerance,
            unit="steps",
        )
    return stat


def final_poses(
    golden: Recording, candidate: Recording, tol: dict[str, float]
) -> list[FinalPose]:
    """The last pose of each object both runs have, judged with tol (final.*)."""
    names, g_obj, c_obj = common_objects(golden, candidate)
    g, c = golden.frames.object_poses[-1][g_obj], candidate.frames.object_poses[-1][c_obj]
    dist = np.linalg.norm(g[:, :3] - c[:, :3], axis=-1)
    ang = quat_angle(g[:, 3:], c[:, 3:])
    out = []
    for k, name in enumerate(names):
        ok = True
        for key, err, a, b in (
            ("final.position", dist[k], g[k, :3], c[k, :3]),
            ("final.orientation", ang[k], g[k, 3:], c[k, 3:]),
        ):
            t = tol[key]
            ok &= bool(np.array_equal(a, b) if t == 0 else err <= t)
        pose = FinalPose(
            name=name,
            expected=values(g[k]),
            actual=values(c[k]),
            distance_m=float(dist[k]),
            angle_rad=float(ang[k]),
            ok=ok,
        )
        out.append(pose)
    return out


def final_stats(
    finals: list[FinalPose], tol: dict[str, float], last_step: int, dt_ns: int
) -> list[FieldStat]:
    stats = []
    for name, attr, part in (
        ("final.position", "distance_m", slice(0, 3)),
        ("final.orientation", "angle_rad", slice(3, 7)),
    ):
        t = tol[name]
        errs = [getattr(f, attr) for f in finals]
        worst_k = int(np.argmax(errs)) if errs else 0
        # "not <=" so that a NaN error counts as bad, as it does in final_poses
        bad = [
            f
            for f in finals
            if (f.expected[part] != f.actual[part] if t == 0 else not getattr(f, attr) <= t)
        ]
        stat = FieldStat(
            name=name,
            unit=FIELDS[name][0],
            tolerance=t,
            worst=errs[worst_k] if errs else 0.0,
            worst_step=last_step,
            worst_element=finals[worst_k].name if finals else "",
            rms=float(np.sqrt(np.mean(np.square(errs)))) if errs else 0.0,
            steps_over=len(bad),
        )
        if bad:
            f = bad[0]
            stat.first = Divergence(
                step=last_step,
                t_s=last_step * dt_ns * 1e-9,
                channel="final",
                field=name.split(".")[1],
                element=f.name,
                expected=f.expected[part],
                actual=f.actual[part],
                difference=getattr(f, attr),
                tolerance=t,
                unit=FIELDS[name][0],
            )
        stats.append(stat)
    return stats


def task_stat(
    golden: Recording, candidate: Recording, tolerance: float, last_step: int, dt_ns: int
) -> FieldStat:
    a, b = golden.outcome, candidate.outcome
    stat = FieldStat(
        name="outcome.task",
        unit="",
        tolerance=tolerance,
        worst=float(a != b),
        worst_step=last_step,
        worst_element="",
        rms=float(a != b),
        steps_over=int(a != b and tolerance != INF),
    )
    if a != b and tolerance != INF:
        stat.first = Divergence(
            step=last_step,
            t_s=last_step * dt_ns * 1e-9,
            channel="outcome",
            field="task",
            element="",
            expected=[a],
            actual=[b],
            difference=1.0,
            tolerance=tolerance,
            unit="",
        )
    return stat


def count_stats(
    g: list, c: list, tol: dict[str, float], last_step: int, dt_ns: int
) -> list[FieldStat]:
    stats = []
    for kind in COUNTED_EVENTS:
        name = f"counts.{kind}"
        a, b = sum(e.kind == kind for e in g), sum(e.kind == kind for e in c)
        t = tol[name]
        over = not abs(a - b) <= t
        stat = FieldStat(
            name=name,
            unit="events",
            tolerance=t,
            worst=float(abs(a - b)),
            worst_step=last_step,
            worst_element="",
            rms=float(abs(a - b)),
            steps_over=int(over),
        )
        if over:
            stat.first = Divergence(
                step=last_step,
                t_s=last_step * dt_ns * 1e-9,
                channel="counts",
                field=kind,
                element="",
                expected=[a],
                actual=[b],
                difference=float(abs(a - b)),
                tolerance=t,
                unit="events",
            )
        stats.append(stat)
    return stats


def image_stat(golden: Recording, candidate: Recording, tolerance: float, dt_ns: int) -> FieldStat:
    """Each camera's pictures, paired by step: the mean absolute difference of their pixels (levels
    0..255), inf for a picture only one run has. Identical bytes are 0 without decoding; others are
    decoded by the codec (twin.pictures.track_rgb). Not looked at when the tolerance is inf."""
    unit = FIELDS["images.pixels"][0]
    if tolerance == INF:
        return FieldStat.nothing("images.pixels", unit, tolerance)
    names = list(
        dict.fromkeys(
            [c.name for c in golden.config.cameras] + [c.name for c in candidate.config.cameras]
        )
    )
    # (step, "camera #index", error, golden's, candidate's)
    rows: list[tuple[int, str, float, str, str]] = []
    for name in names:
        g, c = golden.cameras.get(name), candidate.cameras.get(name)
        g_steps = g.step if g is not None else np.zeros(0, dtype=np.int64)
        c_steps = c.step if c is not None else np.zeros(0, dtype=np.int64)
        _, gi, ci = np.intersect1d(g_steps, c_steps, assume_unique=True, return_indices=True)
        for i, j in zip(gi.tolist(), ci.tolist(), strict=True):
            rows.append(
                (int(g_steps[i]), f"{name} #{i}", _picture_error(g, i, c, j), "picture", "picture")
            )
        for steps, which, sides in (
            (g_steps, gi, ("picture", "missing")),
            (c_steps, ci, ("missing", "picture")),
        ):
            missing = np.setdiff1d(np.arange(len(steps)), which)
            rows += [(int(steps[k]), f"{name} #{k}", INF, *sides) for k in missing.tolist()]
    if not rows:
        return FieldStat.nothing("images.pixels", unit, tolerance)
    rows.sort(key=lambda r: r[0])
    errors = np.array([r[2] for r in rows])
    worst = int(np.argmax(errors))
    over = [r for r in rows if not r[2] <= tolerance]
    stat = FieldStat(
        name="images.pixels",
        unit=unit,
        tolerance=tolerance,
        worst=float(errors[worst]),
        worst_step=rows[worst][0],
        worst_element=rows[worst][1],
        rms=float(np.sqrt(np.mean(np.square(errors)))),
        steps_over=len(over),
    )
    if over:
        step, element, err, expected, actual = over[0]
        stat.first = Divergence(
            step=step,
            t_s=step * dt_ns * 1e-9,
            channel="images",
            field="pixels",
            element=element,
            expected=[expected],
            actual=[actual],
            difference=err,
            tolerance=tolerance,
            unit=unit,
        )
    return stat


def _picture_error(g, i: int, c, j: int) -> float:
    """Mean absolute pixel difference of picture i of track g and picture j of track c (inf: other
    sizes)."""
    if g.data[i] == c.data[j]:
        return 0.0
    a, b = track_rgb(g, i), track_rgb(c, j)
    if a.shape != b.shape:
        return INF
    return float(np.mean(np.abs(a.astype(np.int16) - b.astype(np.int16))))
