"""Verdicts that travel: judge a candidate against a golden with the candidate's noise floor
measured here.

The floor run is the candidate's inputs again (its task re-run, or its commands replayed) with
gravity one unit in the last place stronger: every physics step's arithmetic then differs in its
last bits, as it does under another libm or CPU, and the floor is how far the run drifts from that
on its own. Measured on this machine and with this code, at every check, so it never goes stale.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

from twin.compare.engine import compare, refuse_incomparable
from twin.compare.explain import explain
from twin.compare.fields import error_series
from twin.compare.noise import measure
from twin.compare.result import DiffResult
from twin.compare.tolerances import Tolerances
from twin.model.errors import TwinError
from twin.model.recording import Recording
from twin.record.machine import differences, machine, machine_text

PERTURBATION = "gravity 1 ulp stronger"


def perturbed(rec: Recording) -> Recording:
    """rec with its engine's gravity nudged by one unit in the last place (its inputs unchanged)."""
    engine = rec.config.engine
    gx, gy, gz = engine.gravity_m_s2
    nudged = (gx, gy, math.nextafter(gz, -math.inf if gz <= 0 else math.inf))
    config = dataclasses.replace(
        rec.config, engine=dataclasses.replace(engine, gravity_m_s2=nudged)
    )
    return dataclasses.replace(rec, config=config)


def judge(
    golden: Recording,
    candidate: Recording,
    tolerances: Tolerances,
    remake: Callable[[Recording], Recording],
    *,
    source: Recording | None = None,
    event_kinds: frozenset[str] | None = None,
    force: bool = False,
) -> DiffResult:
    """compare(golden, candidate), against the noise floor of the candidate's inputs when the
    tolerances ask.

    remake(recording) re-runs a recording (its task, or its commands). source: the recording the
    candidate was just remade from (check, replay); the floor is then the candidate against
    remake(perturbed source). Without it (a candidate from a file or a test), both runs of the floor
    are remade here: remake(candidate) and remake(perturbed candidate), so that nothing but last-bit
    noise separates them. When the floor cannot be measured (nothing to re-run), the verdict is the
    preset's own tolerances, with a note saying so.
    """
    if tolerances.noise_margin is None:
        return _where(
            compare(golden, candidate, tolerances, event_kinds=event_kinds, force=force),
            golden,
            candidate,
        )
    refuse_incomparable(golden, candidate, force)  # before the floor runs, not after
    floor, note = None, ""
    try:
        base = candidate if source is not None else remake(candidate)
        nudged = remake(perturbed(source or candidate))
        floor = measure(
            base, nudged, error_series(base, nudged), PERTURBATION, tolerances.noise_margin
        )
    except TwinError as err:
        note = (
            f"the noise floor could not be measured ({err}); judged by the "
            f"{tolerances.preset} preset's "
            "tolerances alone"
        )
    result = compare(
        golden, candidate, tolerances, event_kinds=event_kinds, force=force, floor=floor
    )
    if note:
        result.notes.append(note)
    return _where(result, golden, candidate)


def _where(result: DiffResult, golden: Recording, candidate: Recording) -> DiffResult:
    """The result explained (what changed, in one line), and a note "recorded on X, checked on Y"
    when the golden's machine record differs from the candidate's (a run made here has none: it
    is this machine's)."""
    result.explanation = explain(golden, candidate, result)
    made, checked = golden.machine, candidate.machine or machine()
    if made and differences(made, checked):
        result.notes.append(f"recorded on {machine_text(made)}, checked on {machine_text(checked)}")
    return result
