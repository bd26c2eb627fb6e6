"""Allowances: each field's tolerance and the measured noise floor, worked out once."""

import numpy as np

from twin.compare.allowances import Allowances
from twin.compare.noise import NoiseFloor
from twin.compare.tolerances import INF, Tolerances


def _floor(**kw) -> NoiseFloor:
    return NoiseFloor(
        perturbation="test",
        margin=10.0,
        steps=np.array([0, 10]),
        envelopes={"joints.position": np.array([1e-12, 1e-3])},
        **kw,
    )


def test_without_a_floor_the_tolerances_stand_as_they_are():
    tol = Tolerances.from_preset("tight")
    allow = Allowances.of(tol, None)
    assert allow.scalar == tol.values
    assert allow.commands == tol["commands.sequence"]
    assert allow.annotations == tol["commands.annotations"]
    assert allow.task == tol["outcome.task"]
    assert allow.event_window == tol.event_window_steps
    assert allow.commands_until is None and allow.events_until is None
    assert allow.commands_note() == [] and allow.events_note() == []
    tolerance, floor = allow.frame("joints.position", np.array([0, 5]))
    assert tolerance == tol["joints.position"] and floor is None


def test_a_floor_raises_each_allowance_and_stops_commands_and_events():
    tol = Tolerances.from_preset("tight")
    floor = _floor(
        scalars={"final.position": 1.0},
        commands=0.5,
        commands_split_step=40,
        event_shift_steps=tol.event_window_steps + 7,
        events_split_step=50,
        outcome_differs=True,
    )
    allow = Allowances.of(tol, floor)
    assert allow.scalar["final.position"] == 1.0
    assert allow.scalar["run.length"] == tol["run.length"]
    assert allow.commands == allow.annotations == 0.5
    assert allow.commands_until == 40 and allow.events_until == 50
    assert allow.task == INF
    assert allow.event_window == tol.event_window_steps + 7
    assert allow.commands_note()[0].endswith("commands are compared up to there")
    assert "from step 50 on: events are paired" in allow.events_note()[0]
    _, at = allow.frame("joints.position", np.array([5, 15]))
    assert at.tolist() == [1e-12, 1e-3]


def test_without_an_event_window_the_floor_pairs_no_events():
    tol = Tolerances.from_preset("outcome")
    allow = Allowances.of(tol, _floor(event_shift_steps=3, events_split_step=50))
    assert allow.event_window is None and allow.events_until is None
    assert allow.events_note() == []


def test_only_a_zero_annotation_tolerance_judges_the_task_identity():
    assert Allowances.of(Tolerances.from_preset("exact"), None).identity_judged
    assert not Allowances.of(Tolerances.from_preset("tight"), _floor()).identity_judged
