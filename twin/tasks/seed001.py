"""Report 001's step-4 Lua program (threaded child script), translated statement by statement.

Its own IK `moving(x, y)` as written, bugs included: the triangle's height is area/(2c) (should be
2*area/c) and the base angle atan(x/y) gets +pi only when x and y are both negative. So the pad
stops 13 cm from the box at (0.2, 0.7) and the recording shows the miss (`suction_empty`, the box
unmoved). Targets as the report set them: Revolute_joint = deg1, Revolute_joint1 = -deg2, the wrist
Revolute_joint0 = deg3, Prismatic_joint -0.055 (down) and 0 (up), signal pad_switch; `sim.wait(t)`
with t = 5 s is `twin.wait(t)`. Its loop runs while the simulation state differs from
`sim.simulation_advancing_abouttostopre` (a misspelt constant: nil, so it never ends); `cycles`
bounds it. Run it on the seed001 profile, whose joint conventions are that scene's
(docs/seed-conventions.md).
"""

from __future__ import annotations

import math


def moving(twin, x: float, y: float) -> None:
    """The report's moving(x, y): Heron's-formula IK, then the three arm targets."""
    a = 0.467
    b = 0.401
    c = math.pow(math.pow(x, 2) + math.pow(y, 2), 0.5)
    s = (a + b + c) * 0.5
    area = math.pow((s * (s - a) * (s - b) * (s - c)), 0.5)
    h = area / (2 * c)
    deg1_base = math.atan(x / y)
    if x < 0 and y < 0:
        deg1_base = deg1_base + math.pi
    deg1_tri = math.asin(h / a)
    deg1 = deg1_base + deg1_tri
    deg2 = math.pi - (0.5 * math.pi - deg1_tri) - math.acos(h / b)
    deg3 = deg2 - deg1
    twin.event("print", message=repr(deg3))
    twin.set_joint_target("Revolute_joint", deg1)
    twin.set_joint_target("Revolute_joint1", -deg2)
    twin.set_joint_target("Revolute_joint0", deg3)


def pick_and_place(twin, x: float, y: float, t: float) -> None:
    """The report's pick_and_place(x, y)."""
    twin.set_signal("pad_switch", 0)
    twin.wait(t)
    moving(twin, 0, 0.868)
    twin.wait(t)
    moving(twin, x, y)
    twin.wait(t)
    twin.set_signal("pad_switch", 1)
    twin.set_joint_target("Prismatic_joint", -0.055)
    twin.wait(t)
    twin.set_joint_target("Prismatic_joint", 0)
    twin.wait(t)


def run(twin, cycles: int = 1) -> None:
    """sysCall_threadmain, its endless loop bounded to `cycles` passes (each: A, then B)."""
    if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 1:
        raise ValueError(f"cycles {cycles!r} is invalid; expected an integer >= 1")
    t = 5
    twin.set_joint_target("Revolute_joint", 0)
    twin.set_joint_target("Revolute_joint1", 0)
    twin.set_joint_target("Revolute_joint0", 0)
    twin.set_signal("pad_switch", 1)
    twin.set_joint_target("Prismatic_joint", -0.055)
    twin.wait(t)
    twin.set_joint_target("Prismatic_joint", 0)
    twin.wait(t)
    for _ in range(cycles):  # while sim.getSimulationState() ~= sim.simulation_advancing_abouttostopre
        x = 0.2
        y = 0.7
        moving(twin, x, y)
        twin.wait(t)
        pick_and_place(twin, x, y, t)
        x = -0.3
        y = -0.55
        moving(twin, x, y)
        twin.wait(t)
        pick_and_place(twin, x, y, t)
