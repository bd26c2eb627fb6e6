"""Report 000's step-4 Lua pick-and-place loop (threaded child script), translated statement by statement.

The report's lines, in order: its own `round` and `ik` (the atan2/acos IK returning degrees rounded to
4 places, called with the axes swapped: `ik(0.7, 0.2)` for the box at (0.2, 0.7)), joint1 = -q1 and
joint2 = q2 as targets, `sim.wait(t)` as `twin.wait(t)`, joint3 = 0.06 (the pad on the box) and
-0.06 (12 cm up), and the suction pad's script parameter `active` ('ture' switches it on: any string
is true in Lua) as the profile's suction signal. Each pass of the report's `while(true)` loop places
the box at (-0.3, -0.55), picks it up again there and places it back at (0.2, 0.7); `cycles` bounds
the loop by carries (each one place, as for the other tasks): 1 ends with the box at (-0.3, -0.55),
after the raise that follows that place; 2 is one whole pass.
The task adds only what the report's scene showed its author: a `placed` event after each release.
Run it on the seed000 profile, whose joint conventions are that scene's (docs/seed-conventions.md).
"""

from __future__ import annotations

import math

A1_M = 0.8  # 手臂長度1 (link 1)
A2_M = 0.8  # 手臂長度2 (link 2)
DEG = 180 / math.pi  # radian to degree
ANGLE1 = math.pi / 180  # the script's `angle1`: degrees to radians


def lua_round(x: float, n: int = 0) -> float:
    """The report's round(x, n): half away from zero (Lua's floor/ceil, not Python's banker's round)."""
    scale = math.pow(10, n)
    x = x * scale
    x = math.floor(x + 0.5) if x >= 0 else math.ceil(x - 0.5)
    return x / scale


def ik(twin, x: float, y: float):
    """The report's ik(x, y): [q1, q2] in degrees, or None (and "Over range!") outside the reach circle."""
    if (x**2 + y**2) <= (A1_M + A2_M) ** 2:
        q2 = -math.acos((x**2 + y**2 - A1_M**2 - A2_M**2) / (2 * A1_M * A2_M))
        q1 = math.atan2(y, x) + math.atan2((A2_M * math.sin(q2)), (A1_M + A2_M * math.cos(q2)))
        return [lua_round(q1 * DEG, 4), lua_round(q2 * DEG, 4)]
    twin.event("print", message="Over range!")
    return None


def _placed(twin, box: str, place: tuple[float, float], n: int) -> None:
    pose = twin.object_pose(box)
    error_m = math.hypot(pose[0] - place[0], pose[1] - place[1])
    twin.event("placed", box, f"release {n}: placed {error_m * 1000:.3f} mm from {place}",
               release=n, target_m=list(place), error_m=error_m)


def run(twin, cycles: int = 1, box: str = "box") -> None:
    """The report's loop, up to `cycles` carries (A to B, B to A, A to B, ...)."""
    if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 1:
        raise ValueError(f"cycles {cycles!r} is invalid; expected an integer >= 1")
    joint_hanld1, joint_hanld2, joint_hanld3 = "joint1", "joint2", "joint3"
    theta = ik(twin, 0.7, 0.2)
    twin.event("print", message=f"{theta[0]}\t{theta[1]}")
    twin.set_joint_target(joint_hanld1, -theta[0] * ANGLE1)
    twin.set_joint_target(joint_hanld2, theta[1] * ANGLE1)
    twin.wait(3)
    releases = 0
    while releases < cycles:  # (0.2,0.7,0) 和 (-0.3,-0.55,0) 來回取放: while(true)
        twin.wait(3)
        twin.set_joint_target(joint_hanld3, 0.06)
        twin.wait(3)
        twin.suction(True)  # setScriptSimulationParameter(..., 'active', 'ture')
        twin.wait(3)
        twin.set_joint_target(joint_hanld3, -0.06)
        twin.wait(3)
        theta = ik(twin, -0.55, -0.3)
        twin.wait(3)
        twin.set_joint_target(joint_hanld1, -theta[0] * ANGLE1)
        twin.set_joint_target(joint_hanld2, theta[1] * ANGLE1)
        twin.wait(10)
        twin.set_joint_target(joint_hanld3, 0.06)
        twin.wait(3)
        twin.suction(False)  # 'active', 'false'
        releases += 1
        twin.wait(3)
        _placed(twin, box, (-0.3, -0.55), releases)
        twin.set_joint_target(joint_hanld3, -0.06)
        if releases == cycles:  # the bound: the raise after this place ends the run (the wait below)
            break
        twin.wait(3)
        twin.suction(True)  # 'active', 'ture'
        twin.wait(3)
        twin.set_joint_target(joint_hanld3, 0.06)
        twin.wait(3)
        twin.set_joint_target(joint_hanld3, -0.06)
        twin.wait(3)
        theta = ik(twin, 0.7, 0.2)
        twin.set_joint_target(joint_hanld1, -theta[0] * ANGLE1)
        twin.set_joint_target(joint_hanld2, theta[1] * ANGLE1)
        twin.wait(10)
        twin.set_joint_target(joint_hanld3, 0.06)
        twin.wait(3)
        twin.suction(False)  # 'active', 'false'
        releases += 1
        twin.wait(3)
        _placed(twin, box, (0.2, 0.7), releases)
        twin.set_joint_target(joint_hanld3, -0.06)
    twin.wait(3)  # the wait that opens the next pass: the last raise ends before the run does
