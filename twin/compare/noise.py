"""The numerical noise floor of a run: how far it drifts on its own when its arithmetic is perturbed
in the last bit. Measured by comparing the run with a second run of the same inputs whose math was
nudged (verify.noise makes it); the `noise` verdict then allows each field margin times the floor
the perturbed run reached by that step (a running maximum: noise does not shrink back), never less
than the preset's own tolerance. Another libm or CPU changes a run by about as much as such a nudge
does, and a real change shows at its onset far above it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from twin.compare.events import by_key
from twin.compare.metrics import quat_angle
from twin.compare.tolerances import COUNTED_EVENTS
from twin.model.recording import Recording
from twin.model.types import Command


@dataclass
class NoiseFloor:
    """Per-field floors of a run (FIELDS units), already multiplied by margin.

    steps and envelopes: per compared field, the running maximum over the run's steps; the rest
    judged on the whole run. commands: the largest number in a command argument that moved; from
    commands_split_step on (the perturbed run's commands differ in kind, step or text) commands are
    not judged, nor events from events_split_step on (an event one run has and the other lacks)."""

    perturbation: str
    margin: float
    steps: np.ndarray
    envelopes: dict[str, np.ndarray]
    # final.*, run.length, counts.* (pictures: tolerance only)
    scalars: dict[str, float] = field(default_factory=dict)
    commands: float = 0.0
    commands_split_step: int | None = None
    event_shift_steps: int = 0
    events_split_step: int | None = None
    outcome_differs: bool = False

    def at(self, name: str, steps: np.ndarray) -> np.ndarray:
        """The floor of field `name` at each of `steps` (0 before the run's first step)."""
        env = self.envelopes.get(name)
        if env is None or len(env) == 0:
            return np.zeros(len(steps))
        i = np.searchsorted(self.steps, steps, side="right") - 1
        return np.where(i >= 0, env[np.clip(i, 0, len(env) - 1)], 0.0)

    def scalar(self, name: str) -> float:
        return self.scalars.get(name, 0.0)

    def to_dict(self) -> dict:
        def num(x: float) -> float | str:
            return x if math.isfinite(x) else str(x)

        return {
            "perturbation": self.perturbation,
            "margin": self.margin,
            "fields": {
                k: num(float(v[-1])) if len(v) else 0.0 for k, v in sorted(self.envelopes.items())
            }
            | {k: num(v) for k, v in sorted(self.scalars.items())},
            "commands": num(self.commands),
            "commands_split_step": self.commands_split_step,
            "event_shift_steps": self.event_shift_steps,
            "events_split_step": self.events_split_step,
            "outcome_differs": self.outcome_differs,
        }


def command_number_difference(a: Command, b: Command) -> float | None:
    """The largest difference between the numbers of two commands' arguments; None when they differ
    in anything else (step, kind, argument names, strings, booleans, list lengths)."""
    if a.step != b.step or a.kind != b.kind:
        return None
    return _value_difference(a.args, b.args)


def _value_difference(a: object, b: object) -> float | None:
    if isinstance(a, bool) or isinstance(b, bool) or isinstance(a, str) or a is None:
        return 0.0 if type(a) is type(b) and a == b else None
    if isinstance(a, int | float) and isinstance(b, int | float):
        if isinstance(a, int) and isinstance(b, int):
            return 0.0 if a == b else None
        if math.isnan(a) or math.isnan(b):
            return 0.0 if math.isnan(a) and math.isnan(b) else None
        return 0.0 if a == b else abs(float(a) - float(b))
    if isinstance(a, dict) and isinstance(b, dict):
        if sorted(a) != sorted(b):
            return None
        parts = [_value_difference(a[k], b[k]) for k in a]
    elif isinstance(a, list | tuple) and isinstance(b, list | tuple):
        if len(a) != len(b):
            return None
        parts = [_value_difference(x, y) for x, y in zip(a, b, strict=True)]
    else:
        return None
    return None if None in parts else max(parts, default=0.0)


def measure(
    run: Recording, perturbed: Recording, series: tuple, perturbation: str, margin: float
) -> NoiseFloor:
    """The floor of `run` from `perturbed`, a run of the same inputs with its math nudged; series is
    engine.error_series(run, perturbed) (the engine uses this module, not the other way round)."""
    steps, _t, errors = series
    envelopes = {
        name: margin * np.maximum.accumulate(np.where(np.isnan(e), math.inf, e))
        for name, e in errors.items()
    }
    a, b = run.frames.object_poses[-1], perturbed.frames.object_poses[-1]
    scalars = {
        "final.position": margin
        * float(np.max(np.linalg.norm(a[:, :3] - b[:, :3], axis=-1), initial=0.0)),
        "final.orientation": margin * float(np.max(quat_angle(a[:, 3:], b[:, 3:]), initial=0.0)),
        "run.length": float(abs(int(run.frames.step[-1]) - int(perturbed.frames.step[-1]))),
    }
    for kind in COUNTED_EVENTS:
        scalars[f"counts.{kind}"] = float(
            abs(
                sum(e.kind == kind for e in run.events)
                - sum(e.kind == kind for e in perturbed.events)
            )
        )
    commands, split = 0.0, None
    for x, y in zip(run.commands, perturbed.commands, strict=False):
        d = command_number_difference(x, y)
        if d is None:
            split = min(x.step, y.step)
            break
        commands = max(commands, d)
    if split is None and len(run.commands) != len(perturbed.commands):
        longer = run.commands if len(run.commands) > len(perturbed.commands) else perturbed.commands
        split = longer[min(len(run.commands), len(perturbed.commands))].step
    shift, unpaired = _event_drift(run.events, perturbed.events)
    return NoiseFloor(
        perturbation=perturbation,
        margin=margin,
        steps=np.asarray(steps),
        envelopes=envelopes,
        scalars=scalars,
        commands=margin * commands,
        commands_split_step=split,
        event_shift_steps=shift,
        events_split_step=unpaired,
        outcome_differs=run.outcome != perturbed.outcome,
    )


def _event_drift(a: list, b: list) -> tuple[int, int | None]:
    """Events of a and b paired by (kind, body) in order, as compare.events pairs them: the largest
    step shift of a pair, and the first step of an event left without a pair (None: all paired)."""
    ka, kb = by_key(a), by_key(b)
    shift, unpaired = 0, []
    for xs, ys in ((ka.get(k, []), kb.get(k, [])) for k in ka.keys() | kb.keys()):
        shift = max([shift] + [abs(x.step - y.step) for x, y in zip(xs, ys, strict=False)])
        unpaired += [e.step for e in (xs[len(ys) :] or ys[len(xs) :])]
    return shift, min(unpaired, default=None)
