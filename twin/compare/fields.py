"""The frame fields: each aligned column of the two runs, its error in physical units, and its
figures (FieldStat) against the allowance. Everything is numpy over whole columns."""

from __future__ import annotations

import numpy as np

from twin.compare.allowances import Allowances
from twin.compare.metrics import (
    REVOLUTE,
    abs_error,
    differs,
    discrete_error,
    joint_error,
    norm_error,
    quat_angle,
)
from twin.compare.result import Divergence, FieldStat, values
from twin.compare.tolerances import FIELDS, INF
from twin.model.fields import COMPARED
from twin.model.recording import Recording

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


def element_series(golden: Recording, candidate: Recording):
    """On the steps both runs have, per frame field: (name, golden (n, k, c), candidate (n, k, c),
    error (n, k) in FIELDS units, element names), what frame_stats judges; and (steps, t_ns)
    first. For drawing the runs against their allowance (twin.report)."""
    gi, ci = align(golden.frames.step, candidate.frames.step)
    fields = [
        (name, a, b, metric(a, b), elements)
        for name, a, b, metric, elements in _field_arrays(golden, candidate, gi, ci)
    ]
    return golden.frames.step[gi], golden.frames.t_ns[gi], fields


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
