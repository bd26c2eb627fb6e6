"""What a comparison allows, each field's tolerance and the noise floor taken together, once.

A measured noise floor (the `noise` preset) raises a field's allowance to the floor where the floor
is larger, and stops the commands and the events at the step where the candidate's own ones change
with last-bit noise. Allowances.of works this out in one place, and the engine judges with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.compare.noise import NoiseFloor
from twin.compare.tolerances import INF, Tolerances


@dataclass(frozen=True)
class Allowances:
    tolerances: Tolerances  # as asked for, before the floor
    floor: NoiseFloor | None  # the candidate's measured noise floor, None when none was measured
    scalar: dict[str, float]  # every field's tolerance, raised to the floor's largest value
    commands: float  # numbers in commands (and annotations) within this much
    commands_until: int | None  # commands compared before this step (None: all)
    annotations: float
    identity_judged: bool  # a tolerance of 0 on commands.annotations judges the task's identity
    task: float
    images_off: bool  # images.pixels = inf: pictures are not looked at
    event_window: int | None  # events pair within this many steps (None: not paired)
    events_until: int | None  # event differences counted before this step (None: all)

    @classmethod
    def of(cls, tolerances: Tolerances, floor: NoiseFloor | None) -> Allowances:
        tol = tolerances
        if floor is None:
            return cls(
                tolerances=tol,
                floor=None,
                scalar=tol.values,
                commands=tol["commands.sequence"],
                commands_until=None,
                annotations=tol["commands.annotations"],
                identity_judged=tol["commands.annotations"] == 0,
                task=tol["outcome.task"],
                images_off=tol["images.pixels"] == INF,
                event_window=tol.event_window_steps,
                events_until=None,
            )
        window = tol.event_window_steps
        return cls(
            tolerances=tol,
            floor=floor,
            scalar={name: max(t, floor.scalar(name)) for name, t in tol.values.items()},
            commands=max(tol["commands.sequence"], floor.commands),
            commands_until=floor.commands_split_step,
            annotations=max(tol["commands.annotations"], floor.commands),
            identity_judged=tol["commands.annotations"] == 0,
            task=INF if floor.outcome_differs else tol["outcome.task"],
            images_off=tol["images.pixels"] == INF,
            event_window=None if window is None else max(window, floor.event_shift_steps),
            events_until=None if window is None else floor.events_split_step,
        )

    def frame(self, name: str, steps: np.ndarray) -> tuple[float, np.ndarray | None]:
        """A frame field's tolerance, and the noise floor at each of steps (None: no floor)."""
        return self.tolerances[name], None if self.floor is None else self.floor.at(name, steps)

    def commands_note(self) -> list[str]:
        return _noise_note(
            "commands",
            self.commands_until,
            " (its noise run took other ones): commands are compared up to there",
        )

    def events_note(self) -> list[str]:
        return _noise_note("events", self.events_until, ": events are paired up to there")


def _noise_note(what: str, step: int | None, then: str) -> list[str]:
    """The note that the candidate's own `what` change with last-bit noise from step on."""
    if step is None:
        return []
    return [f"the candidate's own {what} change with last-bit noise from step {step} on{then}"]
