"""The diff view: golden and candidate in one Rerun recording, the candidate as a ghost, and the
error of every field over time, so a person can see where the two runs part.

Everything per step goes out with `send_columns` (one call per entity, whole runs at once).
"""

from __future__ import annotations

import os

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from twin.compare.fields import error_series
from twin.compare.report import render_markdown
from twin.compare.result import DiffResult
from twin.compare.tolerances import FIELDS
from twin.model.recording import Recording
from twin.record.outputs import check_output, partial_path
from twin.record.rerun.writer import finish_file
from twin.robot import kinematics

STEP, TIME = "step", "sim_time"
GHOST_ALPHA = 110
GOLDEN_ARM_RGBA = (70, 130, 230, 255)
CANDIDATE_RGBA = (255, 110, 60, GHOST_ALPHA)
DIVERGENCE_RGBA = (230, 30, 30, 255)


def _times(steps: np.ndarray, t_ns: np.ndarray) -> list[rr.TimeColumn]:
    return [
        rr.TimeColumn(STEP, sequence=np.asarray(steps, dtype=np.int64)),
        rr.TimeColumn(TIME, duration=np.asarray(t_ns, dtype=np.int64).astype("timedelta64[ns]")),
    ]


def arm_points(rec: Recording) -> np.ndarray:
    """(n, 5, 3): floor, shoulder, elbow, wrist axis, pad tip of every frame (a SCARA as a
    polyline)."""
    p, q, pad = rec.config.profile, rec.frames.joint_q, rec.frames.pad_pose
    n = len(rec.frames)
    elbow_xy, wrist_xy = kinematics.elbow_and_wrist_xy(p, q.T)  # in the profile's own frame
    elbow, wrist = np.stack(elbow_xy, axis=1), np.stack(wrist_xy, axis=1)
    out = np.zeros((n, 5, 3))
    out[:, 1, 2] = p.shoulder_height_m
    out[:, 2, :2], out[:, 2, 2] = elbow, p.elbow_height_m
    out[:, 3, :2], out[:, 3, 2] = wrist, p.elbow_height_m
    out[:, 4] = pad[:, :3]
    return out


def _log_run(stream: rr.RecordingStream, rec: Recording, root: str, ghost: bool) -> None:
    times = _times(rec.frames.step, rec.frames.t_ns)
    n = len(rec.frames)
    arm_rgba = CANDIDATE_RGBA if ghost else GOLDEN_ARM_RGBA
    stream.send_columns(
        f"{root}/arm",
        indexes=times,
        columns=rr.LineStrips3D.columns(
            strips=list(arm_points(rec)), colors=[arm_rgba] * n, radii=[0.008] * n
        ),
    )
    stream.send_columns(
        f"{root}/pad",
        indexes=times,
        columns=rr.Points3D.columns(
            positions=rec.frames.pad_pose[:, :3], radii=[0.02] * n, colors=[arm_rgba] * n
        ),
    )
    stream.log(
        f"{root}/pad_path",
        rr.LineStrips3D([rec.frames.pad_pose[:, :3]], colors=[arm_rgba], radii=[0.002]),
        static=True,
    )
    for k, obj in enumerate(rec.config.objects):
        path = f"{root}/objects/{obj.name}"
        rgba = CANDIDATE_RGBA if ghost else tuple(round(255 * c) for c in obj.rgba[:3]) + (255,)
        stream.log(
            path,
            rr.Boxes3D(
                half_sizes=[[s / 2 for s in obj.size_m]],
                colors=[rgba],
                fill_mode="solid" if not ghost else "majorwireframe",
            ),
            static=True,
        )
        poses = rec.frames.object_poses[:, k]
        stream.send_columns(
            path,
            indexes=times,
            columns=rr.Transform3D.columns(translation=poses[:, :3], quaternion=poses[:, 3:]),
        )
    if rec.events:
        steps = np.array([e.step for e in rec.events], dtype=np.int64)
        stream.send_columns(
            f"events/{root}",
            indexes=_times(steps, [e.t_ns for e in rec.events]),
            columns=rr.TextLog.columns(
                text=[f"{root}: {e.kind} {e.body} {e.message}".rstrip() for e in rec.events]
            ),
        )


def write_diff_rrd(
    golden: Recording, candidate: Recording, result: DiffResult, path: str | os.PathLike
) -> None:
    """Write the diff view to a .rrd file (through NAME.rrd.partial, put in place when complete)."""
    inputs = [p for p in (golden.path, candidate.path) if p and not p.startswith("<")]
    target = check_output(path, ".rrd", inputs=inputs, option="--rrd")
    partial = partial_path(target)
    stream = rr.RecordingStream("twin-diff")
    stream.save(partial, default_blueprint=_blueprint())
    stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    _log_run(stream, golden, "golden", ghost=False)
    _log_run(stream, candidate, "candidate", ghost=True)
    steps, t_ns, errors = error_series(golden, candidate)
    times = _times(steps, t_ns)
    for name, series in errors.items():
        unit = FIELDS[name][0]
        tol = result.tolerances[name]
        label = f"{name} [{unit}] (tolerance {tol:g})" if unit else f"{name} (differs = 1)"
        path = f"error/{_group(name)}/{name}"
        stream.log(path, rr.SeriesLines(names=label), static=True)
        stream.send_columns(path, indexes=times, columns=rr.Scalars.columns(scalars=series))
    stream.log(
        "report",
        rr.TextDocument(render_markdown(result), media_type=rr.MediaType.MARKDOWN),
        static=True,
    )
    first = result.first
    if first is not None:
        stream.send_columns(
            "events/first_divergence",
            indexes=_times([first.step], [round(first.t_s * 1e9)]),
            columns=rr.TextLog.columns(
                text=[f"FIRST DIVERGENCE {first.name} {first.element}".rstrip()], level=["ERROR"]
            ),
        )
        i = int(np.searchsorted(golden.frames.step, first.step).clip(0, len(golden.frames) - 1))
        stream.log(
            "golden/first_divergence",
            rr.Points3D(
                [golden.frames.pad_pose[i, :3]],
                radii=[0.03],
                colors=[DIVERGENCE_RGBA],
                labels=["first divergence"],
            ),
            static=True,
        )
    finish_file(stream, partial, target)


def _group(name: str) -> str:
    """Error plots by scale: poses (m, rad), dynamics (rad/s, N, N·m), discrete state (0/1)."""
    if name.startswith("suction."):
        return "state"
    if name in ("joints.velocity", "joints.effort") or name.startswith("hold."):
        return "dynamics"
    return "pose"


def _blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(
                name="golden (solid) vs candidate (ghost)",
                origin="/",
                contents=["/golden/**", "/candidate/**"],
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="pose error (m, rad)", origin="/error/pose"),
                rrb.TimeSeriesView(
                    name="dynamics error (rad/s, m/s, N, N·m)", origin="/error/dynamics"
                ),
                rrb.TimeSeriesView(name="suction state differs (1)", origin="/error/state"),
                rrb.Tabs(
                    rrb.TextDocumentView(name="report", origin="/report"),
                    rrb.TextLogView(name="events", origin="/events"),
                ),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
