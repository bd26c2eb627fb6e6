"""Key plans for teleop tests: each built-in key map's jog keys, and the whole-degree key-grid
points for a pick and a place chosen from the kinematics (the teleop and tmux tests drive the same
plan)."""

from __future__ import annotations

import math

from twin.model.profiles import PROFILES
from twin.robot.kinematics import fk, ik
from twin.tasks.pick_place import POINT_A_M, POINT_B_M

# Per seed map: the keys for shoulder +1/-1 deg, elbow +1/-1 deg, and the pick/place key sequences
# (with `wait` intervals for the Z stroke, 0.2 m at 0.5 m/s, when keys come every 0.1 s, the teleop
# tests' interval).
Z_WAIT = ["wait"] * 6
MAPS = {
    # report 000's Lua: joints set at once; 8 = suction on and Z up to its count, 5 = Z to the stop
    "seed000": {
        "jog": ("d", "a", "e", "q"),
        "pick": ["8", "5", "8"],
        "place": ["5", "s", "8"],
        "keeps_heading": False,
    },
    # report 001's Lua: the wrist follows deg2 - deg1, so the pad does not keep its heading
    "seed001": {
        "jog": ("left", "right", "up", "down"),
        "pick": ["3", *Z_WAIT, "4", *Z_WAIT],
        "place": ["3", *Z_WAIT, "5", "4"],
        "keeps_heading": False,
    },
}


def _pad_xy_heading(profile, deg, wrist_deg=0.0):
    """Pad (x, y) and heading on the key grid (whole degrees), the wrist at wrist_deg."""
    q1, q2 = math.radians(deg[0]), math.radians(deg[1])
    p = fk(profile, (q1, q2, 0.0, math.radians(wrist_deg)))
    return (p.x_m, p.y_m), p.heading_rad


def _wrist_deg(profile_name, frm, to, before=0.0):
    """Where report 001's map leaves the wrist after the jog keys from frm to to (shoulder keys
    first, then elbow keys): deg2 - deg1 after a left/right key, deg1 - deg2 after up/down; 0 for
    seed000."""
    if profile_name != "seed001":
        return 0.0
    if to[1] != frm[1]:
        return to[0] - to[1]
    return to[1] - to[0] if to[0] != frm[0] else before


def _grid_points(profile, target_m, span_deg=3):
    """Whole-degree (shoulder, elbow) pairs around each IK branch for target_m, within the joint
    limits."""
    lim = [tuple(math.degrees(v) for v in pair) for pair in profile.joint_limits()[:2]]
    for sol in ik(profile, *target_m):
        c1, c2 = round(math.degrees(sol.shoulder_rad)), round(math.degrees(sol.elbow_rad))
        for a in range(c1 - span_deg, c1 + span_deg + 1):
            for b in range(c2 - span_deg, c2 + span_deg + 1):
                if lim[0][0] <= a <= lim[0][1] and lim[1][0] <= b <= lim[1][1]:
                    yield (a, b)


def _rot(v, angle):
    c, s = math.cos(angle), math.sin(angle)
    return (c * v[0] - s * v[1], s * v[0] + v[1] * c)


def plan(profile_name, keeps_heading=None, pick_tolerance_m=0.005):
    """The key grid points (whole degrees) for the pick and the place, chosen from the kinematics:
    among the picks within pick_tolerance_m of the box, the pick and place that put the box (carried
    at its offset from the pad) nearest the place point; ties go to the fewest key presses."""
    profile = PROFILES[profile_name]
    keeps = MAPS[profile_name]["keeps_heading"] if keeps_heading is None else keeps_heading
    best = None
    for pick in _grid_points(profile, POINT_A_M):
        wrist_a = _wrist_deg(profile_name, (0, 0), pick)
        pad_a, h_a = _pad_xy_heading(profile, pick, wrist_a)
        if math.dist(pad_a, POINT_A_M) > pick_tolerance_m:
            continue
        # pad frame
        offset = _rot((POINT_A_M[0] - pad_a[0], POINT_A_M[1] - pad_a[1]), 0.0 if keeps else -h_a)
        for place in _grid_points(profile, POINT_B_M):
            pad_b, h_b = _pad_xy_heading(
                profile, place, _wrist_deg(profile_name, pick, place, wrist_a)
            )
            off = _rot(offset, 0.0 if keeps else h_b)
            box_m = (pad_b[0] + off[0], pad_b[1] + off[1])
            presses = sum(abs(v) for v in pick) + abs(place[0] - pick[0]) + abs(place[1] - pick[1])
            score = (round(math.dist(box_m, POINT_B_M), 9), presses)
            if best is None or score < best[0]:
                best = (score, pick, place, box_m)
    return best[1:]
