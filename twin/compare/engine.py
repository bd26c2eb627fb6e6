"""The diff engine: compare a candidate run with a golden one, field by field, in physical units.

Frames are aligned by step number (so a decimated golden compares with a full candidate); angles
are wrapped; orientations compare by the angle between quaternions; events pair by kind and body,
in order, within a window of steps. Commands (every input, kept at every step whatever the frame
rate) compare exactly, so a divergence between the kept frames of a decimated file still shows.
The outcome fields judge the result alone: the task ended ok, and how often the pad took and let go.
Everything is numpy over whole columns: no per-frame Python.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from twin.compare.allowances import Allowances
from twin.compare.events import EventDiff, match_events
from twin.compare.identity import IdentityDifference, identity_notes, set_identity_apart
from twin.compare.metrics import (
    REVOLUTE,
    abs_error,
    differs,
    discrete_error,
    joint_error,
    norm_error,
    quat_angle,
)
from twin.compare.noise import NoiseFloor, command_number_difference
from twin.compare.tolerances import COUNTED_EVENTS, FIELDS, INF, Tolerances
from twin.model.errors import RecordingError, TwinError
from twin.model.fields import COMPARED
from twin.model.recording import Recording
from twin.model.types import Command
from twin.pictures import track_rgb

if TYPE_CHECKING:
    from twin.compare.explain import Explanation


class NotComparable(TwinError):
    """The two runs differ in structure (joints by role, time step, scene objects)."""

    exit_code = 3


@dataclass
class Divergence:
    """Where the candidate first leaves the golden, in one field of one element."""

    step: int
    t_s: float
    channel: str
    field: str
    element: str
    expected: list
    actual: list
    difference: float
    tolerance: float
    unit: str
    # the measured noise floor there (times its margin); 0 when none was measured
    floor: float = 0.0

    @property
    def name(self) -> str:
        return f"{self.channel}.{self.field}"


@dataclass
class FieldStat:
    name: str
    unit: str
    tolerance: float
    worst: float  # largest error over steps and elements
    worst_step: int
    worst_element: str
    rms: float
    steps_over: int  # steps where some element is over tolerance
    first: Divergence | None = None
    # the largest noise floor allowed (times its margin); 0 when none was measured
    floor: float = 0.0
    identical: bool = False  # every value bit for bit the same

    @property
    def ok(self) -> bool:
        return self.first is None

    @classmethod
    def nothing(
        cls, name: str, unit: str, tolerance: float, identical: bool = False
    ) -> FieldStat:
        """A field with nothing to compare: no error, at no step."""
        return cls(
            name=name,
            unit=unit,
            tolerance=tolerance,
            worst=0.0,
            worst_step=-1,
            worst_element="",
            rms=0.0,
            steps_over=0,
            identical=identical,
        )


@dataclass
class FinalPose:
    name: str
    expected: list
    actual: list
    distance_m: float
    angle_rad: float
    ok: bool


@dataclass
class DiffResult:
    golden: dict  # run_summary(): path, profile, run, frames
    candidate: dict
    tolerances: Tolerances
    fields: list[FieldStat]
    events_matched: int
    events_shifted: int  # matched, but at another step inside the window
    event_diffs: list[EventDiff]
    final_poses: list[FinalPose]
    length: tuple[int, int]  # last step of golden, candidate
    steps_compared: int
    config_differences: list[tuple[str, str, str]]
    notes: list[str] = field(default_factory=list)
    first: Divergence | None = None
    first_command: Divergence | None = None  # the first difference in the command sequences
    # the first difference in what the tasks said (event Commands)
    first_annotation: Divergence | None = None
    # the golden's last command at or before the first divergence acting on its field
    likely_cause: str = ""
    # False: the tolerances pair no events (outcome); counts still compare
    events_compared: bool = True
    floor: NoiseFloor | None = None  # the candidate's measured noise floor (the `noise` preset)
    # what changed, read from both runs (twin.compare.explain; None until explained)
    explanation: Explanation | None = None
    identity: list[IdentityDifference] = field(default_factory=list)  # task_start's, apart

    @property
    def match(self) -> bool:
        return self.first is None

    @property
    def exit_code(self) -> int:
        return 0 if self.match else 1

    def to_dict(self) -> dict:
        def clean(x):
            if isinstance(x, float) and not math.isfinite(x):
                return str(x)
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, list | tuple):
                return [clean(v) for v in x]
            return x

        out = asdict(self)
        out["tolerances"] = self.tolerances.to_dict()
        out["floor"] = self.floor.to_dict() if self.floor is not None else None
        out["match"] = self.match
        return clean(out)


def values(x: np.ndarray) -> list:
    """A numpy row as plain Python numbers."""
    return [v.item() for v in x]


# a joint field's unit for a revolute joint, and for the prismatic Z joint ("rad|m" in model.fields)
JOINT_UNITS = {c.name: tuple(c.unit.split("|")) for f, c in COMPARED if f.shape == "joint"}


# field -> (column, component slice, metric, element kind), from model.fields
_METRICS = {"joint": joint_error, "abs": abs_error, "discrete": discrete_error, "norm": norm_error,
            "angle": quat_angle}
_SPECS = {
    c.name: (
        f.name,
        c.components,
        _METRICS[c.metric],
        {"joint": "joint", "object_pose": "object"}.get(f.shape, ""),
    )
    for f, c in COMPARED
}


def _shaped(column: np.ndarray, components: slice | None, kind: str) -> np.ndarray:
    """Any column -> (n, elements, components)."""
    if column.ndim == 1:
        return column[:, None, None]
    if kind == "joint":
        return column[:, :, None]
    if column.ndim == 2:
        return column[:, None, components or slice(None)]
    return column[:, :, components]


def frame_stats(
    golden: Recording, candidate: Recording, gi: np.ndarray, ci: np.ndarray, allow: Allowances
) -> list[FieldStat]:
    """Every frame field on the aligned steps (golden gi, candidate ci), judged with allow."""
    steps, t_ns = golden.frames.step[gi], golden.frames.t_ns[gi]
    stats = []
    for name, a, b, metric, elements in _field_arrays(golden, candidate, gi, ci):
        tolerance, floor = allow.frame(name, steps)
        stats.append(
            _field_stat(
                name=name,
                a=a,
                b=b,
                metric=metric,
                elements=elements,
                tolerance=tolerance,
                steps=steps,
                t_ns=t_ns,
                floor=floor,
            )
        )
    return stats


def common_objects(
    golden: Recording, candidate: Recording
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Object names both runs have (golden order) and their indices in each run."""
    g_names = [o.name for o in golden.config.objects]
    c_names = [o.name for o in candidate.config.objects]
    common = [n for n in g_names if n in c_names]
    return (
        common,
        np.array([g_names.index(n) for n in common], dtype=np.int64),
        np.array([c_names.index(n) for n in common], dtype=np.int64),
    )


def _field_arrays(golden: Recording, candidate: Recording, gi: np.ndarray, ci: np.ndarray):
    """Per field: (name, golden (n, k, c), candidate (n, k, c), metric, element names) on aligned
    steps."""
    g, c = golden.frames, candidate.frames
    common, g_obj, c_obj = common_objects(golden, candidate)
    g_names = [o.name for o in golden.config.objects]
    c_names = [o.name for o in candidate.config.objects]
    joint_names = list(golden.config.profile.joint_names)
    for name, (column, comp, metric, kind) in _SPECS.items():
        a, b = getattr(g, column)[gi], getattr(c, column)[ci]
        if kind == "object":
            a, b = a[:, g_obj], b[:, c_obj]
        elif column in ("sensed_body", "held_body"):
            b = _remap_bodies(b, c_names, g_names)
        elements = joint_names if kind == "joint" else common if kind == "object" else [""]
        yield name, _shaped(a, comp, kind), _shaped(b, comp, kind), metric, elements


def error_series(
    golden: Recording, candidate: Recording
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """On the steps both runs have: (steps, t_ns, {field: largest error over its elements}), FIELDS
    units."""
    gi, ci = align(golden.frames.step, candidate.frames.step)
    out = {}
    for name, a, b, metric, _elements in _field_arrays(golden, candidate, gi, ci):
        err = metric(a, b)
        out[name] = err.max(axis=1) if err.shape[1] else np.zeros(err.shape[0])
    return golden.frames.step[gi], golden.frames.t_ns[gi], out


def align(g_steps: np.ndarray, c_steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the steps both runs have, in step order."""
    n = min(len(g_steps), len(c_steps))
    if np.array_equal(g_steps[:n], c_steps[:n]):
        idx = np.arange(n)
        return idx, idx
    _, gi, ci = np.intersect1d(g_steps, c_steps, assume_unique=True, return_indices=True)
    return gi, ci


def _remap_bodies(b: np.ndarray, c_names: list[str], g_names: list[str]) -> np.ndarray:
    """Candidate object indices -> golden indices (by name); -2 for objects the golden lacks."""
    table = np.array(
        [g_names.index(n) if n in g_names else -2 for n in c_names] + [-1], dtype=np.int64
    )
    return table[b]  # index -1 (no body) reads the table's last entry, -1


def _field_stat(
    *,
    name: str,
    a: np.ndarray,
    b: np.ndarray,
    metric,
    elements: list[str],
    tolerance: float,
    steps: np.ndarray,
    t_ns: np.ndarray,
    floor: np.ndarray | None = None,
) -> FieldStat:
    """One field over the aligned steps; floor: the noise floor per step (allowed where above
    tolerance)."""
    unit = FIELDS[name][0]
    n = a.shape[0]
    if n == 0 or a.shape[1] == 0:
        return FieldStat.nothing(name, unit, tolerance, identical=True)
    err = metric(a, b)
    bits = differs(a, b)
    if floor is not None and tolerance != INF:
        over = ~(err <= np.maximum(tolerance, floor)[:, None])
    elif tolerance == 0:
        over = bits
    else:
        over = ~(err <= tolerance)
    over_steps = over.any(axis=1)
    finite = np.where(np.isnan(err), INF, err)
    flat = int(np.argmax(finite))
    w_i, w_k = divmod(flat, finite.shape[1])
    stat = FieldStat(
        name=name,
        unit=unit,
        tolerance=tolerance,
        worst=float(finite[w_i, w_k]),
        worst_step=int(steps[w_i]),
        worst_element=elements[w_k],
        rms=float(np.sqrt(np.mean(np.square(finite)))),
        steps_over=int(over_steps.sum()),
        floor=float(floor.max()) if floor is not None and len(floor) else 0.0,
        identical=not bool(bits.any()),
    )
    if stat.steps_over and tolerance != INF:
        i = int(np.argmax(over_steps))
        k = int(np.argmax(over[i]))
        channel, fld = name.split(".")
        if channel == "joints":
            unit = JOINT_UNITS[name][0 if REVOLUTE[k] else 1]
        stat.first = Divergence(
            step=int(steps[i]),
            t_s=int(t_ns[i]) * 1e-9,
            channel=channel,
            field=fld,
            element=elements[k],
            expected=values(a[i, k]),
            actual=values(b[i, k]),
            difference=float(err[i, k]),
            tolerance=tolerance,
            unit=unit,
            floor=float(floor[i]) if floor is not None else 0.0,
        )
    elif tolerance == INF:
        stat.steps_over = 0
    return stat


def _command_text(c: Command) -> str:
    args = ", ".join(f"{k}={v!r}" for k, v in sorted(c.args.items()))
    return f"step {c.step} {c.kind}({args})"


def _split_annotations(commands: list[Command]) -> tuple[list[Command], list[Command]]:
    """(commands that act, annotations): an `event` Command acts on nothing, so the two sequences
    are paired apart and an extra annotation does not shift the pairing of the commands that act."""
    return [c for c in commands if c.kind != "event"], [c for c in commands if c.kind == "event"]


def command_stats(
    golden: Recording, candidate: Recording, allow: Allowances, dt_ns: int
) -> tuple[list[FieldStat], list[IdentityDifference]]:
    """The commands that act (commands.sequence) and the annotations (commands.annotations), each
    paired apart; and the task identities set apart from the annotations (twin.compare.identity)."""
    g_acts, g_said = _split_annotations(golden.commands)
    c_acts, c_said = _split_annotations(candidate.commands)
    said, identities = set_identity_apart(g_said, c_said, allow.identity_judged)
    stats = [
        _command_stat(
            g=g, c=c, name=name, tolerance=t, dt_ns=dt_ns, until_step=allow.commands_until
        )
        for name, g, c, t in (
            ("commands.sequence", g_acts, c_acts, allow.commands),
            ("commands.annotations", g_said, said, allow.annotations),
        )
    ]
    return stats, identities


def _command_stat(
    *,
    g: list[Command],
    c: list[Command],
    name: str,
    tolerance: float,
    dt_ns: int,
    until_step: int | None,
) -> FieldStat:
    """Two command sequences, entry by entry: step, kind and text exactly, the numbers in their
    arguments within tolerance (0: equal; inf: the field is off); entries from until_step on are not
    judged."""
    if until_step is not None:
        g, c = [x for x in g if x.step < until_step], [x for x in c if x.step < until_step]
    n = max(len(g), len(c))
    differing = [
        i
        for i in range(n)
        if i >= len(g) or i >= len(c) or not _commands_agree(g[i], c[i], tolerance)
    ]
    first_i = differing[0] if differing else -1
    step = -1 if first_i < 0 else min(x[first_i].step for x in (g, c) if first_i < len(x))
    stat = FieldStat(
        name=name,
        unit="",
        tolerance=tolerance,
        worst=float(len(differing)),
        worst_step=step,
        worst_element="",
        rms=float(len(differing)),
        steps_over=len(differing) if tolerance != INF else 0,
    )
    if differing and tolerance != INF:
        expected = [_command_text(g[first_i]) if first_i < len(g) else None]
        actual = [_command_text(c[first_i]) if first_i < len(c) else None]
        command = g[first_i] if first_i < len(g) else c[first_i]
        kind = command.args.get("kind", "event") if command.kind == "event" else command.kind
        stat.first = Divergence(
            step=step,
            t_s=step * dt_ns * 1e-9,
            channel="commands",
            field=name.split(".")[1],
            element=f"#{first_i} {kind}",
            expected=expected,
            actual=actual,
            difference=float(len(differing)),
            tolerance=tolerance,
            unit="",
        )
    return stat


def _commands_agree(a: Command, b: Command, tolerance: float) -> bool:
    if tolerance == 0:
        return a == b
    d = command_number_difference(a, b)
    return d is not None and d <= tolerance


def on_path(command: Command, d: Divergence, joint_names: tuple[str, ...] | list[str]) -> bool:
    """Whether a command acts on the diverging field: a joint's command on that joint's fields, any
    joint, suction or key command on the pad, the hold and the objects; an annotation (`event`) on
    nothing."""
    if command.kind == "event":
        return False
    if d.channel == "joints":
        if command.kind == "key":
            return True
        joint = command.args.get("joint")
        if isinstance(joint, int) and not isinstance(joint, bool) and 0 <= joint < len(joint_names):
            joint = joint_names[joint]
        return command.kind.startswith("joint_") and joint == d.element
    return d.channel in (
        "suction",
        "hold",
        "pad",
        "objects",
        "final",
        "counts",
        "events",
        "outcome",
        "run",
        "images",
    )


def likely_cause(
    commands: list[Command], d: Divergence, joint_names: tuple[str, ...] | list[str] = ()
) -> str:
    """The golden's last command at or before the divergence that acts on the diverging field, or
    ""."""
    if d.channel == "commands":
        return ""
    before = [c for c in commands if c.step <= d.step and on_path(c, d, joint_names)]
    return _command_text(max(before, key=lambda c: c.step)) if before else ""


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


# -- the engine --------------------------------------------------------------------------------
def comparable(golden: Recording, candidate: Recording) -> list[str]:
    """Why the two runs cannot be compared (empty when they can): structure, not names. Two robots
    with the same joints by role compare (a renamed profile or a longer link is a difference to
    report); another time step or another set of scene objects does not."""
    g, c = golden.config, candidate.config
    why = []
    if len(g.profile.joint_names) != len(c.profile.joint_names):
        why.append(
            f"the candidate's robot has {len(c.profile.joint_names)} joints, the golden's "
            f"{len(g.profile.joint_names)}"
        )
    if g.dt_ns != c.dt_ns:
        why.append(f"time step {c.dt_ns} ns differs from the golden's {g.dt_ns} ns")
    gn, cn = [o.name for o in g.objects], [o.name for o in c.objects]
    if sorted(gn) != sorted(cn):
        why.append(f"scene objects {cn} differ from the golden's {gn}")
    return why


def refuse_incomparable(golden: Recording, candidate: Recording, force: bool) -> list[str]:
    """NotComparable unless the runs compare (or force); with force, the notes on what was compared
    despite."""
    why = comparable(golden, candidate)
    if why and not force:
        raise NotComparable(
            "the runs are not comparable: " + "; ".join(why) + " (use --force to compare anyway)"
        )
    return [f"compared despite: {w}" for w in why]


def compare(
    golden: Recording,
    candidate: Recording,
    tolerances: Tolerances | None = None,
    *,
    force: bool = False,
    event_kinds: frozenset[str] | None = None,
    floor: NoiseFloor | None = None,
) -> DiffResult:
    """Compare candidate with golden; raises NotComparable for structurally different runs unless
    force.

    event_kinds: the event kinds to pair one by one (None: all). floor: the candidate's measured
    noise floor; each field then allows the larger of its tolerance and the floor at that step.
    """
    tol = tolerances or Tolerances()
    notes = refuse_incomparable(golden, candidate, force)
    _require_frames(golden, candidate)
    allow = Allowances.of(tol, floor)
    gi, ci = align(golden.frames.step, candidate.frames.step)
    dt_ns = golden.config.dt_ns
    length = (int(golden.frames.step[-1]), int(candidate.frames.step[-1]))
    finals = final_poses(golden, candidate, allow.scalar)
    commands, identities = command_stats(golden, candidate, allow, dt_ns)
    pictures, pictures_note = _pictures(golden, candidate, allow, dt_ns)
    fields = [
        *frame_stats(golden, candidate, gi, ci, allow),
        length_stat(length, allow.scalar["run.length"], dt_ns),
        *final_stats(finals, allow.scalar, max(length), dt_ns),
        *commands,
        task_stat(golden, candidate, allow.task, max(length), dt_ns),
        *count_stats(golden.events, candidate.events, allow.scalar, max(length), dt_ns),
        *pictures,
    ]
    matched, shifted, event_diffs = _events(golden, candidate, allow, event_kinds)
    first_annotation = _first_of(fields, "commands.annotations")
    # annotations alone are still a difference, but never ahead of a physical one
    first = _first(fields, event_diffs, dt_ns, allow.event_window) or first_annotation
    notes += allow.commands_note() + pictures_note + allow.events_note()
    notes += _decimation_notes(golden, candidate, int(gi.shape[0]))
    notes += identity_notes(identities, match=first is None, fields=fields)
    return DiffResult(
        golden=run_summary(golden),
        candidate=run_summary(candidate),
        tolerances=tol,
        fields=fields,
        events_matched=matched,
        events_shifted=shifted,
        event_diffs=event_diffs,
        final_poses=finals,
        length=length,
        steps_compared=int(gi.shape[0]),
        config_differences=config_differences(
            {**golden.config.to_dict(), "run": golden.run or {}},
            {**candidate.config.to_dict(), "run": candidate.run or {}},
        ),
        notes=notes,
        first=first,
        first_command=_first_of(fields, "commands.sequence"),
        first_annotation=first_annotation,
        likely_cause=(
            "" if first is None
            else likely_cause(golden.commands, first, golden.config.profile.joint_names)
        ),
        events_compared=tol.event_window_steps is not None,
        floor=floor,
        identity=identities,
    )


def _require_frames(golden: Recording, candidate: Recording) -> None:
    g, c = golden.frames, candidate.frames
    if len(g) == 0 or len(c) == 0:
        raise RecordingError(
            f"cannot compare a run without frames (golden {golden.path or '<memory>'}: {len(g)} "
            f"frames, candidate {candidate.path or '<memory>'}: {len(c)} frames)"
        )


def _pictures(
    golden: Recording, candidate: Recording, allow: Allowances, dt_ns: int
) -> tuple[list[FieldStat], list[str]]:
    """The camera pictures' field (none when neither run has a camera), and the note when the
    tolerances leave them out."""
    if not (golden.config.cameras or candidate.config.cameras):
        return [], []
    stat = image_stat(golden, candidate, allow.scalar["images.pixels"], dt_ns)
    if not allow.images_off:
        return [stat], []
    return [stat], ["camera pictures are not compared under these tolerances (images.pixels = inf)"]


def _events(
    golden: Recording, candidate: Recording, allow: Allowances, kinds: frozenset[str] | None
) -> tuple[int, int, list[EventDiff]]:
    """(matched, shifted, differences) of the events paired within the allowed window, up to
    where the candidate's own events change with last-bit noise; nothing when not paired."""
    if allow.event_window is None:
        return 0, 0, []
    matched, shifted, diffs = match_events(golden.events, candidate.events, allow.event_window,
                                           kinds)
    if allow.events_until is not None:
        diffs = [d for d in diffs if d.step < allow.events_until]
    return matched, shifted, diffs


def _first_of(fields: list[FieldStat], name: str) -> Divergence | None:
    return next((f.first for f in fields if f.name == name), None)


def _decimation_notes(golden: Recording, candidate: Recording, compared: int) -> list[str]:
    notes = []
    for name, rec in (("golden", golden), ("candidate", candidate)):
        rate = rec.rate_steps
        if rate > 1:
            notes.append(
                f"the {name} is decimated (a frame every {rate} steps): frames compare "
                f"on the {compared} "
                "steps both files keep; commands, events and final poses compare at every step"
            )
    return notes


def _first(
    fields: list[FieldStat], event_diffs: list[EventDiff], dt_ns: int, window_steps: int | None
) -> Divergence | None:
    """The first physical divergence: of the fields (annotations aside) and the events."""
    candidates = [
        f.first for f in fields if f.first is not None and f.name != "commands.annotations"
    ]
    for d in event_diffs[:1]:
        element = f"{d.event_kind} {d.body}".strip()
        candidates.append(
            Divergence(
                step=d.step,
                t_s=d.step * dt_ns * 1e-9,
                channel="events",
                field=d.kind,
                element=element,
                expected=[d.expected_step],
                actual=[d.actual_step],
                difference=(
                    float(abs(d.expected_step - d.actual_step)) if d.kind == "moved" else INF
                ),
                tolerance=float(window_steps or 0),
                unit="steps",
            )
        )
    return min(candidates, key=lambda d: d.step) if candidates else None


def run_summary(rec: Recording) -> dict:
    f = rec.frames
    return {
        "path": rec.path,
        "profile": rec.config.profile.name,
        "run": rec.run,
        "frames": len(f),
        "first_step": int(f.step[0]) if len(f) else -1,
        "last_step": int(f.step[-1]) if len(f) else -1,
        "dt_ns": rec.config.dt_ns,
        "objects": [o.name for o in rec.config.objects],
        "events": len(rec.events),
        "commands": len(rec.commands),
    }


def config_differences(g: dict, c: dict, prefix: str = "") -> list[tuple[str, str, str]]:
    """Leaf-by-leaf differences of two configuration dicts: (key, golden, candidate)."""
    out = []
    for key in sorted(set(g) | set(c)):
        name = f"{prefix}{key}"
        a, b = g.get(key, "<absent>"), c.get(key, "<absent>")
        if isinstance(a, dict) and isinstance(b, dict):
            out += config_differences(a, b, name + ".")
        elif _dict_list(a) and _dict_list(b) and len(a) == len(b):
            for i, (x, y) in enumerate(zip(a, b, strict=True)):
                out += config_differences(x, y, f"{name}[{i}].")
        elif _plain(a) != _plain(b):
            out.append((name, repr(_plain(a)), repr(_plain(b))))
    return out


def _dict_list(x) -> bool:
    return isinstance(x, list | tuple) and bool(x) and all(isinstance(v, dict) for v in x)


def _plain(x):
    return [_plain(v) for v in x] if isinstance(x, list | tuple) else x
