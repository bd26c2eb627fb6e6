"""What a comparison finds: where a field first diverges, each field's figures, the final poses,
and the whole result (DiffResult), built once by twin.compare.engine.compare."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from twin.compare.events import EventDiff
from twin.compare.explanation import Explanation
from twin.compare.identity import IdentityDifference
from twin.compare.noise import NoiseFloor
from twin.compare.tolerances import Tolerances
from twin.model.errors import TwinError


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


def bit_identical(fields: list[FieldStat]) -> bool:
    """Every frame field bit for bit the same (what the report's summary calls bit-identical)."""
    return all(f.identical or not f.worst > 0 for f in fields if f.unit)


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
