"""Report 002's step-4 Lua program (threaded child script), translated statement by statement.

Its own IK `moving(x, y)` as written (the triangle-area IK of report 001 with 0.5 m links, the
same two bugs: height area/(2c), atan(x/y) with +pi only for x, y < 0): the pad stops 26 cm from
the box at (0.2, 0.7), so the recording shows the miss (`suction_empty`, the box unmoved). Targets
as the report set them: AB = deg1, BC = -deg2, CD = deg3, Z -0.09 (down) and 0 (up), signal
pad_switch; `sim.wait(t)` with t = 3 s is `twin.wait(t)`. The script has no loop: it runs once
to its end. Run it on the seed002 profile (docs/seed-conventions.md).
"""

from __future__ import annotations

import math


def moving(twin, x: float, y: float) -> None:
    """The report's moving(x, y)."""
    a = 0.5
    b = 0.5
    c = math.pow((math.pow(x, 2) + math.pow(y, 2)), 0.5)
    s = (a + b + c) / 2
    area = math.pow((s * (s - a) * (s - b) * (s - c)), 0.5)
    h = area / (2 * c)
    deg1_base = math.atan(x / y)
    if x < 0 and y < 0:
        deg1_base = deg1_base + math.pi
    deg1_tri = math.asin(h / a)
    deg1 = deg1_base + deg1_tri
    deg2 = math.pi - (0.5 * math.pi - deg1_tri) - math.acos(h / b)
    deg3 = deg2 - deg1
    twin.set_joint_target("AB", deg1)
    twin.set_joint_target("BC", -deg2)
    twin.set_joint_target("CD", deg3)


def run(twin) -> None:
    """sysCall_threadmain, once."""
    t = 3
    twin.set_joint_target("AB", 0)
    twin.set_joint_target("BC", 0)
    twin.set_joint_target("CD", 0)
    twin.set_joint_target("Z", 0)
    twin.wait(t)
    twin.set_signal("pad_switch", 1)
    twin.set_joint_target("Z", -0.09)
    twin.wait(t)
    twin.set_joint_target("Z", 0)
    twin.wait(t)
    moving(twin, 0.2, 0.7)
    twin.wait(t)
    twin.set_signal("pad_switch", 0)
    twin.wait(t)
    twin.set_signal("pad_switch", 1)
    twin.wait(t)
    twin.set_joint_target("Z", -0.09)
    twin.wait(t)
    twin.set_joint_target("Z", 0)
    twin.wait(t)
    moving(twin, -0.3, -0.55)
    twin.wait(t)
    twin.set_signal("pad_switch", 0)
    twin.wait(t)  # the simulation runs on after the script ends: the last switch-off shows in the recording
