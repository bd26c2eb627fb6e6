"""The suction pad in real PyBullet: attach, release, the measured hold wrench and when a hold
breaks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.model.config import SceneObject, SuctionParams, TwinConfig
from twin.model.profiles import PROFILES
from twin.model.types import NO_BODY
from twin.sim.twin import Twin
from twin.verify.collectors import FrameCollector

G_M_S2 = 9.81
BOX_XY_M = (0.5, 0.0)
HIGH = 1e3  # a limit that is never reached


def _twin(
    mass_kg: float = 0.1, size_z_m: float = 0.05, robot: str = "mtb", **suction
) -> tuple[Twin, FrameCollector]:
    box = SceneObject(
        "box", size_m=(0.05, 0.05, size_z_m), mass_kg=mass_kg, pos_m=(*BOX_XY_M, size_z_m / 2)
    )
    sink = FrameCollector()
    config = TwinConfig(profile=PROFILES[robot], objects=(box,), suction=SuctionParams(**suction))
    return Twin(config, sinks=[sink]), sink


def _kinds(sink: FrameCollector) -> list[str]:
    return [e.kind for e in sink.events if e.kind != "phase"]


def _pick(twin: Twin, dx_m: float = 0.0, *, gentle: bool = False) -> None:
    """Pick the box. `gentle` stops the pad 0.1 mm past where its sensor first sees the box top:
    lowering to the end of the stroke drags the attached box 2 mm into the floor, a shove of tens
    of newtons that a weak finite hold would not survive."""
    twin.move_to(BOX_XY_M[0] + dx_m, BOX_XY_M[1], heading_rad=0.0)
    twin.suction(True)
    if gentle:
        twin.z_to(0.05 + SuctionParams().sensor_offset_m - twin.profile.pad_length_m + 0.0059)
    else:
        twin.lower()
    twin.raise_()


def test_switching_off_releases_and_the_box_falls():
    twin, sink = _twin()
    _pick(twin)
    assert twin.frame.held_body == 0
    assert twin.object_pose("box")[2] > 0.2  # lifted with the pad
    twin.suction(False)
    twin.wait(1.0)
    assert twin.frame.held_body == NO_BODY
    assert twin.object_pose("box")[2] == pytest.approx(0.025, abs=1e-3)  # back on the floor
    assert _kinds(sink) == ["attach", "release"]
    release = next(e for e in sink.events if e.kind == "release")
    assert (release.body, release.message) == ("box", "suction off")
    assert twin.frame.hold_force_n == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("mass_kg", [0.1, 0.3])
def test_a_box_hanging_still_pulls_with_its_weight(mass_kg):
    twin, _ = _twin(mass_kg)
    _pick(twin)
    twin.wait(1.0)
    f = twin.frame
    fx, fy, fz = f.hold_force_n
    # the pad holds the box up: +z on the box
    assert fz == pytest.approx(mass_kg * G_M_S2, rel=0.01)
    assert math.hypot(fx, fy) < 1e-3 * mass_kg * G_M_S2
    assert max(abs(t) for t in f.hold_torque_nm) < 1e-4


def test_the_hold_force_is_in_world_axes_and_opposes_the_centripetal_pull():
    """Swinging the shoulder at constant speed: the pad pulls the box towards the shoulder axis."""
    twin, sink = _twin()
    _pick(twin)
    twin.set_joint_target("MTB_axis1", 1.0)
    twin.step(40)  # at full speed (3 rad/s) by now
    f = sink.frames[-1]
    x, y = f.object_poses[0][:2]
    w = f.joint_qd[0]
    fx, fy, _ = f.hold_force_n
    expected = 0.1 * w * w * math.hypot(x, y)  # m ω² r, towards the axis
    assert fx * x + fy * y < 0.0
    assert math.hypot(fx, fy) == pytest.approx(expected, rel=0.05)


def test_an_empty_pad_switched_off_reports_suction_empty():
    twin, sink = _twin()
    twin.move_to(-0.4, 0.4)  # nowhere near the box
    twin.suction(True)
    twin.lower()
    twin.suction(False)
    twin.step()
    twin.raise_()
    assert _kinds(sink) == ["suction_empty"]
    ev = sink.events[-1] if sink.events[-1].kind == "suction_empty" else None
    assert ev is not None and ev.message == "suction on, nothing sensed" and ev.body == ""
    assert twin.object_pose("box")[:2] == pytest.approx(BOX_XY_M, abs=1e-3)


def test_a_heavy_box_breaks_a_finite_hold_on_pull():
    twin, sink = _twin(
        mass_kg=0.5, infinite_strength=False, max_shear_force_n=HIGH, max_peel_torque_nm=HIGH
    )
    _pick(twin)
    twin.wait(1.0)
    breaks = [e for e in sink.events if e.kind == "break"]
    assert len(breaks) == 1 and breaks[0].body == "box"
    assert breaks[0].message.startswith("pull ") and "> max_pull_force 3.0 N" in breaks[0].message
    assert twin.frame.held_body == NO_BODY
    assert twin.object_pose("box")[2] == pytest.approx(0.025, abs=2e-3)  # fell back


def test_the_same_box_holds_with_infinite_strength():
    twin, sink = _twin(mass_kg=0.5)
    _pick(twin)
    twin.wait(1.0)
    assert "break" not in _kinds(sink) and twin.frame.held_body == 0


def test_a_fast_swing_breaks_a_weak_hold_on_shear():
    twin, sink = _twin(
        infinite_strength=False,
        max_pull_force_n=HIGH,
        max_shear_force_n=5.0,
        max_peel_torque_nm=HIGH,
    )
    _pick(twin, gentle=True)
    assert _kinds(sink) == ["attach"]  # lifting is not shear
    twin.move_to(-0.3, -0.55)
    breaks = [e for e in sink.events if e.kind == "break"]
    assert len(breaks) == 1 and breaks[0].message.startswith("shear ")


def test_peel_is_the_torque_at_the_cup_face():
    """A box held 15 mm off its centre pulls with a peel torque of d·m·g·(1 + a/g) at the pad tip (0
    at its centre of mass, where the constraint acts): the jerk of lifting it breaks the stock 0.1
    N·m limit, while a centred box has almost none."""
    limits = {"infinite_strength": False, "max_pull_force_n": HIGH, "max_shear_force_n": HIGH}
    centred, sink_c = _twin(**limits)
    _pick(centred, gentle=True)
    centred.wait(0.5)
    assert "break" not in _kinds(sink_c)
    offset, sink_o = _twin(**limits)
    _pick(offset, dx_m=0.015, gentle=True)
    breaks = [e for e in sink_o.events if e.kind == "break"]
    assert len(breaks) == 1 and breaks[0].message.startswith("peel torque ")

    hanging, _ = _twin()
    _pick(hanging, dx_m=0.015)
    hanging.wait(1.0)
    f = hanging.frame
    tip = np.array(f.pad_pose[:3])
    com = np.array(f.object_poses[0][:3])
    at_tip = np.array(f.hold_torque_nm) + np.cross(com - tip, np.array(f.hold_force_n))
    assert math.hypot(at_tip[0], at_tip[1]) == pytest.approx(0.015 * 0.1 * G_M_S2, rel=0.05)


def test_pressing_the_held_box_down_is_not_pull():
    """A tall box held and pushed into the floor: the pad pushes it down (negative z), which must
    not count as pull; lifting it afterwards keeps the hold."""
    twin, sink = _twin(
        size_z_m=0.07,
        infinite_strength=False,
        max_pull_force_n=20.0,
        max_shear_force_n=HIGH,
        max_peel_torque_nm=HIGH,
    )
    twin.move_to(*BOX_XY_M)
    twin.suction(True)
    twin.z_to(0.06, settle=False)  # 10 mm into the box's top
    twin.wait(0.6)
    pressed = min(f.hold_force_n[2] for f in sink.frames)
    assert pressed < -20.0
    twin.raise_()
    twin.wait(0.5)
    assert _kinds(sink) == ["attach"] and twin.frame.held_body == 0


@pytest.mark.parametrize("depth_m", [0.002, 0.010, 0.020])
def test_a_pad_set_into_a_box_senses_it_as_coppeliasims_ray_sensor_does(depth_m):
    """sim.setJointPosition can put the pad into a box (report 000's key 5): PyBullet's ray sees no
    body it starts inside, CoppeliaSim's ray sensor sees the back face; the twin's pad senses and
    takes the box."""
    from twin.robot.kinematics import z_joint_for_height

    twin, sink = _twin(robot="seed000")  # its Z stop (report 000's 0.084) reaches 19 mm into a box
    twin.move_to(*BOX_XY_M, heading_rad=0.0)
    twin.suction(True)
    twin.step(2)
    assert twin.suction_pad.held == NO_BODY  # high above: nothing
    # the sensor's start (13 mm below the pad root) depth_m below the box top: inside the box
    tip_z = 0.05 - depth_m + SuctionParams().sensor_offset_m - twin.profile.pad_length_m
    twin.set_joint_position("z", z_joint_for_height(twin.profile, tip_z))
    twin.step(1)
    assert twin.suction_pad.held == 0 and _kinds(sink)[-1] == "attach"


def test_a_pad_beside_a_box_at_the_same_height_senses_nothing():
    from twin.robot.kinematics import z_joint_for_height

    twin, sink = _twin(robot="seed000")
    twin.move_to(BOX_XY_M[0] + 0.04, BOX_XY_M[1], heading_rad=0.0)  # 15 mm beyond the box's side
    twin.suction(True)
    twin.set_joint_position("z", z_joint_for_height(twin.profile, 0.035))
    twin.step(3)
    assert twin.suction_pad.held == NO_BODY and "attach" not in _kinds(sink)


def test_the_sensor_skips_its_ray_only_where_no_object_can_be_sensed():
    """Suction._may_sense skips the engine's ray and the inside test when the sensor's segment is
    outside every object's bounding sphere: on a grid of sensor starts around two boxes (one long,
    turned), wherever it says no, the ray and the inside test find nothing; where they find a box,
    it says yes; and it says no for most of the grid."""
    boxes = (
        SceneObject("box", pos_m=(0.5, 0.0, 0.025)),
        SceneObject("bar", size_m=(0.2, 0.03, 0.04), pos_m=(0.3, 0.3, 0.02), yaw_rad=0.7),
    )
    twin = Twin(TwinConfig(objects=boxes))
    pad, frame, rng_m = twin.suction_pad, twin.frame, SuctionParams().sensor_range_m
    skipped = sensed = 0
    for x in np.arange(0.15, 0.65, 0.02):
        for y in np.arange(-0.1, 0.45, 0.02):
            for z_from in (0.004, 0.03, 0.045, 0.05, 0.056, 0.07, 0.09, 0.2):
                found = twin._world.ray_down(x, y, z_from, rng_m)
                if found == NO_BODY:
                    found = pad._inside(frame, (x, y, z_from))
                may = pad._may_sense(frame, x, y, z_from)
                assert may or found == NO_BODY, (x, y, z_from, found)
                skipped += not may
                sensed += found != NO_BODY
    assert sensed > 50 and skipped > 0.8 * 25 * 28 * 8
