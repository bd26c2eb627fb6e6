"""The seeds' pick-and-place loop: a box shuttled between (0.2, 0.7) and (-0.3, -0.55).

Like the seeds, the task has no camera: each cycle picks at the fixed point where the previous
cycle put the box, so whatever offset a placement leaves is carried into every later cycle. Two
habits keep that offset from growing: the pad stops at the height where it took hold of the box
(driving on to the end of the Z stroke would press the held box into the floor and shove it
sideways), and it sets the box down at that same height. A pick that holds nothing, a box lost on
the way, or a placement beyond `max_error_m` fails the task at once, naming the cycle, unless
`keep_going` is set (then it is an Event and the loop goes on).
"""

from __future__ import annotations

import math

from twin.model.errors import TaskError
from twin.model.types import NO_BODY

POINT_A_M = (0.2, 0.7)
POINT_B_M = (-0.3, -0.55)
SAFE_POINT_M = (0.5, 0.0)
MAX_ERROR_M = 0.002
Z_JOINT = 2  # role order: shoulder, elbow, z, wrist
DOWN_TOL_M = 2e-4  # the pad is down (at the profile's z_down) and still holds nothing
LOWER_TIMEOUT_S = 10.0


def run(twin, cycles: int = 2, pause_s: float = 0.5, box: str = "box", keep_going: bool = False,
        max_error_m: float = MAX_ERROR_M) -> None:
    """Each cycle picks the box at one point and places it on the other; see the module docstring."""
    if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 1:
        raise ValueError(f"cycles {cycles!r} is invalid; expected an integer >= 1")
    box_index = twin.object_index(box)
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
        hold_z, took_hold = _lower_until_held(twin)
        twin.wait(pause_s)
        held = twin.frame.held_body
        if held != box_index:
            twin.suction(False)
            twin.raise_()
            what = (f"held {_name(twin, held)!r} instead of {box!r}" if held != NO_BODY
                    else "the hold broke" if took_hold else "nothing sensed")
            _miss(twin, keep_going, cycle, box, f"cycle {cycle}: suction on at {pick}, {what}")
            continue
        twin.raise_()
        twin.phase(f"cycle {cycle}: place at {place}")
        twin.move_to(*place)
        twin.set_joint_target(Z_JOINT, hold_z)  # the box's bottom where it stood when picked: on the floor
        twin.settle()
        if twin.frame.held_body != box_index:
            twin.suction(False)
            twin.raise_()
            _miss(twin, keep_going, cycle, box, f"cycle {cycle}: {box!r} was lost on the way to {place}")
            continue
        twin.suction(False)
        twin.wait(pause_s)
        twin.raise_()
        pose = twin.object_pose(box)
        error_m = math.hypot(pose[0] - place[0], pose[1] - place[1])
        yaw_rad = 2.0 * math.atan2(pose[5], pose[6])  # the box stays flat: its turn about z
        twin.event("placed", box, f"cycle {cycle}: placed {error_m * 1000:.3f} mm from {place}",
                   cycle=cycle, target_m=list(place), error_m=error_m, yaw_rad=yaw_rad)
        if error_m > max_error_m:
            _miss(twin, keep_going, cycle, box, f"cycle {cycle}: placed {mm_beyond(error_m, max_error_m)} mm "
                  f"from {place}, beyond {max_error_m * 1000:g} mm")


def mm_beyond(error_m: float, limit_m: float) -> str:
    """error_m in mm with as many decimals (3 at least) as it takes to read larger than limit_m."""
    for decimals in range(3, 10):
        text = f"{error_m * 1000:.{decimals}f}"
        if float(text) > limit_m * 1000:
            return text
    return f"{error_m * 1000!r}"


def _lower_until_held(twin) -> tuple[float, bool]:
    """Lower the pad as `twin.lower()` does until it holds something (or gets there); returns the Z
    joint value it stops at and whether it took hold. On a hold the Z joint goes back to where it was when the hold was made
    (the step that attached the box also moved the pad on by up to 2 mm, pressing the box into the
    floor)."""
    down = twin.profile.z_down()
    twin.set_joint_target(Z_JOINT, down)
    stop_z, took_hold = down, False
    for _ in range(round(LOWER_TIMEOUT_S / twin.config.dt_s)):
        before_z = twin.frame.joint_q[Z_JOINT]
        if abs(before_z - down) <= DOWN_TOL_M:
            break
        twin.step()
        if twin.frame.held_body != NO_BODY:
            stop_z, took_hold = before_z, True
            twin.set_joint_target(Z_JOINT, stop_z)
            break
    twin.settle()
    return stop_z, took_hold


def _miss(twin, keep_going: bool, cycle: int, box: str, message: str) -> None:
    """A failed cycle: an Event when the task goes on, else the task fails with this message."""
    if not keep_going:
        raise TaskError(message)
    twin.event("cycle_failed", box, message, cycle=cycle)


def _name(twin, index: int) -> str:
    return twin.config.objects[index].name
