"""The default `noise` verdict and what reports say: full precision, numeric command data, likely
causes."""

from __future__ import annotations

import copy
import dataclasses
import math

import pytest

from twin.compare.engine import compare
from twin.compare.noise import command_number_difference
from twin.compare.report import noise_summary, render_text
from twin.compare.tolerances import DEFAULT, Tolerances
from twin.model.config import TwinConfig
from twin.model.types import Command
from twin.verify.check import record_task, remade
from twin.verify.noise import judge, perturbed


@pytest.fixture(scope="module")
def run():
    return record_task(TwinConfig(), "pick_place", {"cycles": 1})


def _copy(rec):
    return dataclasses.replace(rec, frames=copy.deepcopy(rec.frames), commands=list(rec.commands))


def test_the_default_is_noise_and_a_run_against_itself_is_bit_identical(run):
    assert DEFAULT == "noise"
    result = judge(run, remade(run), Tolerances.from_preset(DEFAULT), remade)
    assert result.match and noise_summary(result) == "bit-identical"
    assert result.floor is not None and result.floor.margin == 10.0
    assert "noise floor" in render_text(result)


def test_the_floor_comes_from_a_perturbed_run(run):
    nudged = perturbed(run)
    assert nudged.config.engine.gravity_m_s2[2] < run.config.engine.gravity_m_s2[2]
    assert nudged.commands == run.commands
    floor = judge(run, run, Tolerances.from_preset(DEFAULT), remade).floor
    # the nudge moved the run's last bits
    assert max(float(e[-1]) for e in floor.envelopes.values()) > 0


def test_a_last_bit_difference_prints_in_full_beside_fail(run):
    other = _copy(run)
    k = int(next(i for i, q in enumerate(run.frames.joint_q[:, 0]) if abs(q) > 0.5))
    # one ulp: 1e-16 rad
    other.frames.joint_q[k, 0] = math.nextafter(float(run.frames.joint_q[k, 0]), math.inf)
    result = compare(run, other, Tolerances.from_preset("exact"))
    assert not result.match and result.first.difference > 0
    text = render_text(result)
    assert "difference 0 rad" not in text and f"{result.first.difference:.4g}" in text


def test_event_data_compares_numerically_under_tight_and_noise(run):
    other = _copy(run)
    i = next(
        k
        for k, c in enumerate(run.commands)
        if c.kind == "event" and c.args.get("kind") == "placed"
    )
    c = run.commands[i]
    data = {**c.args["data"], "error_m": c.args["data"]["error_m"] + 1e-12}
    other.commands[i] = Command(c.step, c.kind, {**c.args, "data": data})
    assert command_number_difference(c, other.commands[i]) == pytest.approx(1e-12, rel=1e-3)
    assert not compare(run, other, Tolerances.from_preset("exact")).match
    assert compare(run, other, Tolerances.from_preset("tight")).match
    data["error_m"] += 1e-6  # a micrometre is a change
    other.commands[i] = Command(c.step, c.kind, {**c.args, "data": data})
    assert not compare(run, other, Tolerances.from_preset("tight")).match


def test_a_changed_message_is_a_change_whatever_the_tolerance(run):
    other = _copy(run)
    i = next(k for k, c in enumerate(run.commands) if c.kind == "event")
    c = run.commands[i]
    other.commands[i] = Command(c.step, c.kind, {**c.args, "message": c.args["message"] + "!"})
    assert command_number_difference(c, other.commands[i]) is None
    assert not compare(run, other, Tolerances.from_preset("tight")).match


def test_the_likely_cause_acts_on_the_diverging_field(run):
    other = _copy(run)
    step = 600
    k = int(next(i for i, s in enumerate(run.frames.step) if s == step))
    other.frames.joint_q[k:, 1] += 1e-3  # the second joint leaves the golden at step 600
    result = compare(run, other, Tolerances.from_preset("tight"))
    joint = run.config.profile.joint_names[1]
    assert result.first.element == joint
    assert f"joint='{joint}'" in result.likely_cause and "event(" not in result.likely_cause
    other = _copy(run)
    # the box: any joint or suction command may explain it
    other.frames.object_poses[k:, 0, 0] += 1e-3
    result = compare(run, other, Tolerances.from_preset("tight"))
    assert result.likely_cause and "event(" not in result.likely_cause


def test_a_real_change_is_reported_against_the_floor(run):
    other = _copy(run)
    k = 700
    other.frames.object_poses[k:, 0, 1] += 1e-3
    result = judge(run, other, Tolerances.from_preset(DEFAULT), remade)
    assert not result.match and result.first.step == int(run.frames.step[k])
    assert noise_summary(result).startswith("changed: 0.001 m at step")
    assert "x the allowance" in noise_summary(result)
