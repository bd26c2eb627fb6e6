"""Forward and inverse kinematics of the SCARA arm (pure math, no pybullet).

Conventions: shoulder angle q1 and elbow angle q2 about +z, zero along +x; the Z joint q3 lowers
the pad (positive down); the wrist q4 about +z. The pad's heading is q1 + q2 + q4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from twin.errors import OutOfReach
from twin.profiles import RobotProfile


class PadPose(NamedTuple):
    """The pad tip in the robot base frame (a NamedTuple: it is computed every physics step)."""

    x_m: float
    y_m: float
    z_m: float
    heading_rad: float


@dataclass(frozen=True)
class ArmSolution:
    """One IK solution; `elbow_sign` is +1 or -1 (the two branches)."""

    shoulder_rad: float
    elbow_rad: float
    elbow_sign: int


def wrap_rad(a: float) -> float:
    """Wrap an angle into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def fk(profile: RobotProfile, q: tuple[float, ...] | list[float]) -> PadPose:
    """Pad tip pose from joint values (shoulder, elbow, z, wrist)."""
    q1, q2, q3, q4 = q[0], q[1], q[2], q[3]
    l1, l2 = profile.link1_m, profile.link2_m
    return PadPose(
        x_m=l1 * math.cos(q1) + l2 * math.cos(q1 + q2),
        y_m=l1 * math.sin(q1) + l2 * math.sin(q1 + q2),
        z_m=profile.tip_z0_m - q3,
        heading_rad=q1 + q2 + q4,
    )


def ik_branches(profile: RobotProfile, x_m: float, y_m: float) -> list[ArmSolution]:
    """Both elbow branches reaching (x, y), ignoring joint limits; [] if outside the outer circle."""
    l1, l2 = profile.link1_m, profile.link2_m
    r2 = x_m * x_m + y_m * y_m
    c2 = (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    if c2 > 1.0 + 1e-12 or c2 < -1.0 - 1e-12:
        return []
    c2 = min(1.0, max(-1.0, c2))
    s2_abs = math.sqrt(max(0.0, 1.0 - c2 * c2))
    out = []
    for sign in (1, -1):
        s2 = sign * s2_abs
        q2 = math.atan2(s2, c2)
        q1 = wrap_rad(math.atan2(y_m, x_m) - math.atan2(l2 * s2, l1 + l2 * c2))
        out.append(ArmSolution(q1, q2, sign))
    return out


def _within(value: float, limits: tuple[float, float]) -> bool:
    return limits[0] - 1e-12 <= value <= limits[1] + 1e-12


def _reach_text(profile: RobotProfile) -> str:
    inner, outer = profile.reach_m
    (s_lo, s_hi), (e_lo, e_hi) = profile.joint_limits()[:2]
    return (
        f"reach annulus {inner:.4f}..{outer:.4f} m, shoulder {math.degrees(s_lo):.0f}..{math.degrees(s_hi):.0f} deg,"
        f" elbow {math.degrees(e_lo):.0f}..{math.degrees(e_hi):.0f} deg"
    )


def ik(profile: RobotProfile, x_m: float, y_m: float) -> list[ArmSolution]:
    """The IK solutions for (x, y) that respect the joint limits; raises OutOfReach if none."""
    if not (math.isfinite(x_m) and math.isfinite(y_m)):
        raise OutOfReach(f"target ({x_m}, {y_m}) is not a finite point; {_reach_text(profile)}")
    limits = profile.joint_limits()
    branches = ik_branches(profile, x_m, y_m)
    valid = [s for s in branches if _within(s.shoulder_rad, limits[0]) and _within(s.elbow_rad, limits[1])]
    if not valid:
        why = "outside the reach annulus" if not branches else "beyond the joint limits"
        raise OutOfReach(f"target ({x_m:.4f}, {y_m:.4f}) m is {why}: {_reach_text(profile)}")
    return valid


def choose(solutions: list[ArmSolution], current: tuple[float, float]) -> ArmSolution:
    """The solution nearest the current (shoulder, elbow); ties go to the +1 branch."""
    return min(
        solutions,
        key=lambda s: (abs(s.shoulder_rad - current[0]) + abs(s.elbow_rad - current[1]), -s.elbow_sign),
    )


def wrist_for_heading(profile: RobotProfile, sol: ArmSolution, heading_rad: float) -> float:
    """Wrist angle that keeps the pad at `heading_rad`, wrapped into the wrist's range."""
    q4 = wrap_rad(heading_rad - sol.shoulder_rad - sol.elbow_rad)
    lo, hi = profile.joint_limits()[3]
    if not _within(q4, (lo, hi)):
        raise OutOfReach(
            f"heading {heading_rad:.4f} rad needs wrist {q4:.4f} rad, outside {lo:.4f}..{hi:.4f} rad"
        )
    return q4


def z_joint_for_height(profile: RobotProfile, z_m: float) -> float:
    """Z joint value that puts the pad tip at height z_m; raises OutOfReach outside the stroke."""
    q3 = profile.tip_z0_m - z_m
    if not (math.isfinite(q3) and -1e-12 <= q3 <= profile.z_stroke_m + 1e-12):
        lowest = profile.tip_z0_m - profile.z_stroke_m
        raise OutOfReach(f"pad height {z_m} m is outside the Z stroke: {lowest:.4f}..{profile.tip_z0_m:.4f} m")
    return min(profile.z_stroke_m, max(0.0, q3))
