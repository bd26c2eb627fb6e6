"""Forward and inverse kinematics of the SCARA arm (pure math, no pybullet): the only FK/IK.

Geometry is worked in the base frame: link 1 at angle t1 counter-clockwise from +x, link 2 at
t1 + t2, the pad's heading t1 + t2 + t4, the pad tip at height tip_z0 - z. Joint values are the
profile's own: t1 = shoulder_zero + s1 q1, t2 = s2 q2, t4 = s4 q4, z = s3 q3, with the signs
`axis_signs` (+1: counter-clockwise seen from above, Z positive lowers). The mtb profile has zero
along +x and every sign +1, so there joint values and geometry angles coincide.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from twin.model.errors import OutOfReach
from twin.model.profiles import RobotProfile


class PadPose(NamedTuple):
    """The pad tip in the robot base frame (a NamedTuple: it is computed every physics step)."""

    x_m: float
    y_m: float
    z_m: float
    heading_rad: float


@dataclass(frozen=True)
class ArmSolution:
    """One IK solution in the profile's joint values; `elbow_sign` is +1 or -1 (the two branches:
    the sign of the elbow's joint value)."""

    shoulder_rad: float
    elbow_rad: float
    elbow_sign: int


def wrap_rad(a: float) -> float:
    """Wrap an angle into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def link_angles(profile: RobotProfile, q: tuple[float, ...] | list[float]) -> tuple[float, float]:
    """Directions of link 1 and link 2 (rad, counter-clockwise from +x) for joint values q."""
    s1, s2 = profile.axis_signs[0], profile.axis_signs[1]
    t1 = profile.shoulder_zero_rad + s1 * q[0]
    return t1, t1 + s2 * q[1]


def heading(profile: RobotProfile, q: tuple[float, ...] | list[float]) -> float:
    """The pad's heading (rad, counter-clockwise from +x, not wrapped) for joint values q."""
    return link_angles(profile, q)[1] + profile.axis_signs[3] * q[3]


def elbow_and_wrist_xy(profile: RobotProfile, q) -> tuple[tuple, tuple]:
    """Where the elbow and the wrist axis stand in the plane (m), for joint values q: a tuple, or
    numpy columns (q[j] an array over frames), which give arrays."""
    t1, t12 = link_angles(profile, q)
    ex, ey = profile.link1_m * np.cos(t1), profile.link1_m * np.sin(t1)
    return (ex, ey), (ex + profile.link2_m * np.cos(t12), ey + profile.link2_m * np.sin(t12))


def fk(profile: RobotProfile, q: tuple[float, ...] | list[float]) -> PadPose:
    """Pad tip pose from joint values (shoulder, elbow, z, wrist): pad_pose_function's position and
    heading()'s angle (the same arithmetic, so the same bits, as the twin's Frames)."""
    x_m, y_m, z_m = pad_pose_function(profile)(q)[:3]
    return PadPose(x_m=x_m, y_m=y_m, z_m=z_m, heading_rad=heading(profile, q))


def pad_pose_function(profile: RobotProfile):
    """q -> the pad tip's pose (x, y, z, qx, qy, qz, qw) for joint values q, the pad pointing down
    about z by its heading (half of heading()'s angle in the quaternion): the one statement of the
    arm's forward kinematics, with the profile's numbers bound once; the twin calls it every physics
    step."""
    l1, l2, z0 = profile.link1_m, profile.link2_m, profile.tip_z0_m
    zero = profile.shoulder_zero_rad
    # the signs as floats: an int times a float takes Python's slow path (a call cost 5.3k CPU
    # instructions, now 4.7k: callgrind); the products are the same
    s1, s2, s3, s4 = (float(s) for s in profile.axis_signs)
    cos, sin = math.cos, math.sin

    def pad_pose(q) -> tuple[float, ...]:
        t1 = zero + s1 * q[0]
        t12 = t1 + s2 * q[1]
        half = 0.5 * (t12 + s4 * q[3])
        return (
            l1 * cos(t1) + l2 * cos(t12),
            l1 * sin(t1) + l2 * sin(t12),
            z0 - s3 * q[2],
            0.0,
            0.0,
            sin(half),
            cos(half),
        )

    return pad_pose


def ik_branches(profile: RobotProfile, x_m: float, y_m: float) -> list[ArmSolution]:
    """Both elbow branches reaching (x, y) in the profile's joint values (wrapped into [-pi, pi)),
    ignoring joint limits; [] if outside the outer circle."""
    l1, l2 = profile.link1_m, profile.link2_m
    s1, s2 = profile.axis_signs[0], profile.axis_signs[1]
    r = math.hypot(x_m, y_m)
    c2 = (r * r - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)  # cosine of the elbow's bend
    # 1 + c2 and 1 - c2 as products, not from c2: near a folded or straight arm c2 rounds to -1 or 1
    # and its sine would vanish (a target 2 nm from the base of equal links came back 2 nm off)
    one_plus = (r - abs(l1 - l2)) * (r + abs(l1 - l2)) / (2.0 * l1 * l2)
    one_minus = (l1 + l2 - r) * (l1 + l2 + r) / (2.0 * l1 * l2)
    if one_minus < -1e-12 or one_plus < -1e-12:
        return []
    c2 = min(1.0, max(-1.0, c2))
    s2_abs = math.sqrt(max(0.0, one_plus * one_minus))
    out = []
    for sign in (1, -1):  # the sign of the elbow's joint value
        bend = math.atan2(sign * s2 * s2_abs, c2)  # the elbow's geometric angle on this branch
        t1 = math.atan2(y_m, x_m) - math.atan2(l2 * math.sin(bend), l1 + l2 * math.cos(bend))
        out.append(ArmSolution(wrap_rad(s1 * (t1 - profile.shoulder_zero_rad)), s2 * bend, sign))
    return out


def _within(value: float, limits: tuple[float, float]) -> bool:
    return limits[0] - 1e-12 <= value <= limits[1] + 1e-12


def _reach_text(profile: RobotProfile) -> str:
    inner, outer = profile.reach_m
    if profile.revolute_cyclic:
        return f"reach annulus {inner:.4f}..{outer:.4f} m (cyclic joints)"
    (s_lo, s_hi), (e_lo, e_hi) = profile.joint_limits()[:2]
    return (
        f"reach annulus {inner:.4f}..{outer:.4f} m, shoulder "
        f"{math.degrees(s_lo):.0f}..{math.degrees(s_hi):.0f} deg,"
        f" elbow {math.degrees(e_lo):.0f}..{math.degrees(e_hi):.0f} deg"
    )


def ik(profile: RobotProfile, x_m: float, y_m: float) -> list[ArmSolution]:
    """The IK solutions for (x, y) that respect the joint limits; raises OutOfReach if none."""
    if not (math.isfinite(x_m) and math.isfinite(y_m)):
        raise OutOfReach(f"target ({x_m}, {y_m}) is not a finite point; {_reach_text(profile)}")
    limits = profile.joint_limits()
    branches = ik_branches(profile, x_m, y_m)
    if profile.revolute_cyclic:
        inner = profile.reach_m[0]
        valid = branches if math.hypot(x_m, y_m) >= inner - 1e-12 else []
    else:
        valid = [
            s
            for s in branches
            if _within(s.shoulder_rad, limits[0]) and _within(s.elbow_rad, limits[1])
        ]
    if not valid:
        why = (
            "outside the reach annulus"
            if not branches or profile.revolute_cyclic
            else "beyond the joint limits"
        )
        raise OutOfReach(f"target ({x_m:.4f}, {y_m:.4f}) m is {why}: {_reach_text(profile)}")
    return valid


def choose(solutions: list[ArmSolution], current: tuple[float, float]) -> ArmSolution:
    """The solution nearest the current (shoulder, elbow); ties go to the +1 branch."""
    return min(
        solutions,
        key=lambda s: (
            abs(s.shoulder_rad - current[0]) + abs(s.elbow_rad - current[1]),
            -s.elbow_sign,
        ),
    )


def wrist_for_heading(profile: RobotProfile, sol: ArmSolution, heading_rad: float) -> float:
    """Wrist joint value that keeps the pad at `heading_rad`, wrapped into the wrist's range."""
    _t1, t12 = link_angles(profile, (sol.shoulder_rad, sol.elbow_rad, 0.0, 0.0))
    q4 = wrap_rad(profile.axis_signs[3] * (heading_rad - t12))
    lo, hi = profile.joint_limits()[3]
    if not _within(q4, (lo, hi)):
        raise OutOfReach(
            f"heading {heading_rad:.4f} rad needs wrist {q4:.4f} rad, outside "
            f"{lo:.4f}..{hi:.4f} rad"
        )
    return q4


def z_joint_for_height(profile: RobotProfile, z_m: float) -> float:
    """Z joint value that puts the pad tip at height z_m; raises OutOfReach outside the stroke."""
    q3 = profile.axis_signs[2] * (profile.tip_z0_m - z_m)
    lo, hi = profile.joint_limits()[2]
    if not (math.isfinite(q3) and lo - 1e-12 <= q3 <= hi + 1e-12):
        heights = sorted(profile.tip_z0_m - profile.axis_signs[2] * v for v in (lo, hi))
        raise OutOfReach(
            f"pad height {z_m} m is outside the Z stroke: {heights[0]:.4f}..{heights[1]:.4f} m"
        )
    return min(hi, max(lo, q3))
