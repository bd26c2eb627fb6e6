"""Kinematics properties over the whole workspace of every built-in profile (pure math, no
physics)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twin.model.errors import OutOfReach
from twin.model.profiles import PROFILES
from twin.robot import kinematics as k

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
    within = [
        b
        for b in k.ik_branches(profile, x, y)
        if s_lo - 1e-12 <= b.shoulder_rad <= s_hi + 1e-12
        and e_lo - 1e-12 <= b.elbow_rad <= e_hi + 1e-12
    ]
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
@given(
    name=profiles,
    rf=st.floats(0.01, 0.99),
    angle=st.floats(-math.pi, math.pi),
    heading=st.floats(-math.pi, math.pi),
    z_fraction=fraction,
)
def test_wrist_keeps_the_heading_and_z_sets_the_height(name, rf, angle, heading, z_fraction):
    profile = PROFILES[name]
    x, y = _point(profile, rf, angle)
    try:
        solutions = k.ik(profile, x, y)
    except OutOfReach:
        return  # behind the robot, beyond the shoulder limit: covered above
    z_lo, z_hi = profile.joint_limits()[2]
    z_m = profile.tip_z0_m - profile.axis_signs[2] * (z_lo + z_fraction * (z_hi - z_lo))
    q3 = k.z_joint_for_height(profile, z_m)
    assert z_lo - 1e-12 <= q3 <= z_hi + 1e-12
    for sol in solutions:
        q4 = k.wrist_for_heading(profile, sol, heading)
        lo, hi = profile.joint_limits()[3]
        assert lo <= q4 <= hi
        pose = k.fk(profile, (sol.shoulder_rad, sol.elbow_rad, q3, q4))
        assert _angle_diff(pose.heading_rad, heading) <= 1e-12
        assert abs(pose.z_m - z_m) <= 1e-12
        assert math.hypot(pose.x_m - x, pose.y_m - y) <= POSITION_TOL_M


@settings(max_examples=200, deadline=None)
@given(
    name=profiles,
    angle=st.floats(-math.pi, math.pi),
    outside=st.sampled_from(["in", "out"]),
    margin=st.floats(1e-6, 5.0),
)
def test_unreachable_targets_raise_out_of_reach_naming_target_annulus_and_limits(
    name, angle, outside, margin
):
    profile = PROFILES[name]
    inner, outer = profile.reach_m
    if outside == "in" and inner == 0.0:
        return  # equal links on cyclic joints fold onto the shoulder: nothing inside is unreachable
    r = outer + margin if outside == "out" else inner * (1.0 - min(margin, 1.0))
    x, y = r * math.cos(angle), r * math.sin(angle)
    with pytest.raises(OutOfReach) as err:
        k.ik(profile, x, y)
    message = str(err.value)
    assert f"({x:.4f}, {y:.4f})" in message
    assert f"reach annulus {inner:.4f}..{outer:.4f} m" in message
    if profile.revolute_cyclic:
        assert "cyclic joints" in message
        return
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
    # a task that asks for it fails; 3 is only "runs not comparable"
    assert err.value.exit_code == 1


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


# -- each report's own joint conventions (docs/seed-conventions.md) --------------------------------


def _report000_ik(x, y):
    """Report 000's ik(x, y) (links 0.8/0.8): degrees, q2 = -acos(...), q1 = atan2(y, x) +
    atan2(...)."""
    q2 = -math.acos((x**2 + y**2 - 0.8**2 - 0.8**2) / (2 * 0.8 * 0.8))
    q1 = math.atan2(y, x) + math.atan2(0.8 * math.sin(q2), 0.8 + 0.8 * math.cos(q2))
    return round(math.degrees(q1), 4), round(math.degrees(q2), 4)


@pytest.mark.parametrize("box", [(0.2, 0.7), (-0.3, -0.55)])
def test_report000_program_lands_on_its_box_in_the_seed000_frame(box):
    """The report calls ik(y, x) and sends joint1 = -q1, joint2 = q2: seed000's frame makes that
    exact."""
    q1, q2 = _report000_ik(box[1], box[0])
    pose = k.fk(PROFILES["seed000"], (math.radians(-q1), math.radians(q2), 0.06, 0.0))
    assert math.hypot(pose.x_m - box[0], pose.y_m - box[1]) < 1e-5  # the 4-place rounding
    assert pose.z_m == pytest.approx(0.055)  # 5 mm over the 50 mm box: within the pad's sensor


def _heron(x, y, a, b):
    """Reports 001/002's triangle-area IK as written (h = area / (2c), atan(x / y))."""
    c = math.pow(x * x + y * y, 0.5)
    s = (a + b + c) * 0.5
    h = math.pow(s * (s - a) * (s - b) * (s - c), 0.5) / (2 * c)
    base = math.atan(x / y) + (math.pi if x < 0 and y < 0 else 0.0)
    tri = math.asin(h / a)
    deg2 = math.pi - (0.5 * math.pi - tri) - math.acos(h / b)
    return base + tri, deg2, deg2 - (base + tri)


@pytest.mark.parametrize(
    "name, links, miss_m", [("seed001", (0.467, 0.401), 0.1319), ("seed002", (0.5, 0.5), 0.2572)]
)
def test_heron_ik_misses_the_box_in_its_own_frame_and_keeps_the_heading(name, links, miss_m):
    profile = PROFILES[name]
    deg1, deg2, deg3 = _heron(0.2, 0.7, *links)
    pose = k.fk(profile, (deg1, -deg2, profile.z_down(), deg3))
    assert math.hypot(pose.x_m - 0.2, pose.y_m - 0.7) == pytest.approx(miss_m, abs=1e-4)
    # wrist = deg2 - deg1
    assert k.wrap_rad(pose.heading_rad - math.pi / 2) == pytest.approx(0.0, abs=1e-12)
    straight = k.fk(profile, (0.0, 0.0, 0.0, 0.0))  # moving(0, 0.868): the arm along +y
    assert (straight.x_m, straight.y_m) == pytest.approx((0.0, sum(links)))


def test_report003_ik_is_the_mtb_frame():
    """Report 003's ik(0.2, 0.7) (q2 = +acos, q1 = atan2 - atan2) lands on the box in the MTB
    frame."""
    a1, a2 = 0.468, 0.4
    q2 = math.acos((0.2**2 + 0.7**2 - a1**2 - a2**2) / (2 * a1 * a2))
    q1 = math.atan2(0.7, 0.2) - math.atan2(a2 * math.sin(q2), a1 + a2 * math.cos(q2))
    pose = k.fk(PROFILES["seed003"], (q1, q2, 0.0, 0.0))
    assert (pose.x_m, pose.y_m) == pytest.approx((0.2, 0.7), abs=1e-12)


@pytest.mark.parametrize(
    "name, down, up",
    [
        ("seed000", 0.06, -0.06),
        ("seed001", -0.055, 0.0),
        ("seed002", -0.09, 0.0),
        ("mtb", 0.2, 0.0),
    ],
)
def test_each_scene_s_down_puts_the_pad_on_a_50_mm_box(name, down, up):
    profile = PROFILES[name]
    assert (profile.z_down(), profile.z_up()) == (down, up)
    assert k.fk(profile, (0.0, 0.0, down, 0.0)).z_m == pytest.approx(0.055)
    assert k.fk(profile, (0.0, 0.0, up, 0.0)).z_m > 0.1


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(sorted(PROFILES)), q=st.tuples(*[st.floats(-7.0, 7.0)] * 4))
def test_the_per_step_pad_pose_is_fk_bit_for_bit(name, q):
    """The twin's per-step pad pose (pad_pose_function) and fk give the same bits: recordings depend
    on it."""
    profile = PROFILES[name]
    pose = k.fk(profile, q)
    half = 0.5 * pose.heading_rad
    assert k.pad_pose_function(profile)(q) == (
        pose.x_m,
        pose.y_m,
        pose.z_m,
        0.0,
        0.0,
        math.sin(half),
        math.cos(half),
    )
