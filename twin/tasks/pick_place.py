"""The seeds' pick-and-place loop: a box shuttled between (0.2, 0.7) and (-0.3, -0.55)."""

from __future__ import annotations

import math

POINT_A_M = (0.2, 0.7)
POINT_B_M = (-0.3, -0.55)
SAFE_POINT_M = (0.5, 0.0)


def run(twin, cycles: int = 2, pause_s: float = 0.5, box: str = "box") -> None:
    """Each cycle picks the box where it stands and places it on the other point."""
    if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 1:
        raise ValueError(f"cycles {cycles!r} is invalid; expected an integer >= 1")
    twin.phase("safe pose")
    twin.suction(False)
    twin.raise_()
    twin.move_to(*SAFE_POINT_M, heading_rad=0.0)
    for cycle in range(1, cycles + 1):
        pick, place = (POINT_A_M, POINT_B_M) if cycle % 2 else (POINT_B_M, POINT_A_M)
        twin.phase(f"cycle {cycle}: pick at {pick}")
        twin.move_to(*pick)
        twin.wait(pause_s)
        twin.suction(True)
        twin.lower()
        twin.wait(pause_s)
        twin.raise_()
        twin.phase(f"cycle {cycle}: place at {place}")
        twin.move_to(*place)
        twin.lower()
        twin.suction(False)
        twin.wait(pause_s)
        twin.raise_()
        pose = twin.object_pose(box)
        error_m = math.hypot(pose[0] - place[0], pose[1] - place[1])
        twin.event("placed", box, f"cycle {cycle}: placed {error_m * 1000:.2f} mm from {place}",
                   cycle=cycle, target_m=list(place), error_m=error_m)
