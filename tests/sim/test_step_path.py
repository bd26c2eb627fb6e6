"""The per-step path's shortcuts keep what a Frame says: object poses for any number of objects, the
pad's idle state (when update() is skipped), and the motor targets each Frame carries."""

from __future__ import annotations

import math

import pytest

from twin.model.config import SceneObject, SuctionParams, TwinConfig
from twin.model.types import NO_BODY
from twin.sim.twin import Twin


@pytest.mark.parametrize(
    "objects",
    [
        (),
        (SceneObject("box"),),
        (
            SceneObject("a", pos_m=(0.2, 0.7, 0.025)),
            SceneObject("b", pos_m=(0.5, 0.0, 0.025), yaw_rad=0.5),
        ),
    ],
)
def test_frames_give_every_object_pose_in_scene_order(objects):
    twin = Twin(TwinConfig(objects=objects))
    try:
        frame = twin.step(10)
        assert len(frame.object_poses) == len(objects)
        for obj, pose in zip(objects, frame.object_poses, strict=True):
            assert len(pose) == 7
            assert math.dist(pose[:3], obj.pos_m) < 1e-3  # resting where it was put
            assert 2.0 * math.atan2(pose[5], pose[6]) == pytest.approx(obj.yaw_rad, abs=1e-6)
    finally:
        twin.close()


@pytest.mark.parametrize("infinite", [True, False])
def test_the_pad_is_idle_only_off_or_holding_on_with_infinite_strength(infinite):
    box = SceneObject("box", pos_m=(0.5, 0.0, 0.025))
    twin = Twin(
        TwinConfig(
            objects=(box,),
            suction=SuctionParams(
                infinite_strength=infinite,
                max_pull_force_n=1e3,
                max_shear_force_n=1e3,
                max_peel_torque_nm=1e3,
            ),
        )
    )
    pad = twin.suction_pad
    try:
        assert pad.idle_on is False
        twin.move_to(0.5, 0.0, heading_rad=0.0)
        twin.suction(True)
        twin.step()
        # on and empty: the sensor looks every step
        assert (pad.on, pad.held, pad.idle_on) == (True, NO_BODY, None)
        twin.lower()
        assert pad.held == 0 and pad.sensed == 0
        # a finite hold is checked for breaking every step
        assert pad.idle_on is (True if infinite else None)
        twin.raise_()
        assert twin.frame.held_body == 0 and twin.frame.sensed_body == 0
        twin.suction(False)
        twin.step()
        assert (pad.on, pad.held, pad.idle_on) == (False, NO_BODY, False)
    finally:
        twin.close()


def test_each_frame_keeps_the_targets_of_its_step():
    twin = Twin()
    try:
        before = twin.step()
        twin.set_joint_target("MTB_axis1", 0.5)
        after = twin.step()
        assert before.joint_target == (0.0, 0.0, 0.0, 0.0)
        assert after.joint_target == (0.5, 0.0, 0.0, 0.0) == twin.targets
        assert type(after.joint_target) is tuple
    finally:
        twin.close()


@pytest.mark.parametrize("timeout_s", [0.0, 1 / 240, 0.05])
def test_a_settle_that_times_out_takes_its_steps_and_says_so(timeout_s):
    """settle() looks at the Frame before each of its steps: it takes round(timeout * 240) steps,
    no more, before its settle_timeout event."""
    from twin.verify.collectors import FrameCollector

    collector = FrameCollector()
    twin = Twin(sinks=[collector])
    try:
        twin.set_joint_target(0, 1.0)  # far: the arm cannot get there in 0.05 s
        assert twin.settle(timeout_s) is False
        assert twin.step_index == round(timeout_s * 240)
        assert [e.kind for e in collector.events][-1] == "settle_timeout"
        assert collector.events[-1].step == twin.step_index
    finally:
        twin.close()


def test_a_settled_arm_takes_no_step():
    twin = Twin()
    try:
        assert twin.settle() is True  # at rest at its targets from the start
        assert twin.step_index == 0
    finally:
        twin.close()
