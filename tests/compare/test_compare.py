"""The diff engine on real runs (in memory): exactness, sensitivity, tolerances, events, reports."""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.runs import record_pick_place

from twin.compare.engine import NotComparable, compare
from twin.compare.events import match_events
from twin.compare.metrics import quat_angle
from twin.compare.report import render_json, render_junit, render_markdown, render_text
from twin.compare.tolerances import FIELDS, Tolerances, parse_override
from twin.model.columns import FrameColumns
from twin.model.config import EngineParams, SceneObject, TwinConfig
from twin.model.errors import ConfigError
from twin.model.profiles import PROFILES
from twin.model.types import Event

BASE = TwinConfig()
PARAMS = {"cycles": 1}

FLOAT_COLUMNS = (
    "joint_q",
    "joint_qd",
    "joint_effort",
    "joint_target",
    "hold_force_n",
    "hold_torque_nm",
    "pad_pose",
    "object_poses",
    "suction_on",
    "sensed_body",
    "held_body",
)


def run(config: TwinConfig = BASE, params: dict = PARAMS):
    return record_pick_place(None, config, params)


def first_differing_step(a: FrameColumns, b: FrameColumns) -> int:
    """Computed independently of twin.compare: the first step where any column differs at all."""
    n = min(len(a), len(b))
    firsts = []
    for name in FLOAT_COLUMNS:
        x, y = getattr(a, name)[:n].reshape(n, -1), getattr(b, name)[:n].reshape(n, -1)
        rows = np.flatnonzero((x != y).any(axis=1))
        if rows.size:
            firsts.append(int(a.step[rows[0]]))
    if len(a) != len(b):
        firsts.append(n)
    return min(firsts)


@pytest.fixture(scope="module")
def golden():
    return run()


def test_same_run_twice_matches_exactly(golden):
    again = run()
    assert golden.frames.equals(again.frames)
    result = compare(golden, again, Tolerances.from_preset("exact"))
    assert result.match and result.exit_code == 0 and result.first is None
    assert all(f.worst == 0 for f in result.fields)
    assert result.events_matched == len(golden.events)
    assert "MATCH" in render_text(result)


@pytest.mark.parametrize("change", ["link 1 mm", "box 1 mm", "solver iterations"])
def test_a_small_change_is_caught_no_later_than_it_shows(golden, change):
    config = {
        "link 1 mm": dataclasses.replace(
            BASE, profile=dataclasses.replace(BASE.profile, link1_m=0.468)
        ),
        "box 1 mm": dataclasses.replace(
            BASE, objects=(SceneObject("box", pos_m=(0.201, 0.7, 0.025)),)
        ),
        "solver iterations": dataclasses.replace(
            BASE, engine=EngineParams(num_solver_iterations=40)
        ),
    }[change]
    candidate = run(config)
    shows_at = first_differing_step(golden.frames, candidate.frames)
    result = compare(golden, candidate)  # default: exact
    assert not result.match and result.exit_code == 1
    assert result.first.step <= shows_at
    assert result.config_differences, "the report names what changed in the configuration"
    text = render_text(result)
    assert f"first divergence: step {result.first.step}" in text


def test_outcome_passes_a_solver_change_when_the_box_lands_within_5_mm(golden):
    candidate = run(dataclasses.replace(BASE, engine=EngineParams(num_solver_iterations=40)))
    g_box, c_box = golden.frames.object_poses[-1, 0, :3], candidate.frames.object_poses[-1, 0, :3]
    assert np.linalg.norm(g_box - c_box) < 5e-3
    assert not compare(golden, candidate, Tolerances.from_preset("exact")).match
    assert compare(golden, candidate, Tolerances.from_preset("outcome")).match


def test_outcome_fails_when_the_box_ends_at_nan(golden):
    broken = copy.deepcopy(golden)
    broken.frames.object_poses[-1, 0, :3] = np.nan  # e.g. a physics blow-up in the last step
    result = compare(golden, broken, Tolerances.from_preset("outcome"))
    assert not result.match
    assert result.first.name == "final.position" and result.first.element == "box"


def test_outcome_fails_when_the_box_lands_elsewhere(golden):
    moved = copy.deepcopy(golden)
    moved.frames.object_poses[-1, 0, 0] += 0.006
    result = compare(golden, moved, Tolerances.from_preset("outcome"))
    assert not result.match
    assert result.first.name == "final.position" and result.first.element == "box"
    assert result.final_poses[0].distance_m == pytest.approx(0.006)


def test_tolerance_decides_and_the_first_divergence_carries_the_numbers(golden):
    shifted = copy.deepcopy(golden)
    # elbow 0.2 mrad off from step 100 on (physical allows 0.25)
    shifted.frames.joint_q[100:, 1] += 2e-4
    assert compare(golden, shifted, Tolerances.from_preset("physical")).match
    result = compare(
        golden, shifted, Tolerances.from_preset("physical").with_overrides(["joints.position=1e-4"])
    )
    first = result.first
    assert (first.step, first.name, first.element, first.unit) == (
        100,
        "joints.position",
        "MTB_axis2",
        "rad",
    )
    assert first.difference == pytest.approx(2e-4) and first.tolerance == 1e-4
    assert first.t_s == pytest.approx(100 * BASE.dt_ns * 1e-9)
    assert first.expected == [golden.frames.joint_q[100, 1]] and first.actual == [
        shifted.frames.joint_q[100, 1]
    ]


def test_angles_wrap_and_quaternion_sign_does_not_matter(golden):
    other = copy.deepcopy(golden)
    other.frames.joint_q[:, 3] += 2 * math.pi  # the same wrist angle, one turn on
    other.frames.object_poses[:, :, 3:] *= -1  # q and -q: the same orientation
    result = compare(golden, other, Tolerances.from_preset("tight"))
    assert result.match, render_text(result)


def test_a_decimated_golden_compares_on_its_steps(golden):
    every_10th = copy.deepcopy(golden)
    keep = np.r_[np.arange(0, len(golden.frames), 10), len(golden.frames) - 1]
    every_10th.frames = FrameColumns(
        **{f.name: getattr(golden.frames, f.name)[keep] for f in dataclasses.fields(FrameColumns)}
    )
    result = compare(every_10th, golden)
    assert result.match and result.steps_compared == len(keep)


def test_a_shorter_run_is_a_divergence_not_an_error(golden):
    short = copy.deepcopy(golden)
    short.frames = golden.frames.slice(0, 500)
    result = compare(golden, short)
    assert result.exit_code == 1
    assert result.length == (len(golden.frames) - 1, 499)
    assert result.first.name == "run.length" and result.first.step == 500


def test_another_robot_with_the_same_joints_is_a_mismatch_not_incomparable(golden):
    # comparability is structure (joints by role, time step, objects), not names: a profile copied
    # under a new name with one link 1 mm longer is a difference to report (exit 1), not exit 3
    renamed = dataclasses.replace(BASE.profile, name="my_mtb", link1_m=BASE.profile.link1_m + 0.001)
    other = run(dataclasses.replace(BASE, profile=renamed))
    result = compare(golden, other)
    assert result.exit_code == 1 and result.first.step == 0 and result.first.channel == "pad"
    assert ("profile.name", "'mtb'", "'my_mtb'") in result.config_differences
    assert any(k == "profile.link1_m" for k, _, _ in result.config_differences)
    seed = compare(golden, run(dataclasses.replace(BASE, profile=PROFILES["seed003"])))
    assert seed.exit_code == 1 and ("profile.name", "'mtb'", "'seed003'") in seed.config_differences


def test_other_scene_objects_or_time_step_are_not_comparable(golden):
    other = copy.deepcopy(golden)
    other.config = dataclasses.replace(BASE, objects=(SceneObject("crate"),))
    with pytest.raises(NotComparable, match="scene objects"):
        compare(golden, other)
    other.config = dataclasses.replace(BASE, dt_ns=2_000_000)
    with pytest.raises(
        NotComparable, match="time step 2000000 ns differs from the golden's 4166667 ns"
    ):
        compare(golden, other)


def _ev(step: int, kind: str, body: str = "box") -> Event:
    return Event(step, step * BASE.dt_ns, kind, body)


def test_events_pair_by_kind_and_body_in_order_within_the_window():
    golden = [_ev(10, "attach"), _ev(50, "release"), _ev(90, "attach"), _ev(95, "phase", "")]
    candidate = [_ev(12, "attach"), _ev(80, "release"), _ev(95, "phase", ""), _ev(99, "break")]
    matched, shifted, diffs = match_events(golden, candidate, window_steps=5)
    assert (matched, shifted) == (2, 1)
    assert [(d.kind, d.event_kind, d.expected_step, d.actual_step) for d in diffs] == [
        ("moved", "release", 50, 80),
        ("missing", "attach", 90, None),
        ("extra", "break", None, 99),
    ]
    assert match_events(golden, candidate, window_steps=40)[0] == 3


def test_event_differences_fail_the_diff(golden):
    other = copy.deepcopy(golden)
    other.events = [e for e in golden.events if e.kind != "release"]
    result = compare(golden, other)
    assert not result.match and result.first.channel == "events" and result.first.field == "missing"
    release = next(e for e in golden.events if e.kind == "release")
    assert result.first.step == release.step


def test_reports_in_every_format(golden):
    other = copy.deepcopy(golden)
    other.frames.pad_pose[700:, 2] += 0.002
    result = compare(golden, other, Tolerances.from_preset("physical"))
    md = render_markdown(result)
    assert md.startswith("# twin diff: MISMATCH") and "step 700" in md and "pad.position" in md
    data = json.loads(render_json(result))
    assert (
        data["match"] is False
        and data["first"]["step"] == 700
        and data["first"]["field"] == "position"
    )
    suite = ET.fromstring(render_junit(result)).find("testsuite")
    failed = [c.get("name") for c in suite.findall("testcase") if c.find("failure") is not None]
    assert failed == ["pad.position"] and suite.get("failures") == "1"


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("joints.position", "malformed"),
        ("joints.position=abc", "expected a number >= 0 or inf"),
        ("joints.pos=1e-3", "unknown field 'joints.pos'"),
        ("pad.position=-1", "expected a number >= 0"),
        ("a=b=c", "malformed"),
    ],
)
def test_malformed_tolerances_name_the_value(spec, expected):
    with pytest.raises(ConfigError, match=expected) as err:
        Tolerances.from_preset("physical").with_overrides([spec])
    assert repr(spec) in str(err.value) and "\n" not in str(err.value)


def test_tolerance_overrides_by_field_channel_and_inf():
    tol = Tolerances.from_preset("exact").with_overrides(["hold=inf", "pad.position=2e-3"])
    assert tol["hold.force"] == tol["hold.torque"] == math.inf and tol["pad.position"] == 2e-3
    assert parse_override("suction.on=0") == (["suction.on"], 0.0)
    assert set(Tolerances.from_preset("tight").values) == set(FIELDS)
    with pytest.raises(ConfigError, match="unknown tolerance preset 'loose'"):
        Tolerances.from_preset("loose")


unit_quats = (
    st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4)
    .filter(lambda v: sum(x * x for x in v) > 0.01)
    .map(lambda v: np.array(v) / np.linalg.norm(v))
)


@settings(max_examples=60, deadline=None)
@given(unit_quats, unit_quats)
def test_quaternion_angle_is_a_symmetric_sign_free_angle(a, b):
    ab, ba = quat_angle(a, b), quat_angle(b, a)
    assert ab == pytest.approx(ba, abs=1e-12)
    assert 0 <= ab <= math.pi + 1e-12
    assert quat_angle(a, -b) == pytest.approx(ab, abs=1e-9)
    assert quat_angle(a, a) == 0
