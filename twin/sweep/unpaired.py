"""Two runs over different scenarios (another seed, other varied keys): not a paired experiment,
so their success rates are compared as independent samples (Newcombe's unpaired interval) and
their placement errors by each median's interval. twin sweep compare falls back to this when
paired.pair cannot pair them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.sweep.paired import Side
from twin.sweep.stats import median_ci, newcombe_unpaired, wilson


@dataclass
class Unpaired:
    """Two runs over different scenarios (another seed or other varied keys): their rates
    compared as independent samples, their placement errors by each median's interval."""

    reference: str
    new: str
    reference_ok: int
    reference_n: int
    new_ok: int
    new_n: int
    interval: tuple[float, float]  # Newcombe's hybrid score 95 % of new - reference
    reference_median: tuple[float, float, float] | None
    new_median: tuple[float, float, float] | None
    why: str  # why the scenarios are not paired

    @property
    def difference(self) -> float:
        return self.new_ok / self.new_n - self.reference_ok / self.reference_n

    def as_dict(self) -> dict:
        def med(m):
            return None if m is None else {"median": m[0], "ci95": [m[1], m[2]]}

        return {
            "kind": "unpaired",
            "why": self.why,
            "reference": self.reference,
            "new": self.new,
            "reference_ok": self.reference_ok,
            "reference_scenarios": self.reference_n,
            "new_ok": self.new_ok,
            "new_scenarios": self.new_n,
            "reference_wilson95": list(wilson(self.reference_ok, self.reference_n)),
            "new_wilson95": list(wilson(self.new_ok, self.new_n)),
            "difference": self.difference,
            "newcombe_unpaired95": list(self.interval),
            "reference_placement_median_mm": med(self.reference_median),
            "new_placement_median_mm": med(self.new_median),
        }


def unpaired(reference: Side, new: Side, why: str) -> Unpaired:
    return Unpaired(
        reference=reference.label,
        new=new.label,
        reference_ok=int(reference.ok.sum()),
        reference_n=reference.n,
        new_ok=int(new.ok.sum()),
        new_n=new.n,
        interval=newcombe_unpaired(int(new.ok.sum()), new.n, int(reference.ok.sum()), reference.n),
        reference_median=median_ci(_placed(reference)),
        new_median=median_ci(_placed(new)),
        why=why,
    )


def _placed(side: Side) -> np.ndarray:
    return side.placement_mm[~np.isnan(side.placement_mm)]


def unpaired_problems(u: Unpaired) -> list[str]:
    """Worse beyond sampling noise: the rate difference's interval below 0, or the new median
    placement error's interval above the reference's (two 95 % intervals apart: conservative)."""
    out = []
    lo, hi = u.interval
    if hi < 0:
        out.append(
            f"success rate is lower: {u.difference * 100:+.2f} points (Newcombe 95 % "
            f"{100 * lo:+.2f} to {100 * hi:+.2f})"
        )
    if u.reference_median and u.new_median and u.new_median[1] > u.reference_median[2]:
        out.append(
            f"placement error is higher: median {u.new_median[0]:.3f} mm (95 % from "
            f"{u.new_median[1]:.3f}) against {u.reference_median[0]:.3f} mm (95 % up to "
            f"{u.reference_median[2]:.3f})"
        )
    return out


def unpaired_text(u: Unpaired) -> str:
    lo, hi = u.interval
    rl, rh = wilson(u.reference_ok, u.reference_n)
    nl, nh = wilson(u.new_ok, u.new_n)
    lines = [
        f"not paired ({u.why}): reference {u.reference}, new {u.new}",
        (
            f"  reference {u.reference_ok}/{u.reference_n} ok: "
            f"{100 * u.reference_ok / u.reference_n:.2f} % "
            f"(Wilson 95 % {100 * rl:.2f}-{100 * rh:.2f} %)"
        ),
        (
            f"  new {u.new_ok}/{u.new_n} ok: {100 * u.new_ok / u.new_n:.2f} % "
            f"(Wilson 95 % {100 * nl:.2f}-{100 * nh:.2f} %)"
        ),
        (
            f"  difference {100 * u.difference:+.2f} points (Newcombe unpaired 95 % "
            f"{100 * lo:+.2f} to {100 * hi:+.2f})"
        ),
    ]
    for name, m in (("reference", u.reference_median), ("new", u.new_median)):
        if m is not None:
            lines.append(
                f"  {name} placement error median {m[0]:.3f} mm (95 % {m[1]:.3f} to {m[2]:.3f})"
            )
    return "\n".join(lines) + "\n"


def unpaired_markdown(u: Unpaired) -> str:
    return (
        f"# Unpaired comparison: {u.new} vs {u.reference}\n\n{u.why}.\n\n```text\n"
        f"{unpaired_text(u)}```\n"
    )
