"""What changed, in one line: the first divergence with both values and the difference in its
unit, a timing shift named as such, the annotations whose data changed, and the configuration
(scene, task parameters, task file) that differs.

It reads the two runs and the DiffResult the engine made of them; it judges nothing itself.
"""

from __future__ import annotations

import ast
import math
import re

import numpy as np

from twin.compare.explanation import SAME_MOTION_M, Explanation, TimingShift, si, steps_word
from twin.compare.metrics import REVOLUTE
from twin.compare.noise import command_number_difference
from twin.compare.result import DiffResult, Divergence
from twin.model.recording import Recording
from twin.model.types import Command

SAME_COMMAND = 1e-9  # the numbers of a shifted command agree this closely (tight's tolerance)
MOST_ANNOTATIONS = 2  # changed annotations named in the headline


def _exact(x: float, diff: float) -> str:
    """A value with enough decimals that a difference of `diff` shows (6 at least)."""
    if isinstance(x, bool | int) or not isinstance(x, float) or not math.isfinite(x):
        return repr(x)
    places = 6 if diff == 0 or not math.isfinite(diff) else max(6, 2 - math.floor(math.log10(diff)))
    return f"{x:.{min(places, 17)}f}"


def _vector(values: list, diff: float) -> str:
    return "(" + ", ".join(_exact(v, diff) for v in values) + ")"


# -- the first divergence, with both values --------------------------------------------------
def _joint_unit(rec: Recording, joint: object) -> str:
    names = list(rec.config.profile.joint_names)
    k = names.index(joint) if joint in names else joint if isinstance(joint, int) else -1
    return "rad" if 0 <= k < len(REVOLUTE) and REVOLUTE[k] else "m" if k >= 0 else ""


def _arg_unit(rec: Recording, command: Command, name: str) -> str:
    """A command argument's unit: a joint's for its q and v, else what the name ends in."""
    if name in ("q", "v") and "joint" in command.args:
        unit = _joint_unit(rec, command.args["joint"])
        return unit + "/s" if name == "v" and unit else unit
    return _NAMED_UNITS.get(name.rsplit("_", 1)[-1], "")


_NAMED_UNITS = {"m": "m", "rad": "rad", "s": "s", "kg": "kg", "n": "N"}  # error_m, hold_s, ...


def _number_change(subject: str, name: str, x: float, y: float, unit: str) -> str:
    """`subject name x -> y unit (+d unit)`, with as many decimals as the difference needs."""
    diff = abs(y - x)
    text = f"{subject} {name} {_exact(x, diff)} -> {_exact(y, diff)} {unit}".rstrip()
    return f"{text} ({si(y - x, unit, signed=True)})"


def _command_change(golden: Recording, candidate: Recording, d: Divergence) -> str:
    """A differing command: its kind and subject, the number that moved, both values and the
    difference; or its step moved; or both texts."""
    index = int(d.element.split()[0][1:])
    annotations = d.field == "annotations"
    g = [c for c in golden.commands if (c.kind == "event") == annotations]
    c = [c for c in candidate.commands if (c.kind == "event") == annotations]
    a, b = (g[index] if index < len(g) else None), (c[index] if index < len(c) else None)
    if a is None or b is None:
        side, present = ("candidate", a) if b is None else ("golden", b)
        return f"the {side} has no {_subject(present)} (the other's: step {present.step})"
    if annotations:
        return _annotation_change(a, b) or f"{_subject(a)} at step {a.step} -> {b.step}"
    if (
        a.kind == b.kind
        and a.step != b.step
        and command_number_difference(
            Command(a.step, a.kind, a.args), Command(a.step, b.kind, b.args)
        )
        == 0.0
    ):
        later = b.step - a.step
        return f"{_subject(a)} at step {a.step} -> {b.step} ({later:+d} {steps_word(later)})"
    moved = _moved_number(a, b)
    if a.kind == b.kind and a.step == b.step and moved is not None:
        return _number_change(_subject(a), *moved, _arg_unit(golden, a, moved[0]))
    return f"{d.expected[0]} -> {d.actual[0]}"


def _subject(c: Command) -> str:
    if c.kind == "event":
        return " ".join(str(x) for x in (c.args.get("kind", "event"), c.args.get("body")) if x)
    subject = c.args.get("joint", c.args.get("name", c.args.get("key", "")))
    return f"{c.kind} {subject}".strip()


def _moved_number(a: Command, b: Command) -> tuple[str, float, float] | None:
    """The numeric argument that moved most: (name, golden's, candidate's)."""
    best = None
    for name in sorted(set(a.args) & set(b.args)):
        x, y = a.args[name], b.args[name]
        if any(isinstance(v, bool) or not isinstance(v, int | float) for v in (x, y)):
            continue
        if x != y and (best is None or abs(y - x) > abs(best[2] - best[1])):
            best = (name, float(x), float(y))
    return best


def _annotation_change(a: Command, b: Command, nth: int = 0) -> str:
    """An annotation that says something else: its subject (the nth of its kind and body, from
    1, when given), the number in its data that moved most with both values and the difference,
    else the two messages; "" when they agree or are not the same annotation."""
    if (a.args.get("kind"), a.args.get("body")) != (b.args.get("kind"), b.args.get("body")):
        return ""
    subject = _subject(a) + (f" #{nth}" if nth else "")
    moved = _moved_number(
        Command(a.step, "data", a.args.get("data") or {}),
        Command(b.step, "data", b.args.get("data") or {}),
    )
    if moved is not None and abs(moved[2] - moved[1]) > SAME_COMMAND:  # not last-bit noise
        return _number_change(subject, *moved, _NAMED_UNITS.get(moved[0].rsplit("_", 1)[-1], ""))
    if a.args.get("message") != b.args.get("message"):
        return f"{subject} {a.args.get('message')!r} -> {b.args.get('message')!r}"
    return ""


def _frame_change(d: Divergence) -> str:
    """A frame field's divergence: the element, both values and the difference in its unit."""
    element = f" {d.element}" if d.element else ""
    if len(d.expected) == 1:
        x, y = d.expected[0], d.actual[0]
        if isinstance(x, bool) or isinstance(y, bool) or not isinstance(x, int | float):
            return f"{d.name}{element} {x!r} -> {y!r}"
        if isinstance(x, int) and isinstance(y, int):  # a body id, a count
            return f"{d.name}{element} {x} -> {y}"
        return _number_change(d.name, d.element, x, y, d.unit).replace("  ", " ")
    if d.unit == "rad":  # an orientation: the angle between the two
        return f"{d.name}{element} turned {si(d.difference, 'rad')}"
    return (
        f"{d.name}{element} {_vector(d.expected, d.difference)} -> "
        f"{_vector(d.actual, d.difference)} {d.unit} ({si(d.difference, d.unit)} apart)"
    )


def _event_change(d: Divergence, candidate: Recording) -> str:
    if d.field == "missing":
        return f"{d.element} at step {d.expected[0]} is missing from the candidate"
    if d.field == "extra":
        return f"{d.element} at step {d.actual[0]} is extra in the candidate"
    steps = d.actual[0] - d.expected[0]
    later = "later" if steps > 0 else "earlier"
    return (
        f"{d.element} {abs(steps)} {steps_word(steps)} {later} (step {d.expected[0]} -> "
        f"{d.actual[0]})"
    )


def change_text(golden: Recording, candidate: Recording, d: Divergence) -> str:
    """The first divergence as `step N: what golden -> candidate (difference)`."""
    if d.channel == "commands":
        what = _command_change(golden, candidate, d)
    elif d.channel == "events":
        what = _event_change(d, candidate)
    elif d.channel == "outcome":
        why = next((e.message for e in candidate.events if e.kind == "task_error"), "")
        what = f"outcome {d.expected[0]} -> {d.actual[0]}" + (f" ({why})" if why else "")
    elif d.channel == "run":
        what = f"run length {d.expected[0]} -> {d.actual[0]} steps"
    elif d.channel == "counts":
        what = f"{d.field} events {d.expected[0]} -> {d.actual[0]}"
    elif d.channel == "images":
        what = f"camera {d.element}: pictures differ by {d.difference:.3g} levels (mean)"
    else:
        what = _frame_change(d)
    return f"step {d.step}: {what}"


# -- a timing shift --------------------------------------------------------------------------
def timing_shift(golden: Recording, candidate: Recording) -> TimingShift | None:
    """The longest tail of the commands that act in which the candidate's are the golden's (their
    numbers within SAME_COMMAND) moved by one constant number of steps, not 0."""
    g = [c for c in golden.commands if c.kind != "event"]
    c = [c for c in candidate.commands if c.kind != "event"]
    if len(g) != len(c) or not g:
        return None
    shift, start = None, len(g)
    for i in range(len(g) - 1, -1, -1):
        a, b = g[i], c[i]
        moved = Command(a.step, b.kind, b.args)
        diff = command_number_difference(a, moved)
        if diff is None or diff > SAME_COMMAND or b.step == a.step:
            break
        if shift is None:
            shift = b.step - a.step
        elif b.step - a.step != shift:
            break
        start = i
    if shift is None:
        return None
    from_step = g[start].step
    same, residual_rad, residual_m = _shifted_motion(golden, candidate, from_step, shift)
    return TimingShift(
        steps=shift,
        from_step=from_step,
        commands=len(g) - start,
        same_motion=same,
        residual_rad=residual_rad,
        residual_m=residual_m,
    )


def _shifted_motion(
    golden: Recording, candidate: Recording, from_step: int, shift: int
) -> tuple[bool, float, float]:
    """Whether the candidate's frames from from_step + shift follow the golden's from from_step,
    and the largest joint and object-position errors between them."""
    gf, cf = golden.frames, candidate.frames
    g_at = {int(s): i for i, s in enumerate(gf.step.tolist())}
    c_at = {int(s): i for i, s in enumerate(cf.step.tolist())}
    pairs = [(i, c_at[s + shift]) for s, i in g_at.items() if s >= from_step and s + shift in c_at]
    if not pairs or len(golden.config.objects) != len(candidate.config.objects):
        return False, math.nan, math.nan
    gi, ci = (np.array(x, dtype=np.int64) for x in zip(*pairs, strict=True))
    joints = float(np.abs(gf.joint_q[gi] - cf.joint_q[ci]).max())
    objects = np.linalg.norm(gf.object_poses[gi, :, :3] - cf.object_poses[ci, :, :3], axis=-1)
    objects_m = float(objects.max()) if objects.size else 0.0
    return joints <= SAME_MOTION_M and objects_m <= SAME_MOTION_M, joints, objects_m


# -- annotations and configuration -----------------------------------------------------------
def changed_annotations(golden: Recording, candidate: Recording) -> list[str]:
    """The annotations (task start aside) that say something else in the candidate, paired in
    order as the engine pairs them: those whose data holds a number that moved (a placement's
    error) first, then those whose message alone changed (a phase's wording)."""
    g = [c for c in golden.commands if c.kind == "event"]
    c = [c for c in candidate.commands if c.kind == "event"]
    out: list[str] = []
    seen: dict[tuple, int] = {}
    for a, b in zip(g, c, strict=False):
        key = (a.args.get("kind"), a.args.get("body"))
        seen[key] = seen.get(key, 0) + 1
        if a.args.get("kind") == "task_start":
            continue
        text = _annotation_change(a, b, seen[key])
        if text:
            out.append(text)
    return sorted(out, key=lambda text: not text.endswith(")"))  # numbers end in "(+d unit)"


def task_file_changed(golden: Recording, candidate: Recording) -> bool:
    """The task's source differs: its task_start carries another sha256."""

    def source(rec: Recording) -> str:
        start = next(
            (c for c in rec.commands if c.kind == "event" and c.args.get("kind") == "task_start"),
            None,
        )
        return str(start.args.get("message", "")) if start is not None else ""

    a, b = source(golden), source(candidate)
    return a.startswith("sha256:") and b.startswith("sha256:") and a != b


_OBJECT_KEY = re.compile(r"^objects\[(\d+)\]\.(\w+)$")
_AXES = ("x_m", "y_m", "z_m")


def configuration_changes(result: DiffResult, golden: Recording) -> list[str]:
    """The configuration differences in the words a sweep uses, each with what it is: `scene
    changed: box.x_m 0.2 -> 0.201`, `task parameter hold_s 0.2 -> 0.5`, `configuration changed:
    profile.name 'mtb' -> 'seed003'`; the task file's name and hash aside (a task is its content:
    task_file_changed says when that differs)."""
    scene, task, other = [], [], []
    for key, a, b in result.config_differences:
        m = _OBJECT_KEY.match(key)
        if key in ("run.task", "run.task_sha256"):  # the task's name and source: not its behaviour
            continue
        if key.startswith("run.params."):
            task.append(f"task parameter {key[len('run.params.') :]} {a} -> {b}")
        elif m and int(m.group(1)) < len(golden.config.objects):
            scene += _object_changes(golden.config.objects[int(m.group(1))].name, m.group(2), a, b)
        else:
            other.append(f"{key} {a} -> {b}")
    return (
        ([f"scene changed: {'; '.join(scene)}"] if scene else [])
        + task
        + ([f"configuration changed: {'; '.join(other)}"] if other else [])
    )


def _object_changes(name: str, attr: str, a: str, b: str) -> list[str]:
    try:
        x, y = ast.literal_eval(a), ast.literal_eval(b)
    except (ValueError, SyntaxError):
        return [f"{name}.{attr} {a} -> {b}"]
    if attr == "pos_m" and isinstance(x, list) and isinstance(y, list) and len(x) == len(y) == 3:
        return [
            f"{name}.{axis} {u!r} -> {v!r}"
            for axis, u, v in zip(_AXES, x, y, strict=True)
            if u != v
        ]
    return [f"{name}.{attr} {x!r} -> {y!r}"]


# -- the whole line --------------------------------------------------------------------------
def explain(golden: Recording, candidate: Recording, result: DiffResult) -> Explanation:
    """Everything the one-line summary says about result, read from the two runs."""
    configuration = configuration_changes(result, golden)
    task_changed = task_file_changed(golden, candidate)
    annotations = changed_annotations(golden, candidate)
    if result.first is None:
        return Explanation(
            headline="",
            change="",
            shift=None,
            annotations=annotations,
            configuration=configuration,
            task_file_changed=task_changed,
        )
    change = change_text(golden, candidate, result.first)
    shift = None
    if result.first.field != "annotations":
        shift = timing_shift(golden, candidate)
    parts = [change]
    if shift is not None:
        parts.append(("then " if shift.from_step > result.first.step else "") + shift.text())
    others = [a for a in annotations if a not in change]  # the first divergence says its own
    parts += others[:MOST_ANNOTATIONS]
    if len(others) > MOST_ANNOTATIONS:
        parts.append(f"{len(others) - MOST_ANNOTATIONS} more annotations changed")
    if task_changed:
        parts.append("task file changed")
    parts += configuration
    return Explanation(
        headline="; ".join(parts),
        change=change,
        shift=shift,
        annotations=annotations,
        configuration=configuration,
        task_file_changed=task_changed,
    )
