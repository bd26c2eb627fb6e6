"""What changed, as data: a timing shift and the explanation of a DiffResult, with the words
their numbers are said in (twin.compare.explain finds them in two runs)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

# a shifted run's motion is "the same motion" when it stays this close to the golden's, shifted
SAME_MOTION_M = 2.5e-4  # the physical preset's position tolerance (m, and rad for joints)


@dataclass
class TimingShift:
    """From golden step `from_step` on, the candidate's commands are the golden's, `steps` later
    (negative: earlier); `same_motion` when the frames follow them within SAME_MOTION_M."""

    steps: int
    from_step: int
    commands: int  # how many commands of the golden's tail are shifted
    same_motion: bool
    residual_rad: float  # the largest joint error after shifting (rad or m), nan without frames
    residual_m: float  # the largest object position error after shifting (m)

    def text(self) -> str:
        later = "later" if self.steps > 0 else "earlier"
        when = f"{abs(self.steps)} {steps_word(self.steps)} {later}"
        what = "the same motion" if self.same_motion else "the same commands"
        text = f"{what}, {when} from step {self.from_step}"
        if self.same_motion and (self.residual_rad > 0 or self.residual_m > 0):
            text += (
                f" (within {si(self.residual_rad, 'rad')} and {si(self.residual_m, 'm')} "
                "once shifted)"
            )
        return text


@dataclass
class Explanation:
    """What a DiffResult says in words (twin.compare.explain)."""

    headline: str  # one line: what changed, by how much, and why it may have
    change: str = ""  # the first divergence with both values ("" when the runs match)
    shift: TimingShift | None = None
    annotations: list[str] = field(default_factory=list)  # annotations whose data changed
    configuration: list[str] = field(default_factory=list)  # scene and task differences
    task_file_changed: bool = False


_PREFIXES = ((1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"))


def si(x: float, unit: str, signed: bool = False) -> str:
    """A difference in its unit with a prefix that keeps 3 significant digits readable: 4.41 mrad,
    2.00 mm, 1.9e-10 N·m (prefixes only for m and rad)."""
    sign = "+" if signed and x > 0 else ""
    if not math.isfinite(x):
        return f"{x} {unit}".strip()
    if x == 0:
        return f"0 {unit}".strip()
    if unit in ("m", "rad"):
        rounded = float(f"{x:.3g}")  # 0.00099997 m is 1 mm, not 1e+03 µm
        for scale, prefix in _PREFIXES:
            if abs(rounded) >= scale:
                return f"{sign}{x / scale:.3g} {prefix}{unit}"
    return f"{sign}{x:.3g} {unit}".strip()


def steps_word(n: int) -> str:
    """"step" or "steps", for n of them."""
    return "step" if abs(n) == 1 else "steps"
