"""`twin run` end to end: the pick-and-place loop on every profile, user task files, bad input,
--gui."""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from twin.cli import main
from twin.model.config import TwinConfig
from twin.model.profiles import PROFILES
from twin.sim.twin import Twin
from twin.tasks import TASKS, resolve, run_task
from twin.verify.collectors import FrameCollector

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
FAR = FIXTURES / "far_task.py"
PLACE_TOL_M = 0.005
EVENT_LINE = re.compile(r"^\s+t=\s*([\d.]+) s\s+(\w+)\s+(\S*)\s+(.*)$")


def _twin_cli(*args: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "twin.cli", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def _one_error_line(stderr: str) -> str:
    assert "Traceback" not in stderr
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("twin: error: ")
    return lines[0]


@pytest.mark.parametrize("robot", sorted(PROFILES))
def test_pick_place_places_within_5_mm_with_one_attach_and_release_per_cycle(robot):
    sink = FrameCollector()
    twin = Twin(TwinConfig(profile=PROFILES[robot]), sinks=[sink])
    run_task(twin, TASKS["pick_place"], {"cycles": 2})
    kinds = [
        e.kind
        for e in sink.events
        if e.kind in ("attach", "release", "break", "placed", "suction_empty")
    ]
    assert kinds == ["attach", "release", "placed"] * 2
    placed = [e for e in sink.events if e.kind == "placed"]
    assert [e.data["cycle"] for e in placed] == [1, 2]
    assert all(0.0 <= e.data["error_m"] < PLACE_TOL_M for e in placed), [
        e.data["error_m"] for e in placed
    ]
    x, y = twin.object_pose("box")[:2]  # two cycles: back where it started
    assert abs(x - 0.2) < PLACE_TOL_M and abs(y - 0.7) < PLACE_TOL_M


@pytest.mark.parametrize("robot", sorted(PROFILES))
def test_twin_run_pick_place_prints_each_cycles_attach_release_and_placement(
    robot, capsys, tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "pick_place", "--robot", robot, "--cycles", "2", "--no-record"]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    events = [
        EVENT_LINE.match(line).groups() for line in out.splitlines() if EVENT_LINE.match(line)
    ]
    assert [e[1] for e in events] == ["attach", "release", "placed"] * 2
    for _t, kind, body, message in events:
        assert body == "box"
        if kind == "placed":
            assert float(re.search(r"placed ([\d.]+) mm", message).group(1)) < 5.0
    assert f"robot {robot}:" in out and "over 2 cycle(s)" in out
    assert not list(tmp_path.iterdir())  # --no-record wrote nothing


def test_report_001s_loop_reports_an_empty_suction_and_leaves_the_box():
    """The built-in seed001 task is report 001's Lua loop with its Heron IK as written: it
    misses."""
    sink = FrameCollector()
    twin = Twin(TwinConfig(profile=PROFILES["seed001"]), sinks=[sink])
    start = twin.object_pose("box")
    run_task(twin, resolve("seed001"), {"cycles": 1})
    kinds = [e.kind for e in sink.events]
    assert kinds[0] == "task_start" and kinds[-1] == "task_end" and "attach" not in kinds
    assert kinds.count("suction_empty") == 2  # at the pick and at the place
    assert all(
        e.message == "suction on, nothing sensed" for e in sink.events if e.kind == "suction_empty"
    )
    end = twin.object_pose("box")
    assert abs(end[0] - start[0]) < 1e-3 and abs(end[1] - start[1]) < 1e-3
    assert all(f.held_body == -1 for f in sink.frames)
    # wherever the pad went down, the nearest it came to the box is where the report's IK sent it:
    # 13 cm off
    z_low = min(f.pad_pose[2] for f in sink.frames) + 1e-3
    miss_m = min(
        ((f.pad_pose[0] - 0.2) ** 2 + (f.pad_pose[1] - 0.7) ** 2) ** 0.5
        for f in sink.frames
        if f.pad_pose[2] < z_low
    )
    assert 0.12 < miss_m < 0.14


def test_report_001s_loop_from_the_command_line_exits_0(tmp_path):
    done = _twin_cli(
        "run", "seed001", "--robot", "seed001", "--cycles", "1", "--no-record", cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    assert "suction_empty 2" in done.stdout and "attach" not in done.stdout
    final = re.search(r"box final pose: x ([-+\d.]+) y ([-+\d.]+)", done.stdout)
    # not moved
    assert abs(float(final.group(1)) - 0.2) < 1e-3 and abs(float(final.group(2)) - 0.7) < 1e-3


def test_far_task_is_one_line_on_stderr_and_exit_code_1(tmp_path):
    done = _twin_cli("run", str(FAR), "--no-record", cwd=tmp_path)
    assert done.returncode == 1  # the task failed; 3 is only "runs not comparable"
    line = _one_error_line(done.stderr)
    assert line.startswith("twin: error: target (2.0000, 0.0000) m is outside the reach annulus: ")
    assert "reach annulus 0.2335..0.8675 m" in line and "shoulder -160..160 deg" in line
    assert "out_of_reach" in done.stdout  # the summary still lists the event


@pytest.mark.parametrize(
    "args, expected",
    [
        (["run", "pick_place", "--robot", "scara9000"], "unknown robot 'scara9000'"),
        (["run", "dance"], "unknown task 'dance'"),
        (["run", "no/such/task.py"], "task file 'no/such/task.py' does not exist"),
        (
            ["run", "pick_place", "--cycles", "0"],
            "argument --cycles: '0' is not a whole number >= 1",
        ),
        (["run", "pick_place", "--cycles", "two"], "'two' is not a whole number >= 1"),
        (
            ["run", "pick_place", "--cycles", "9223372036854775808"],
            "is not a whole number 1..2**63-1 (int64)",
        ),
        (
            ["run", "pick_place", "--param", "cycles=1e400"],
            "--param cycles=1e400 is invalid: 1e400 is not a finite",
        ),
        (["run", "pick_place", "--rate-hz", "0"], "physics rate 0.0 Hz is out of range"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(args, expected, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    try:
        code = main([*args, "--no-record"])
    except SystemExit as stop:  # argparse's own errors leave through exit()
        code = stop.code
    captured = capsys.readouterr()
    assert code == 2
    assert expected in _one_error_line(captured.err)
    assert not list(tmp_path.iterdir())


def test_bad_input_from_a_real_process(tmp_path):
    done = _twin_cli("run", "pick_place", "--cycles", "0", cwd=tmp_path)
    assert done.returncode == 2 and done.stdout == ""
    _one_error_line(done.stderr)


@pytest.mark.parametrize(
    "body, code, expected",
    [
        (
            "def run(twin):\n    raise RuntimeError('gripper on fire')\n",
            1,
            "task raised RuntimeError: gripper on fire",
        ),
        ("import no_such_module\n", 2, "failed to import: ModuleNotFoundError"),
        ("def go(twin):\n    pass\n", 2, "has no function run(twin, **params)"),
        ("def run(twin):\n    twin.set_joint_target('elbowz', 1.0)\n", 2, "unknown joint 'elbowz'"),
    ],
)
def test_broken_user_task_files_are_one_line(body, code, expected, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    task = tmp_path / "mytask.py"
    task.write_text(body)
    assert main(["run", str(task), "--no-record"]) == code
    assert expected in _one_error_line(capsys.readouterr().err)


def test_gui_without_a_display_is_one_line(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    done = _twin_cli("run", "pick_place", "--gui", "--no-record", cwd=tmp_path, env=env)
    assert done.returncode == 2
    assert "needs a display but DISPLAY is not set" in _one_error_line(done.stderr)
    env["DISPLAY"] = ":87"  # no server there
    done = _twin_cli("run", "pick_place", "--gui", "--no-record", cwd=tmp_path, env=env)
    assert done.returncode == 2
    assert "cannot connect to the X display DISPLAY=':87'" in _one_error_line(done.stderr)


@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="Xvfb is not installed")
@pytest.mark.slow  # real processes
def test_gui_under_xvfb_runs_pick_place(tmp_path):
    read_fd, write_fd = os.pipe()  # Xvfb picks a free display and writes its number here
    xvfb = subprocess.Popen(
        [
            "Xvfb",
            "-displayfd",
            str(write_fd),
            "-screen",
            "0",
            "800x600x24",
            "-nolisten",
            "tcp",
            "-noreset",
        ],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    try:
        with os.fdopen(read_fd) as numbers:
            display = ":" + numbers.readline().strip()
        assert display != ":", "Xvfb did not start"
        env = dict(os.environ, DISPLAY=display)
        done = _twin_cli(
            "run", "pick_place", "--gui", "--cycles", "1", "--no-record", cwd=tmp_path, env=env
        )
        assert done.returncode == 0, done.stderr[-2000:]
        assert "placed 1" in done.stdout and "attach 1" in done.stdout
    finally:
        xvfb.terminate()
        xvfb.wait(timeout=10)


@pytest.mark.parametrize(("cycles", "final_m"), [(1, (-0.3, -0.55)), (2, (0.2, 0.7))])
def test_report_000s_loop_carries_the_box_to_b_and_a_second_carry_back(cycles, final_m, tmp_path):
    done = _twin_cli(
        "run", "seed000", "--robot", "seed000", "--cycles", str(cycles), "--no-record", cwd=tmp_path
    )
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert f"attach {cycles}" in done.stdout and f"release {cycles}" in done.stdout
    placed = re.findall(r"placed ([\d.]+) mm from \(([-\d.]+), ([-\d.]+)\)", done.stdout)
    assert [(float(x), float(y)) for _, x, y in placed] == [(-0.3, -0.55), (0.2, 0.7)][:cycles]
    assert all(float(mm) < 5.0 for mm, _, _ in placed)
    final = re.search(r"box final pose: x ([-+\d.]+) y ([-+\d.]+)", done.stdout)
    assert math.dist((float(final.group(1)), float(final.group(2))), final_m) < 0.005


def test_report_002s_program_as_a_task_misses_and_leaves_the_box(tmp_path):
    done = _twin_cli("run", "seed002", "--robot", "seed002", "--no-record", cwd=tmp_path)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert "suction_empty 2" in done.stdout and "attach" not in done.stdout
    final = re.search(r"box final pose: x ([-+\d.]+) y ([-+\d.]+)", done.stdout)
    assert math.dist((float(final.group(1)), float(final.group(2))), (0.2, 0.7)) < 1e-3


def test_output_piped_into_head_leaves_a_good_recording_and_no_process_behind(tmp_path):
    """`twin run ... | head -1`: the reader goes away before the twin has printed all of its
    summary. The run's files are finished before the summary is printed, so they are what an unpiped
    run writes (byte for byte, the camera's pictures included), and the camera process ends with the
    twin: exit 141 (128 + SIGPIPE). The reader here closes its end before the first line: had it
    read one line first, the twin could write the whole short summary into the pipe before the
    close, and exit 0."""
    args = ["run", "pick_place", "--cycles", "1", "--camera", "overhead", "--camera-size", "64x48"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin.cli", *args, "--record", str(tmp_path / "piped.mcap")],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        # each line written as printed
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    proc.stdout.close()  # as head does after its line
    assert proc.wait(timeout=120) == 141, proc.stderr.read()
    assert proc.stderr.read() == b""
    plain = _twin_cli(*args, "--record", str(tmp_path / "plain.mcap"), cwd=tmp_path)
    assert plain.returncode == 0, plain.stderr
    assert (tmp_path / "piped.mcap").read_bytes() == (tmp_path / "plain.mcap").read_bytes()


# A user task may say `placed` with no usable error figure: the summary used to crash on it (a
# KeyError or TypeError traceback, exit 1, though the recording was finalized ok), and hid the
# task's own error.
PLACED_TASK = """
def run(twin, error: str = "missing", fail: bool = False):
    twin.wait(0.05)
    data = {"missing": {}, "none": {"error_m": None}, "text": {"error_m": "1 mm"},
            "bool": {"error_m": True}, "huge": {"error_m": 10**400},
            "list": {"error_m": [0.001]}}[error]
    twin.event("placed", "box", "put down", **data)
    twin.event("placed", "box", "put down again", error_m=0.0015)
    if fail:
        raise RuntimeError("after placing")
"""


@pytest.mark.parametrize("error", ["missing", "none", "text", "bool", "huge", "list"])
def test_a_placed_event_without_an_error_figure_is_summarized(error, tmp_path, monkeypatch, capsys):
    import twin

    monkeypatch.chdir(tmp_path)
    task = tmp_path / "placing.py"
    task.write_text(PLACED_TASK)
    assert (
        main(["run", str(task), "--param", f"error={error}", "--record", str(tmp_path / "p.mcap")])
        == 0
    )
    out, err = capsys.readouterr()
    assert err == ""
    assert "placement error: worst 1.50 mm over 1 cycle(s); 1 more placed (no error figure)" in out
    assert "placed 2" in out and "recorded " in out
    assert twin.load(tmp_path / "p.mcap").outcome == "ok"


def test_placed_events_with_no_figure_at_all_and_a_failing_task(tmp_path, monkeypatch, capsys):
    """The exit code follows the task: it raised after saying `placed` (exit 1, its error on one
    line)."""
    import twin

    monkeypatch.chdir(tmp_path)
    task = tmp_path / "placing.py"
    task.write_text(PLACED_TASK.replace("error_m=0.0015", "error_m=None"))
    assert (
        main(["run", str(task), "--param", "error=none", "--record", str(tmp_path / "p.mcap")]) == 0
    )
    assert "placement error: 2 placed (no error figure)" in capsys.readouterr().out
    assert (
        main(
            [
                "run",
                str(task),
                "--param",
                "error=text",
                "--param",
                "fail=true",
                "--record",
                str(tmp_path / "f.mcap"),
            ]
        )
        == 1
    )
    out, err = capsys.readouterr()
    assert _one_error_line(err) == "twin: error: task raised RuntimeError: after placing"
    assert "placement error: 2 placed (no error figure)" in out
    assert twin.load(tmp_path / "f.mcap").outcome == "error"
