"""Tolerances for comparing two runs: per channel and field, in physical units, with presets.

Names are `channel.field`. Joint values are rad for the revolute joints and m for the prismatic Z
joint (one number covers both: 2.5e-4 means 0.25 mrad or 0.25 mm). A tolerance of 0 means
bit-identical; `inf` switches a field off. Discrete fields (suction state, run length, the command
sequence, the task outcome) compare exactly unless off; the numbers in commands' arguments compare
within the commands.sequence tolerance; event counts allow that many events more or fewer. Events
pair within a window of steps; a window of None (the `outcome` preset) leaves them out. The `noise`
preset, the default, is `tight` that also allows each field the candidate's measured noise floor
(compare.noise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from twin.model.errors import ConfigError
from twin.model.fields import COMPARED

INF = math.inf

# name -> (unit, what it is). The order is the report's order: the Frame's fields as model.fields
# describes them, then what is judged on the whole run.
FIELDS: dict[str, tuple[str, str]] = {
    **{c.name: (c.unit, c.what) for _, c in COMPARED},
    "final.position": ("m", "distance between final object positions"),
    "final.orientation": ("rad", "angle between final object orientations"),
    "run.length": ("steps", "difference in the last step"),
    "commands.sequence": (
        "",
        (
            "every Command that acts (joints, suction, keys): step, kind and text exactly, "
            "in order; the numbers in its arguments within the tolerance"
        ),
    ),
    "commands.annotations": (
        "",
        (
            "every annotation (an `event` Command: what the task said, such as "
            "task_start naming the task by its content's sha256), judged like commands.sequence "
            "but reported apart from the first physical divergence; the task's identity in "
            "task_start only at a tolerance of 0 (exact), with a note under the other presets"
        ),
    ),
    "outcome.task": (
        "",
        (
            "how the task ended: ok (no task_error, finalized ok), error, interrupted, or "
            "unfinished (a file cut short, also once recovered); exact or off"
        ),
    ),
    "counts.attach": ("events", "number of attach events"),
    "counts.release": ("events", "number of release events"),
    "counts.break": ("events", "number of break events"),
    "counts.cycle_failed": (
        "events",
        "number of cycle_failed events (a cycle a task let fail and went on)",
    ),
    "images.pixels": (
        "levels",
        "mean absolute difference of a camera picture's pixels (0..255 per channel)",
    ),
}
DISCRETE = frozenset(
    {
        "suction.on",
        "suction.sensed",
        "suction.held",
        "commands.sequence",
        "commands.annotations",
        "outcome.task",
    }
)
COUNTED_EVENTS = ("attach", "release", "break", "cycle_failed")
_ALWAYS = {"outcome.task": 0.0, **{f"counts.{kind}": 0.0 for kind in COUNTED_EVENTS}}
# tight: a picture may differ by half a level on average (another CPU's rounding)
IMAGE_TIGHT_LEVELS = 0.5
POSITION_M = 2.5e-4  # physical: a clear margin below 1 mm, so a 1 mm change always shows

_ALL_ZERO = {name: 0.0 for name in FIELDS}
_PHYSICAL = _ALWAYS | {
    "joints.position": POSITION_M,  # 0.25 mrad, 0.25 mm
    "joints.velocity": 1e-2,  # 10 mrad/s, 10 mm/s
    "joints.effort": 0.5,  # N·m | N: under 1 % of the motors' 60 N·m / 60 N
    "joints.target": POSITION_M,
    "suction.on": 0.0,
    "suction.sensed": 0.0,
    "suction.held": 0.0,
    "hold.force": 0.1,  # N: a tenth of the stock pad's 1 N shear limit
    "hold.torque": 0.01,  # N·m: a tenth of its 0.1 N·m peel limit
    "pad.position": POSITION_M,
    "pad.orientation": 1e-3,
    "objects.position": POSITION_M,
    "objects.orientation": 1e-3,
    "final.position": POSITION_M,
    "final.orientation": 1e-3,
    "run.length": 0.0,
    # physically equal runs may be driven by other but equivalent commands
    "commands.sequence": INF,
    "commands.annotations": INF,
    # pictures of physically equal runs differ where the robot differs by a pixel
    "images.pixels": INF,
}
# outcome: where the objects ended, whether the task ended ok, how often the pad took and let go
_OUTCOME = (
    {name: INF for name in FIELDS} | _ALWAYS | {"final.position": 5e-3, "final.orientation": 0.05}
)

# tight: 1e-9 on every number (frames of another libm stayed within it over 44k steps), commands'
# numbers too
_TIGHT = {
    name: 0.0
    if name in DISCRETE - {"commands.sequence", "commands.annotations"}
    or name == "run.length"
    or name in _ALWAYS
    else 1e-9
    for name in FIELDS
} | {"images.pixels": IMAGE_TIGHT_LEVELS}
# preset -> (field tolerances, event window in steps; None: events are not paired)
PRESETS: dict[str, tuple[dict[str, float], int | None]] = {
    "noise": (_TIGHT, 0),
    "exact": (_ALL_ZERO, 0),
    "tight": (_TIGHT, 0),
    "physical": (_PHYSICAL, 12),
    "outcome": (_OUTCOME, None),
}
# presets judged against the candidate's measured noise floor, times this margin (compare.noise)
NOISE_MARGINS: dict[str, float] = {"noise": 10.0}
DEFAULT = "noise"


@dataclass(frozen=True)
class Tolerances:
    """Per-field tolerances (FIELDS units) and the event time window in physics steps (None: events
    are not paired one by one; the counts of attach, release and break still compare)."""

    preset: str = "exact"
    values: dict[str, float] = field(default_factory=lambda: dict(_ALL_ZERO))
    event_window_steps: int | None = 0
    overrides: tuple[str, ...] = ()
    # judge against the measured noise floor times this (None: do not)
    noise_margin: float | None = None

    @staticmethod
    def from_preset(name: str) -> Tolerances:
        if name not in PRESETS:
            raise ConfigError(
                f"unknown tolerance preset {name!r}; expected one of {', '.join(PRESETS)}"
            )
        values, window = PRESETS[name]
        return Tolerances(name, dict(values), window, noise_margin=NOISE_MARGINS.get(name))

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def with_overrides(self, specs: list[str] | tuple[str, ...]) -> Tolerances:
        """Apply `channel.field=VALUE` (or `channel=VALUE` for every field of a channel)."""
        values = dict(self.values)
        for spec in specs:
            names, value = parse_override(spec)
            for name in names:
                values[name] = value
        return replace(self, values=values, overrides=self.overrides + tuple(specs))

    def with_event_window(self, steps: int | None) -> Tolerances:
        if steps is None:
            return self
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
            raise ConfigError(
                f"event window {steps!r} is invalid; expected a whole number of steps >= 0"
            )
        return replace(self, event_window_steps=steps)

    def to_dict(self) -> dict:
        return {
            "preset": self.preset,
            "event_window_steps": self.event_window_steps,
            "overrides": list(self.overrides),
            "noise_margin": self.noise_margin,
            "fields": {name: _json_number(self.values[name]) for name in FIELDS},
        }


def parse_override(spec: str) -> tuple[list[str], float]:
    """`joints.position=1e-4` -> (["joints.position"], 1e-4); `hold=inf` -> every hold.* field."""
    known = ", ".join(FIELDS)
    if not isinstance(spec, str) or spec.count("=") != 1:
        raise ConfigError(
            f"tolerance {spec!r} is malformed; expected CHANNEL.FIELD=VALUE, e.g. "
            f"joints.position=1e-4"
        )
    name, text = (s.strip() for s in spec.split("="))
    if name in FIELDS:
        names = [name]
    else:
        names = [f for f in FIELDS if f.split(".")[0] == name]
        if not names:
            raise ConfigError(
                f"tolerance {spec!r} names unknown field {name!r}; expected one of {known}"
            )
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if math.isnan(value) or value < 0:
        raise ConfigError(f"tolerance {spec!r} has value {text!r}; expected a number >= 0 or inf")
    return names, value


def _json_number(value: float) -> float | str:
    return "inf" if math.isinf(value) else value
