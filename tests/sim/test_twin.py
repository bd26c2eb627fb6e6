"""The Twin API in real PyBullet: frames and time, moves, joint names, bad input, determinism."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from support.runs import collect_pick_place, columns_digest

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError, OutOfReach, UnknownName
from twin.model.profiles import PROFILES
from twin.model.sink import Sink
from twin.model.types import Command
from twin.robot.kinematics import pad_pose_function, wrap_rad
from twin.sim.twin import Twin
from twin.tasks import TASKS, TimeLimit, run_task
from twin.verify.collectors import FrameCollector

ONE_CYCLE = {"cycles": 1}


def _run_pick_place(params: dict = ONE_CYCLE, profile: str = "mtb") -> FrameCollector:
    return collect_pick_place(None, TwinConfig(profile=PROFILES[profile]), params)


def test_frame_zero_then_one_frame_per_step_on_one_clock():
    sink = FrameCollector()
    twin = Twin(sinks=[sink])
    assert len(sink.frames) == 1 and sink.frames[0].step == 0 and sink.frames[0].t_ns == 0
    twin.step(5)
    twin.wait(0.1)
    assert [f.step for f in sink.frames] == list(range(len(sink.frames)))
    assert len(sink.frames) == 1 + 5 + 24
    assert all(f.t_ns == f.step * twin.config.dt_ns for f in sink.frames)
    assert twin.frame is sink.frames[-1] and twin.t_ns == twin.step_index * twin.config.dt_ns


@pytest.mark.parametrize("x_m, y_m", [(0.6, 0.2), (-0.3, 0.6), (-0.5, -0.4), (0.3, -0.55)])
def test_move_to_reaches_every_quadrant_and_keeps_the_pad_heading(x_m, y_m):
    twin = Twin()
    twin.move_to(0.5, 0.0, heading_rad=0.4)
    twin.move_to(x_m, y_m)
    x, y, _ = twin.pad_position()
    q = twin.frame.joint_q
    assert math.hypot(x - x_m, y - y_m) < 1e-3
    assert abs(wrap_rad(q[0] + q[1] + q[3] - 0.4)) < 2e-3  # the wrist kept the heading
    lo_hi = twin.profile.joint_limits()
    assert all(lo - 1e-3 <= v <= hi + 1e-3 for v, (lo, hi) in zip(q, lo_hi, strict=True))


def test_z_moves_the_pad_height_with_the_prismatic_joint():
    twin = Twin()
    twin.z_to(0.15)
    assert twin.pad_position()[2] == pytest.approx(0.15, abs=3e-4)
    assert twin.joint_position("MTB_axis3") == pytest.approx(twin.profile.tip_z0_m - 0.15, abs=3e-4)
    twin.lower()
    assert twin.joint_position("/joint3") == pytest.approx(twin.profile.z_stroke_m, abs=3e-4)


def test_a_far_move_raises_out_of_reach_and_emits_an_event():
    sink = FrameCollector()
    twin = Twin(sinks=[sink])
    with pytest.raises(OutOfReach) as err:
        twin.move_to(2.0, 0.0)
    assert "(2.0000, 0.0000)" in str(err.value) and "reach annulus 0.2335..0.8675 m" in str(
        err.value
    )
    ev = sink.events[-1]
    assert (
        ev.kind == "out_of_reach"
        and ev.data == {"x_m": 2.0, "y_m": 0.0}
        and ev.message == str(err.value)
    )
    # nothing moved: the only Command is the event itself, recorded so that a replay says it again
    assert [c.kind for c in sink.commands] == ["event"] and twin.step_index == 0
    twin.move_to(0.4, 0.4)  # and the twin carries on
    assert math.hypot(twin.pad_position()[0] - 0.4, twin.pad_position()[1] - 0.4) < 1e-3


def test_a_height_outside_the_stroke_raises_out_of_reach():
    sink = FrameCollector()
    twin = Twin(sinks=[sink])
    with pytest.raises(OutOfReach, match="outside the Z stroke"):
        twin.z_to(0.5)
    assert sink.events[-1].kind == "out_of_reach" and sink.events[-1].data == {"z_m": 0.5}


@pytest.mark.parametrize("name", ["MTB_axis1", "/MTB_axis1", "joint1", "Revolute_joint", "/AB", 0])
def test_any_variants_shoulder_name_drives_the_shoulder(name):
    sink = FrameCollector()
    twin = Twin(sinks=[sink])
    twin.set_joint_target(name, 0.5)
    twin.settle()
    assert twin.joint_position(0) == pytest.approx(0.5, abs=1e-3)
    # recorded under the profile's name
    assert sink.commands[0].args == {"joint": "MTB_axis1", "q": 0.5}


def test_a_target_beyond_the_limit_is_clamped_with_an_event():
    sink = FrameCollector()
    twin = Twin(sinks=[sink])
    twin.set_joint_target("MTB_axis2", 4.0)
    twin.settle()
    limit = twin.profile.elbow_limit_rad
    assert twin.joint_position(1) == pytest.approx(limit, abs=1e-3)
    assert [e.kind for e in sink.events] == ["joint_limit"]
    assert sink.events[0].data["requested"] == 4.0 and sink.events[0].data["limit"] == limit


@pytest.mark.parametrize(
    "call, error, text",
    [
        (lambda t: t.set_joint_target("MTB_axis7", 0.1), UnknownName, "'MTB_axis7'"),
        (lambda t: t.set_joint_target(4, 0.1), UnknownName, "joint index 4"),
        (lambda t: t.set_joint_target("MTB_axis1", math.nan), ConfigError, "nan"),
        (lambda t: t.set_joint_target("MTB_axis1", "1"), ConfigError, "'1'"),
        (lambda t: t.set_joint_max_velocity("MTB_axis1", 0.0), ConfigError, "maximum velocity 0.0"),
        (lambda t: t.set_signal("pad_switch", True), ConfigError, "True"),
        (lambda t: t.set_signal("", 1), ConfigError, "signal name ''"),
        (lambda t: t.wait(-1.0), ConfigError, "wait of -1.0 s"),
        (lambda t: t.object_pose("ball"), UnknownName, "'ball'"),
        (lambda t: t.apply(Command(3, "signal", {"name": "a", "value": 1})), ConfigError, "step 3"),
        (lambda t: t.apply(Command(0, "teleport", {})), ConfigError, "'teleport'"),
    ],
)
def test_bad_input_raises_a_twin_error_naming_the_value(call, error, text):
    twin = Twin()
    with pytest.raises(error) as err:
        call(twin)
    assert text in str(err.value)
    assert "\n" not in str(err.value)


def test_the_suction_signal_of_each_variant_switches_the_pad():
    twin = Twin(TwinConfig(profile=PROFILES["seed003"]))
    twin.set_signal("suctionPad", 1)
    twin.step()
    assert twin.frame.suction_on
    twin.set_signal("suctionPad", None)
    twin.step()
    assert not twin.frame.suction_on and twin.get_signal("suctionPad") is None


def test_two_runs_give_bit_identical_frames_events_and_commands():
    a, b = _run_pick_place(), _run_pick_place()
    assert a.columns().equals(b.columns())
    assert a.events == b.events and a.commands == b.commands
    c = _run_pick_place({"cycles": 1, "pause_s": 0.51})  # the comparison can fail
    assert not a.columns().equals(c.columns())


def test_feeding_the_recorded_commands_back_reproduces_the_frames():
    original = _run_pick_place()
    sink = FrameCollector()
    twin = Twin(sinks=[sink])
    last_step = original.frames[-1].step
    pending = list(original.commands)
    while twin.step_index < last_step or pending:
        while pending and pending[0].step == twin.step_index:
            twin.apply(pending.pop(0))
        if twin.step_index < last_step:
            twin.step()
    assert sink.columns().equals(original.columns())
    assert sink.commands == original.commands


_CHILD = """
import hashlib, sys
sys.path.insert(0, {tests!r})
from support.runs import collect_pick_place, columns_digest
print(columns_digest(collect_pick_place().columns()))
"""


def test_separate_processes_give_bit_identical_frames():
    here = columns_digest(_run_pick_place().columns())
    tests_dir = str(__import__("pathlib").Path(__file__).resolve().parents[1])
    code = _CHILD.format(tests=tests_dir)
    digests = [
        subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
        ).stdout.strip()
        for _ in range(2)
    ]
    assert digests == [here, here]


def test_every_command_kind_has_a_handler_and_every_handler_a_kind():
    """Twin.apply looks a Command's handler up by kind (formerly an import-time check)."""
    from twin.model.types import COMMAND_ARGS

    assert set(Twin._COMMANDS) == set(COMMAND_ARGS)


def test_a_closed_worlds_client_serves_the_next_twin_as_a_fresh_one(monkeypatch):
    """A process's next headless World takes the PyBullet client a closed one left (connecting is
    most of building a Twin); after build()'s reset it steps bit for bit as a new client does, even
    one left holding a box with its collisions off."""
    from twin.sim import world
    from twin.tasks import TASKS, run_task

    monkeypatch.setattr(world, "_SPARE_CLIENTS", [])
    fresh = _run_pick_place()
    (client,) = world._SPARE_CLIENTS
    monkeypatch.setattr(world, "_SPARE_CLIENTS", [])  # the next one connects anew
    holding = Twin()
    assert holding._world.client != client
    box = holding.config.objects[0].pos_m
    holding.move_to(box[0], box[1])
    holding.lower()
    holding.suction(True)
    holding.step(10)
    assert holding.frame.held_body == 0
    left = holding._world.client
    holding.close()
    assert world._SPARE_CLIENTS == [left]
    assert not holding._world.connected()  # the closed world no longer reaches the client it left
    sink = FrameCollector()
    again = Twin(sinks=[sink])
    assert again._world.client == left and not world._SPARE_CLIENTS
    run_task(again, TASKS["pick_place"], ONE_CYCLE)
    again.close()
    assert sink.columns().equals(fresh.columns())
    assert sink.events == fresh.events and sink.commands == fresh.commands


class _Kept(Sink):
    """Keeps every Frame it is handed."""

    def __init__(self, reads_pad_pose: bool = True) -> None:
        self.frames = []
        self.reads_pad_pose = reads_pad_pose

    def on_frame(self, frame) -> None:
        self.frames.append(frame)


class _EventsOnly(Sink):
    def on_event(self, event) -> None:
        pass


def _pick_place(sinks) -> tuple[Twin, list]:
    """pick_place (1 cycle) with `sinks`; the twin and the joint values it worked out a pad pose
    for."""
    twin = Twin(TwinConfig(), sinks=sinks)
    worked_out, pad_pose = [], twin._pad_pose

    def counted(q):
        worked_out.append(q)
        return pad_pose(q)

    twin._pad_pose = counted
    run_task(twin, TASKS["pick_place"], {"cycles": 1})
    return twin, worked_out


def test_with_no_sink_reading_it_the_pad_pose_is_worked_out_only_when_asked():
    """The pad pose is half the twin's own work a step: with no sink reading it (none at all, one
    that takes only events, a time limit, one that says so) the stepping loop leaves it out, and
    `twin.frame` works it out when asked (the suction rule, a task, the caller), with the same bits
    as a Frame that carried it."""
    pad_pose = pad_pose_function(TwinConfig().profile)
    for sinks in ([], [_EventsOnly()], [TimeLimit(1e6)], [_Kept(reads_pad_pose=False)]):
        twin, worked_out = _pick_place(sinks)
        try:
            assert 0 < len(worked_out) < twin.step_index / 4, sinks
            frame = twin.frame
            assert frame.pad_pose == pad_pose(frame.joint_q)
            assert twin.frame is frame  # worked out once
        finally:
            twin.close()
    quiet = _Kept(reads_pad_pose=False)
    _pick_place([quiet])[0].close()
    assert quiet.frames[0].pad_pose is not None  # the first Frame is read whole
    assert sum(f.pad_pose is None for f in quiet.frames) > len(quiet.frames) * 3 / 4
    twin, worked_out = _pick_place([_Kept()])
    twin.close()
    assert len(worked_out) >= twin.step_index  # a sink reads it: every step


def test_frames_a_sink_reads_whole_are_the_same_beside_one_that_does_not():
    """One sink that reads the pad pose has it worked out every step, for every sink; the run is
    the same as with that sink alone."""
    alone, reading, quiet = _Kept(), _Kept(), _Kept(reads_pad_pose=False)
    for sinks in ([alone], [reading, quiet]):
        _pick_place(sinks)[0].close()
    assert reading.frames == alone.frames == quiet.frames
    assert all(len(f.pad_pose) == 7 for f in alone.frames)
