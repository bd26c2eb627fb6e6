"""Kinematics properties over the whole workspace of every built-in profile (pure math, no physics)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twin import kinematics as k
from twin.errors import OutOfReach
from twin.profiles import PROFILES

POSITION_TOL_M = 1e-9
QUADRANTS = {  # (lowest, highest) polar angle of the target, radians
    "x+y+": (0.0, 0.5 * math.pi),
    "x-y+": (0.5 * math.pi, math.pi),
    "x-y-": (-math.pi, -0.5 * math.pi),
    "x+y-": (-0.5 * math.pi, 0.0),
}
profiles = st.sampled_from(sorted(PROFILES))
fraction = st.floats(0.0, 1.0)


def _point(profile, radius_fraction: float, angle_rad: float) -> tuple[float, float]:
    inner, outer = profile.reach_m
    r = inner + radius_fraction * (outer - inner)
    return r * math.cos(angle_rad), r * math.sin(angle_rad)


def _angle_diff(a: float, b: float) -> float:
    return abs(k.wrap_rad(a - b))


@pytest.mark.parametrize("quadrant", sorted(QUADRANTS))
@settings(max_examples=150, deadline=None)
@given(name=profiles, rf=fraction, af=st.floats(0.0, 1.0))
def test_fk_of_each_branch_hits_the_target(quadrant, name, rf, af):
    profile = PROFILES[name]
    lo, hi = QUADRANTS[quadrant]
    x, y = _point(profile, rf, lo + af * (hi - lo))
    branches = k.ik_branches(profile, x, y)
    assert sorted(b.elbow_sign for b in branches) == [-1, 1]
    for sol in branches:
        pose = k.fk(profile, (sol.shoulder_rad, sol.elbow_rad, 0.0, 0.0))
        assert math.hypot(pose.x_m - x, pose.y_m - y) <= POSITION_TOL_M, (sol, pose)
        assert sol.elbow_sign * sol.elbow_rad >= 0.0


@settings(max_examples=300, deadline=None)
@given(name=profiles, rf=fraction, angle=st.floats(-math.pi, math.pi))
def test_ik_returns_exactly_the_branches_within_the_limits(name, rf, angle):
    profile = PROFILES[name]
    (s_lo, s_hi), (e_lo, e_hi) = profile.joint_limits()[:2]
    x, y = _point(profile, rf, angle)
    within = [b for b in k.ik_branches(profile, x, y)
              if s_lo - 1e-12 <= b.shoulder_rad <= s_hi + 1e-12 and e_lo - 1e-12 <= b.elbow_rad <= e_hi + 1e-12]
    if not within:
        with pytest.raises(OutOfReach, match="beyond the joint limits"):
            k.ik(profile, x, y)
        return
    solutions = k.ik(profile, x, y)
    assert solutions == within
    for sol in solutions:
        pose = k.fk(profile, (sol.shoulder_rad, sol.elbow_rad, 0.0, 0.0))
        assert math.hypot(pose.x_m - x, pose.y_m - y) <= POSITION_TOL_M


@settings(max_examples=200, deadline=None)
@given(name=profiles, rf=st.floats(0.01, 0.99), angle=st.floats(-math.pi, math.pi),
       heading=st.floats(-math.pi, math.pi), z_fraction=fraction)
def test_wrist_keeps_the_heading_and_z_sets_the_height(name, rf, angle, heading, z_fraction):
    profile = PROFILES[name]
    x, y = _point(profile, rf, angle)
    try:
        solutions = k.ik(profile, x, y)
    except OutOfReach:
        return  # behind the robot, beyond the shoulder limit: covered above
    z_m = profile.tip_z0_m - z_fraction * profile.z_stroke_m
    q3 = k.z_joint_for_height(profile, z_m)
    assert 0.0 <= q3 <= profile.z_stroke_m
    for sol in solutions:
        q4 = k.wrist_for_heading(profile, sol, heading)
        lo, hi = profile.joint_limits()[3]
        assert lo <= q4 <= hi
        pose = k.fk(profile, (sol.shoulder_rad, sol.elbow_rad, q3, q4))
        assert _angle_diff(pose.heading_rad, heading) <= 1e-12
        assert abs(pose.z_m - z_m) <= 1e-12
        assert math.hypot(pose.x_m - x, pose.y_m - y) <= POSITION_TOL_M


@settings(max_examples=200, deadline=None)
@given(name=profiles, angle=st.floats(-math.pi, math.pi), outside=st.sampled_from(["in", "out"]),
       margin=st.floats(1e-6, 5.0))
def test_unreachable_targets_raise_out_of_reach_naming_target_annulus_and_limits(name, angle, outside, margin):
    profile = PROFILES[name]
    inner, outer = profile.reach_m
    r = outer + margin if outside == "out" else inner * (1.0 - min(margin, 1.0))
    x, y = r * math.cos(angle), r * math.sin(angle)
    with pytest.raises(OutOfReach) as err:
        k.ik(profile, x, y)
    message = str(err.value)
    assert f"({x:.4f}, {y:.4f})" in message
    assert f"reach annulus {inner:.4f}..{outer:.4f} m" in message
    limit_deg = round(math.degrees(profile.shoulder_limit_rad))
    assert f"shoulder -{limit_deg}..{limit_deg} deg" in message
    assert "elbow" in message


def test_out_of_reach_message_for_the_far_point_is_one_clear_line():
    with pytest.raises(OutOfReach) as err:
        k.ik(PROFILES["mtb"], 2.0, 0.0)
    assert str(err.value) == (
        "target (2.0000, 0.0000) m is outside the reach annulus: reach annulus 0.2335..0.8675 m,"
        " shoulder -160..160 deg, elbow -150..150 deg"
    )
    assert err.value.exit_code == 1  # a task that asks for it fails; 3 is only "runs not comparable"


@pytest.mark.parametrize("x, y", [(-0.85, 0.0), (-0.86, 0.01), (-0.86, -0.01)])
def test_behind_the_robot_beyond_the_shoulder_limit_raises(x, y):
    """Straight behind at nearly full reach the shoulder would need about 180 deg (limit 160)."""
    with pytest.raises(OutOfReach, match=r"beyond the joint limits.*shoulder -160\.\.160 deg"):
        k.ik(PROFILES["mtb"], x, y)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_targets_raise(bad):
    with pytest.raises(OutOfReach, match="not a finite point"):
        k.ik(PROFILES["mtb"], bad, 0.3)


@pytest.mark.parametrize("z_m", [0.3, 0.0, -1.0, math.nan])
def test_heights_outside_the_stroke_raise_naming_the_stroke(z_m):
    p = PROFILES["mtb"]
    with pytest.raises(OutOfReach) as err:
        k.z_joint_for_height(p, z_m)
    assert f"pad height {z_m} m" in str(err.value)
    assert f"{p.tip_z0_m - p.z_stroke_m:.4f}..{p.tip_z0_m:.4f} m" in str(err.value)


def test_wrist_beyond_a_narrow_limit_raises():
    from dataclasses import replace

    p = replace(PROFILES["mtb"], wrist_limit_rad=0.5)
    sol = k.ik(p, 0.5, 0.3)[0]
    with pytest.raises(OutOfReach, match="needs wrist"):
        k.wrist_for_heading(p, sol, sol.shoulder_rad + sol.elbow_rad + 1.0)


def test_choose_prefers_the_branch_nearest_the_current_pose():
    p = PROFILES["mtb"]
    sols = k.ik(p, 0.4, 0.4)
    assert {s.elbow_sign for s in sols} == {-1, 1}
    for s in sols:
        assert k.choose(sols, (s.shoulder_rad, s.elbow_rad)) == s
