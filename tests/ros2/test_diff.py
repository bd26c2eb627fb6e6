"""`twin diff RUN.mcap BAG`: a robot's /joint_states log (here a bag rosbags writes from the same
run: another rate, wall-clock stamps, time before the motion, noise, a bias, other names) against
the twin, at the bag's own sample times, judged by the physical preset."""

from __future__ import annotations

import re

import numpy as np
import pytest
from support.cli import twin
from support.ros2_bags import joint_bag

import twin as twin_pkg
from twin.compare.samples import compare_logs
from twin.compare.tolerances import Tolerances
from twin.model.joint_log import JointLog


@pytest.fixture(scope="module")
def run(pick_place_cli):
    return twin_pkg.load(pick_place_cli["mcap"])


def _lag(out: str) -> float:
    return float(re.search(r"lag: B runs ([+-][\d.]+) s", out).group(1))


def test_a_noisy_100hz_wall_clock_bag_matches_and_a_biased_joint_is_named(run, tmp_path, capsys):
    bag = joint_bag(run, tmp_path / "robot", rate_hz=100.0, noise_rad=2e-5)
    code, out, err = twin(capsys, "diff", run.path, bag, "--tolerance", "physical")
    assert code == 0, out + err
    assert out.startswith("MATCH") and "samples of B (240.0 Hz A, 100.0 Hz B)" in out
    assert "interpolated linearly" in out and abs(_lag(out)) < 1e-4
    biased = joint_bag(run, tmp_path / "biased", noise_rad=2e-5, bias=("MTB_axis1", 0.002))
    code, out, _ = twin(capsys, "diff", run.path, biased, "--tolerance", "physical")
    assert code == 1 and out.startswith("MISMATCH")
    assert "first divergence: MTB_axis1 joints.position" in out
    rows = {line.split()[0]: line for line in out.splitlines() if line.startswith("MTB_axis")}
    assert rows["MTB_axis1"].endswith("s") and "NO, from" in rows["MTB_axis1"]
    assert all(rows[j].endswith("yes") for j in ("MTB_axis2", "MTB_axis3", "MTB_axis4"))


def test_the_lag_is_found_and_an_offset_is_taken_as_given(run, tmp_path, capsys):
    bag = joint_bag(run, tmp_path / "late", rate_hz=80.0, lead_s=1.234, noise_rad=1e-5)
    code, out, _ = twin(capsys, "diff", run.path, bag)  # physical by default, with a bag
    assert code == 0 and abs(_lag(out) - 1.234) < 2e-4, out
    assert "first motion, then best fit" in out
    code, out, _ = twin(capsys, "diff", run.path, bag, "--time-offset", "1.234")
    assert code == 0 and "(--time-offset)" in out
    code, out, _ = twin(capsys, "diff", run.path, bag, "--time-offset", "1.2")  # 34 ms off
    assert code == 1 and "first divergence" in out
    # either side may be the bag: B's lag is then the other way round
    code, out, _ = twin(capsys, "diff", bag, run.path)
    assert code == 0 and abs(_lag(out) + 1.234) < 2e-4, out


def test_other_joint_names_need_a_joint_map(run, tmp_path, capsys):
    names = ["shoulder", "elbow", "z", "wrist"]
    bag = joint_bag(run, tmp_path / "named", names=names)
    code, _, err = twin(capsys, "diff", run.path, bag)
    assert code == 3 and "no joint in common" in err and "--joint-map" in err
    maps = [
        a
        for robot, name in zip(names, run.config.profile.joint_names, strict=True)
        for a in ("--joint-map", f"{robot}={name}")
    ]
    code, out, _ = twin(capsys, "diff", run.path, bag, *maps)
    assert code == 0 and out.count("joints.position") == 4, out


def test_velocities_are_judged_where_the_bag_has_them(run, tmp_path):
    bag = twin_pkg.load(joint_bag(run, tmp_path / "vel", rate_hz=120.0, velocity=True))
    assert bag.velocity_rad_s is not None and bag.effort_nm is None
    tol = Tolerances.from_preset("physical")
    twin_log = JointLog.from_recording(run)
    result = compare_logs(twin_log, bag, tol, revolute={})
    assert result.passed and {s.quantity for s in result.stats} == {
        "joints.position",
        "joints.velocity",
    }
    assert any("joints.effort not compared" in n for n in result.notes)
    bag.velocity_rad_s[50:, 1] += 0.05  # the elbow 50 mrad/s fast from its 51st sample on
    result = compare_logs(twin_log, bag, tol, revolute={})
    (failed,) = [s for s in result.stats if not s.passed]
    assert (failed.joint, failed.quantity) == ("MTB_axis2", "joints.velocity")
    assert failed.parts_t_s == pytest.approx(50 / 120.0, abs=1e-3)


def test_comparing_at_the_bags_samples_beats_resampling_the_bag(run, tmp_path):
    """The issue's measure: resampling a 100 Hz log to the twin's 240 Hz by linear interpolation
    alone adds mrads; comparing at the bag's own times adds nothing (a noiseless bag matches to
    1e-9)."""
    bag = twin_pkg.load(joint_bag(run, tmp_path / "clean", rate_hz=100.0))
    twin_log = JointLog.from_recording(run)
    tight = Tolerances.from_preset("tight")
    result = compare_logs(twin_log, bag, tight, revolute={}, lag_s=0.0)
    worst_at_bag = max(s.worst for s in result.stats)
    t_twin, t_bag = run.frames.t_ns * 1e-9, (bag.t_ns - bag.t_ns[0]) * 1e-9
    inside = t_twin <= t_bag[-1]
    resampled = np.stack(
        [np.interp(t_twin[inside], t_bag, bag.position_rad[:, k]) for k in range(4)], axis=1
    )
    worst_resampled = float(np.max(np.abs(resampled - run.frames.joint_q[inside])))
    assert worst_at_bag < 1e-9 and worst_resampled > 1e-3, (worst_at_bag, worst_resampled)


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--joint-map", "a"], "--joint-map 'a' is malformed; expected ROBOT=TWIN"),
        (["--joint-map", "nope=MTB_axis1"], "--joint-map names 'nope'"),
        (["--time-offset", "nan"], "--time-offset nan is invalid"),
        (["--rrd", "x.rrd"], "--rrd is for two twin recordings"),
    ],
)
def test_bad_options_are_one_line_and_exit_2(run, tmp_path, capsys, argv, expected):
    bag = joint_bag(run, tmp_path / "b", rate_hz=50.0)
    code, out, err = twin(capsys, "diff", run.path, bag, *argv)
    assert code == 2 and expected in err and len(err.strip().splitlines()) == 1 and not out
    assert not (tmp_path / "x.rrd").exists()


def test_offset_options_without_a_bag_and_a_bag_without_joint_states(run, tmp_path, capsys):
    code, _, err = twin(capsys, "diff", run.path, run.path, "--time-offset", "1")
    assert code == 2 and "--time-offset is for a ROS 2 bag; neither input is one" in err
    from rosbags.rosbag2 import StoragePlugin, Writer
    from support.ros2_bags import TYPESTORE

    empty = tmp_path / "no_joints"
    with Writer(empty, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.add_connection("/chatter", "std_msgs/msg/String", typestore=TYPESTORE)
    code, _, err = twin(capsys, "diff", run.path, empty)
    assert code == 2 and "has no /joint_states topic" in err and "/chatter" in err


def test_an_exported_bag_is_judged_on_its_tf_frames_too(run, tmp_path, capsys):
    bag = tmp_path / "exported"
    assert twin(capsys, "export", run.path, "--format", "ros2", "-o", bag)[0] == 0
    code, out, _ = twin(capsys, "diff", run.path, bag)
    rows = {tuple(line.split()[:2]) for line in out.splitlines()[4:]}
    assert code == 0 and {("pad_tip", "pad.position"), ("box", "objects.position")} <= rows, out
    log = twin_pkg.load(bag)
    t_ns, poses = log.tf["pad_tip"]
    poses[len(t_ns) // 2 :, 0] += 0.001  # the pad 1 mm off along x from half way
    result = compare_logs(
        JointLog.from_recording(run), log, Tolerances.from_preset("physical"), revolute={}
    )
    (failed,) = [s for s in result.stats if not s.passed]
    assert (failed.joint, failed.quantity) == ("pad_tip", "pad.position")
    assert failed.worst == pytest.approx(0.001, abs=1e-9)
    assert failed.parts_t_s == pytest.approx((t_ns[len(t_ns) // 2] - t_ns[0]) * 1e-9)


def _damage(bag, how: str) -> None:
    (mcap_file,) = bag.glob("*.mcap")
    if how == "metadata":
        (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [\n")
    elif how == "cut":
        mcap_file.write_bytes(mcap_file.read_bytes()[:50_000])
    else:  # flipped bytes inside a message: a sequence length no message can have
        data = bytearray(mcap_file.read_bytes())
        for i in range(len(data) // 3, len(data) // 3 + 4000):
            data[i] ^= 0x5A
        mcap_file.write_bytes(bytes(data))


@pytest.mark.parametrize("how", ["metadata", "cut", "flipped"])
def test_a_damaged_bag_is_one_line_and_exit_2(run, tmp_path, capsys, how):
    bag = joint_bag(run, tmp_path / "bag", rate_hz=50.0)
    _damage(bag, how)
    code, out, err = twin(capsys, "diff", run.path, bag)
    assert code == 2 and not out and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"twin: error: cannot read ROS 2 bag '{bag}'"), err


def test_an_object_named_like_a_robot_link_keeps_its_frame_apart(run, tmp_path):
    """The export names such an object `object_NAME` in /tf (the link keeps its name); the run's
    side of a diff names it the same, so the box is never judged against the robot's base."""
    import dataclasses

    from twin.ros2.bags import read_bag, run_log
    from twin.ros2.export import write_bag

    (box,) = run.config.objects
    config = dataclasses.replace(run.config, objects=(dataclasses.replace(box, name="MTB_base"),))
    renamed = dataclasses.replace(run, config=config)
    bag = tmp_path / "renamed"
    write_bag(renamed, bag)
    log = read_bag(bag)
    assert {"MTB_base", "object_MTB_base"} <= set(log.tf)
    result = compare_logs(run_log(renamed), log, Tolerances.from_preset("physical"), revolute={})
    frames = {(s.joint, s.quantity) for s in result.stats if not s.joint.startswith("MTB_axis")}
    assert result.passed and frames == {
        ("object_MTB_base", "objects.position"),
        ("pad_tip", "pad.position"),
    }, frames


def test_a_grippers_own_joint_states_are_left_out_and_said(run, tmp_path, capsys):
    bag = joint_bag(run, tmp_path / "with_gripper", gripper_every=10)
    log = twin_pkg.load(bag)
    assert log.names == tuple(run.config.profile.joint_names)
    code, out, _ = twin(capsys, "diff", run.path, bag)
    assert code == 0, out
    assert re.search(
        r"note: .*: \d+ /joint_states messages of other joints \(gripper\) left out", out
    )


def test_nan_efforts_are_not_compared_and_a_nan_position_fails(run, tmp_path):
    """ROS drivers without effort sensing send NaN efforts; a NaN position is a sample the log
    lacks, never a match."""
    log = twin_pkg.load(joint_bag(run, tmp_path / "nan", rate_hz=60.0, velocity=True))
    log.effort_nm = np.full_like(log.position_rad, np.nan)
    tol = Tolerances.from_preset("physical")
    result = compare_logs(JointLog.from_recording(run), log, tol, revolute={})
    assert result.passed and any("joints.effort not compared" in n for n in result.notes)
    log.position_rad[100, 2] = np.nan
    result = compare_logs(JointLog.from_recording(run), log, tol, revolute={})
    (failed,) = [s for s in result.stats if not s.passed]
    assert (failed.joint, failed.quantity, failed.worst) == ("MTB_axis3", "joints.position", np.inf)
