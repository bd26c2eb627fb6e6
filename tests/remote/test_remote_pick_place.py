"""A stepped pick-and-place driven by the official client; its recording replays exactly."""

from __future__ import annotations

import math

import pytest
from support.server import ServerProcess

from twin.cli import main as twin_main
from twin.model.profiles import PROFILES
from twin.record.mcap.reader import load
from twin.robot import kinematics

pytestmark = pytest.mark.slow  # seconds each: `-m "not slow"` leaves them out

PICK_M = (0.2, 0.7)
PLACE_M = (-0.3, -0.55)
Z_DOWN_M = 0.2
TOL_RAD = 1e-3
MAX_STEPS = 2400  # 10 s of simulated time per move


class Arm:
    """Client-side motion over the remote API: joint targets, then sim.step() until they are
    reached."""

    def __init__(self, sim) -> None:
        self.sim = sim
        self.profile = PROFILES["mtb"]
        self.joints = [sim.getObject(f"/MTB_axis{i}") for i in range(1, 5)]
        self.steps = 0

    def settle(self, targets: dict[int, float]) -> None:
        for j, q in targets.items():
            self.sim.setJointTargetPosition(self.joints[j], q)
        for _ in range(MAX_STEPS):
            self.sim.step()
            self.steps += 1
            if all(
                abs(self.sim.getJointPosition(self.joints[j]) - q) < TOL_RAD
                for j, q in targets.items()
            ):
                return
        raise AssertionError(f"joints did not reach {targets} in {MAX_STEPS} steps")

    def over(self, x_m: float, y_m: float) -> None:
        current = (
            self.sim.getJointPosition(self.joints[0]),
            self.sim.getJointPosition(self.joints[1]),
        )
        sol = kinematics.choose(kinematics.ik(self.profile, x_m, y_m), current)
        wrist = kinematics.wrist_for_heading(self.profile, sol, 0.0)
        self.settle({0: sol.shoulder_rad, 1: sol.elbow_rad, 3: wrist})

    def wait(self, steps: int) -> None:
        for _ in range(steps):
            self.sim.step()
        self.steps += steps


def test_stepped_pick_and_place_places_the_box_and_the_recording_replays_exactly(tmp_path, capsys):
    record = tmp_path / "session.mcap"
    with ServerProcess("--stepped", "--robot", "mtb", "--record", str(record)) as server:
        sim = server.client().require("sim")
        arm = Arm(sim)
        box = sim.getObject("/box")
        assert sim.setStepping(True) == 0
        sim.startSimulation()
        sim.addLog(sim.verbosity_scriptinfos, "pick and place over the remote API")
        arm.over(*PICK_M)
        sim.setInt32Signal("pad_switch", 1)
        arm.settle({2: Z_DOWN_M})
        arm.settle({2: 0.0})
        assert sim.getObjectPosition(box, sim.handle_world)[2] > 0.1, "the box was not lifted"
        arm.over(*PLACE_M)
        arm.settle({2: Z_DOWN_M})
        sim.setInt32Signal("pad_switch", 0)
        arm.wait(60)
        arm.settle({2: 0.0})
        arm.wait(120)
        x, y, z = sim.getObjectPosition(box, sim.handle_world)
        t_s = sim.getSimulationTime()
        assert math.hypot(x - PLACE_M[0], y - PLACE_M[1]) < 0.005
        assert z == pytest.approx(0.025, abs=0.002)
        sim.stopSimulation()
        server.wait_for(r"simulation stopped: run 1 lasted \d+ steps .*recorded .*session\.mcap")

        # a second run, recorded under a numbered name, set up while stopped and stopped while
        # holding
        # reset
        assert sim.getObjectPosition(box, sim.handle_world)[:2] == pytest.approx(PICK_M, abs=1e-3)
        sol = kinematics.ik(arm.profile, *PICK_M)[0]
        sim.setJointPosition(arm.joints[0], sol.shoulder_rad)
        sim.setJointPosition(arm.joints[1], sol.elbow_rad)
        sim.setJointPosition(arm.joints[2], Z_DOWN_M)
        sim.setInt32Signal("pad_switch", 1)
        sim.setStepping(True)
        sim.startSimulation()
        for _ in range(3):
            sim.step()
        sim.stopSimulation()
        server.wait_for(
            r"simulation stopped: run 2 lasted 3 steps .*released box; recorded .*session-2\.mcap"
        )

    rec = load(record)
    assert rec.run["source"] == "remote"
    assert rec.config.profile.name == "mtb"
    assert int(rec.frames.step[-1]) == round(t_s / rec.config.dt_s)
    # what the client read is what was recorded
    assert tuple(rec.frames.object_poses[-1][0][:3]) == (x, y, z)
    kinds = [e.kind for e in rec.events]
    assert kinds.count("attach") == 1 and "release" in kinds and "log" in kinds
    # event: the client's addLog
    assert {c.kind for c in rec.commands} == {"joint_target", "signal", "event"}
    assert all(
        rec.commands[i].step <= rec.commands[i + 1].step for i in range(len(rec.commands) - 1)
    )
    second = load(tmp_path / "session-2.mcap")
    assert len(second.frames) == 4
    # given while stopped: step 0 of the run
    assert [c.step for c in second.commands] == [0, 0, 0, 0]
    assert [e.kind for e in second.events] == ["attach"]

    for path in (record, tmp_path / "session-2.mcap"):
        capsys.readouterr()
        assert twin_main(["replay", str(path)]) == 0
        assert "MATCH" in capsys.readouterr().out
