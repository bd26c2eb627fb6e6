"""Verdicts a CI user can trust: a replay matches its source exactly, a divergence between kept
frames still shows, `outcome` judges only the outcome, a crashed run is never blessed, goldens of
user tasks check from anywhere, and every command keeps to one table of exit codes."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from coppeliasim_zmqremoteapi_client import RemoteAPIClient
from support.cli import twin
from support.server import ServerProcess

from twin.cli import main
from twin.record.mcap.reader import load

ROOT = Path(__file__).resolve().parents[2]

# A task that switches the pad on at a chosen step: the one-step-late signal of the issue.
LATE_TASK = """\
def run(twin):
    twin.phase("hover")
    twin.wait({before_s})
    twin.step({early})
    twin.suction(True)
    twin.step({late})
    twin.wait(0.5)
    twin.suction(False)
    twin.wait(0.2)
"""


def cli(*argv, cwd=None) -> subprocess.CompletedProcess:
    """The real `twin` command in its own process."""
    return subprocess.run(
        [sys.executable, "-m", "twin.cli", *map(str, argv)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
        check=False,
    )


# -- 1. a replay diffs as exact against its source ------------------------------------------------
def test_a_replayed_task_run_diffs_exact_and_says_what_it_replays(tmp_path, capsys):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    assert twin(capsys, "run", "pick_place", "--cycles", "1", "--record", a)[0] == 0
    code, out, _ = twin(capsys, "replay", a, "--record", b)
    assert code == 0 and out.startswith("MATCH")
    code, out, _ = twin(capsys, "diff", "--tolerance", "exact", a, b)
    assert code == 0 and out.startswith("MATCH"), out
    kinds = {e.kind for e in load(b).events}
    assert {"task_start", "phase", "placed", "task_end", "attach", "release"} <= kinds
    assert (
        load(b).run["replay_of"]["file"] == "a.mcap"
        and len(load(b).run["replay_of"]["sha256"]) == 64
    )
    assert "replay_of" not in load(a).run
    code, out, _ = twin(capsys, "info", b)
    assert code == 0 and "a replay of a.mcap (sha256 " in out
    code, out, _ = twin(capsys, "check", b)
    assert code == 0 and "1 match" in out


@pytest.mark.slow  # real processes
def test_a_stepped_remote_session_with_addlog_replays_exact(tmp_path, capsys):
    session = tmp_path / "remote.mcap"
    server = ServerProcess("--stepped", "--record", str(session))
    try:
        sim = RemoteAPIClient("127.0.0.1", server.port).require("sim")
        axis1 = sim.getObject("/MTB_axis1")
        sim.setStepping(True)
        sim.startSimulation()
        sim.addLog(sim.verbosity_scriptinfos, "moving the shoulder")
        sim.setJointTargetPosition(axis1, 0.5)
        for _ in range(60):
            sim.step()
        sim.addLog(sim.verbosity_scriptinfos, "done")
        sim.step()
        sim.stopSimulation()
        server.wait_for("finalized|recorded", 30)
    finally:
        server.stop()
    logs = [e for e in load(session).events if e.kind == "log"]
    assert [e.message for e in logs] == ["moving the shoulder", "done"]
    again = tmp_path / "again.mcap"
    code, out, _ = twin(capsys, "replay", session, "--record", again)
    assert code == 0 and out.startswith("MATCH"), out
    assert twin(capsys, "diff", "--tolerance", "exact", session, again)[0] == 0
    assert [e.message for e in load(again).events if e.kind == "log"] == [
        "moving the shoulder",
        "done",
    ]


# -- 2. a divergence between kept frames is not invisible ------------------------------------------
@pytest.fixture(scope="module")
def late_runs(tmp_path_factory):
    """The same run with the pad switched on one step later, each recorded at rates 1, 4 and 7."""
    d = tmp_path_factory.mktemp("late")
    for name, early, late in (("on_time", 0, 1), ("late", 1, 0)):
        (d / name).mkdir()
        task = d / name / "task.py"
        task.write_text(LATE_TASK.format(before_s=1.8, early=early, late=late))
        for rate in (1, 4, 7):
            assert (
                main(
                    [
                        "run",
                        str(task),
                        "--record",
                        str(d / f"{name}_r{rate}.mcap"),
                        "--rate",
                        str(rate),
                    ]
                )
                == 0
            )
    return d


@pytest.mark.parametrize("rate", [4, 7])
@pytest.mark.parametrize("side", ["golden", "candidate", "both"])
def test_a_one_step_late_signal_is_a_mismatch_whichever_side_is_decimated(
    late_runs, capsys, rate, side
):
    d = late_runs
    golden = d / f"on_time_r{rate if side in ('golden', 'both') else 1}.mcap"
    candidate = d / f"late_r{rate if side in ('candidate', 'both') else 1}.mcap"
    code, out, _ = twin(capsys, "diff", golden, candidate)
    assert code == 1, out
    step = next(c.step for c in load(golden).commands if c.kind == "signal")
    assert (
        f"first divergence: step {step}" in out or f"first command difference: step {step}" in out
    )
    assert "decimated (a frame every" in out
    for preset in ("exact", "tight"):
        assert twin(capsys, "diff", "--tolerance", preset, golden, candidate)[0] == 1


def test_the_report_names_the_first_command_difference_and_the_likely_cause(
    late_runs, capsys, tmp_path
):
    d = late_runs
    signal = next(c for c in load(d / "on_time_r1.mcap").commands if c.kind == "signal")
    # decimated and with the command check switched off, the late pad is invisible: what the issue
    # found
    for golden, candidate in (("on_time_r4", "late_r1"), ("on_time_r1", "late_r7")):
        assert (
            twin(
                capsys,
                "diff",
                d / f"{golden}.mcap",
                d / f"{candidate}.mcap",
                "--tol",
                "commands=inf",
            )[0]
            == 0
        )
    # every frame kept, commands off: the frames diverge one step later; the report names the cause
    code, out, _ = twin(
        capsys,
        "diff",
        d / "on_time_r1.mcap",
        d / "late_r1.mcap",
        "--tol",
        "commands=inf",
        "--report",
        tmp_path / "r.json",
    )
    assert code == 1 and f"first divergence: step {signal.step + 1} " in out and "suction.on" in out
    cause = f"step {signal.step} signal(name='pad_switch', value=1)"
    assert (
        f"likely cause: the golden's last command at or before step {signal.step + 1}: {cause}"
        in out
    )
    assert json.loads((tmp_path / "r.json").read_text())["likely_cause"] == cause
    # commands on: the command sequence is the first divergence, and the frames' follows it
    code, out, _ = twin(capsys, "diff", d / "on_time_r4.mcap", d / "late_r4.mcap")
    assert (
        code == 1 and f"first divergence: step {signal.step} " in out and "commands.sequence" in out
    )
    # annotations apart
    acting = [c for c in load(d / "on_time_r4.mcap").commands if c.kind != "event"]
    assert (
        f"the golden's command #{acting.index(signal)} is {cause}; the candidate's is "
        f"step {signal.step + 1} "
        "signal(" in out
    )


# -- 3. outcome judges the outcome ----------------------------------------------------------------
QUIET_TASK = """\
from twin.tasks import pick_place


def run(twin, cycles=1):
    twin.phase = lambda name: None  # the same motions without a single phase line
    pick_place.run(twin, cycles=cycles)
"""

CRASHING_TASK = """\
from twin.tasks import pick_place


def run(twin, cycles=1):
    pick_place.run(twin, cycles=cycles)
    raise RuntimeError("the gripper report failed")
"""


def pick_place_and(
    task_text: str, folder: Path, exit_code: int, pick_place: Path
) -> tuple[Path, Path]:
    """One pick_place cycle recorded as a.mcap (a copy of the recording pick_place), and the task
    file task_text recorded as b.mcap."""
    (folder / "other.py").write_text(task_text)
    a, b = folder / "a.mcap", folder / "b.mcap"
    shutil.copy(pick_place, a)
    assert main(["run", str(folder / "other.py"), "--cycles", "1", "--record", str(b)]) == exit_code
    return a, b


def test_runs_differing_only_in_annotations_pass_outcome_not_exact(
    tmp_path, capsys, pick_place_cli
):
    a, b = pick_place_and(QUIET_TASK, tmp_path, 0, pick_place_cli["mcap"])
    capsys.readouterr()
    assert load(a).frames.object_poses[-1].tobytes() == load(b).frames.object_poses[-1].tobytes()
    code, out, _ = twin(capsys, "diff", "--tolerance", "outcome", a, b)
    assert code == 0 and "events not paired" in out, out
    assert twin(capsys, "diff", "--tolerance", "exact", a, b)[0] == 1


def test_outcome_fails_a_task_that_now_raises_with_the_same_poses(tmp_path, capsys, pick_place_cli):
    a, b = pick_place_and(CRASHING_TASK, tmp_path, 1, pick_place_cli["mcap"])
    capsys.readouterr()
    code, out, _ = twin(capsys, "diff", "--tolerance", "outcome", a, b)
    assert code == 1 and "first divergence" in out and "outcome.task" in out
    assert "expected 'ok', actual 'error'" in out


# -- 5. check --update never blesses a crash -------------------------------------------------------
def test_check_update_leaves_a_golden_untouched_when_its_task_now_raises(tmp_path, capsys):
    task = tmp_path / "my_task.py"
    task.write_text(QUIET_TASK)
    golden = tmp_path / "golden.mcap"
    assert main(["run", str(task), "--cycles", "1", "--record", str(golden)]) == 0
    before = golden.read_bytes()
    task.write_text(CRASHING_TASK)
    capsys.readouterr()
    code, out, _ = twin(capsys, "check", "--update", "-v", golden)
    assert code == 1 and "refused" in out and "not rewritten: the re-run's task failed" in out
    assert "note: the task file 'my_task.py' changed since the golden was recorded" in out
    assert "RuntimeError: the gripper report failed" in out
    assert (
        golden.read_bytes() == before
        and not list(tmp_path.glob("*.tmp"))
        and not list(tmp_path.glob("*partial*"))
    )
    code, out, _ = twin(capsys, "check", "--update", "--allow-error", golden)
    assert code == 0 and "updated" in out
    rewritten = load(golden)
    assert rewritten.meta["twin.finalized"]["outcome"] == "error"  # the file tells the truth
    assert "the gripper report failed" in rewritten.meta["twin.finalized"]["error"]
    code, out, _ = twin(capsys, "check", "-v", golden)  # the rewrite holds the task's new sha256
    assert code == 0 and "changed since the golden was recorded" not in out


def test_a_run_whose_task_raised_is_finalized_as_error_even_when_the_caller_goes_on(tmp_path):
    from twin.model.config import TwinConfig
    from twin.record import open_recorders
    from twin.verify.check import record_task

    (tmp_path / "crash.py").write_text(CRASHING_TASK)
    path = tmp_path / "x.mcap"
    run = {"source": "task", "task": "crash.py", "params": {"cycles": 1}}
    # record_task records, not raises
    with open_recorders(TwinConfig(), run, mcap_path=path) as sinks:
        record_task(TwinConfig(), str(tmp_path / "crash.py"), {"cycles": 1}, sinks=sinks)
    assert load(path).meta["twin.finalized"]["outcome"] == "error"


# -- 6. goldens of your own tasks check from anywhere ---------------------------------------------
@pytest.mark.slow  # real processes
def test_a_user_task_golden_checks_from_root_and_from_a_copy_of_the_project(tmp_path):
    project = tmp_path / "project"
    (project / "tasks").mkdir(parents=True)
    (project / "recordings").mkdir()
    (project / "tasks" / "my_task.py").write_text(QUIET_TASK)
    done = cli(
        "run",
        "my_task.py",
        "--cycles",
        "1",
        "--record",
        "../recordings/mine.mcap",
        cwd=project / "tasks",
    )
    assert done.returncode == 0, done.stderr
    rec = load(project / "recordings" / "mine.mcap")
    assert rec.run["task"] == "../tasks/my_task.py" and len(rec.run["task_sha256"]) == 64
    # no absolute path
    assert str(tmp_path).encode() not in (project / "recordings" / "mine.mcap").read_bytes()
    done = cli("check", project / "recordings" / "mine.mcap", cwd="/")
    assert done.returncode == 0 and "1 match" in done.stdout, done.stdout + done.stderr
    copy = tmp_path / "clone"
    shutil.copytree(project, copy)
    done = cli("check", cwd=copy)
    assert done.returncode == 0 and "1 match" in done.stdout, done.stdout + done.stderr
    # recorded again in the copy, the same run gives the same bytes
    done = cli(
        "run",
        "my_task.py",
        "--cycles",
        "1",
        "--record",
        "../recordings/again.mcap",
        cwd=copy / "tasks",
    )
    assert (copy / "recordings" / "again.mcap").read_bytes() == (
        project / "recordings" / "mine.mcap"
    ).read_bytes()


@pytest.mark.slow  # real processes
def test_a_user_robot_golden_checks_from_another_folder_and_stores_no_absolute_path(tmp_path):
    from support.user_robot import write_user_robot  # the STL-mesh SCARA the URDF tests build

    project = tmp_path / "project"
    profile_file = write_user_robot(project / "robot")
    (project / "recordings").mkdir()
    done = cli(
        "run",
        "pick_place",
        "--cycles",
        "1",
        "--robot",
        profile_file,
        "--record",
        "recordings/user.mcap",
        cwd=project,
    )
    assert done.returncode == 0, done.stderr
    data = (project / "recordings" / "user.mcap").read_bytes()
    assert str(tmp_path).encode() not in data
    urdf = Path(load(project / "recordings" / "user.mcap").config.profile.urdf_path)
    # resolved from the recording's folder
    assert urdf.parent == project / "robot" and urdf.is_file()
    shutil.copytree(project, tmp_path / "clone")
    done = cli("check", tmp_path / "clone" / "recordings", cwd="/")
    assert done.returncode == 0 and "1 match" in done.stdout, done.stdout + done.stderr


# -- 7. smaller wrong answers ---------------------------------------------------------------------
def test_a_moved_event_prints_each_side_its_own_time_and_json_gives_the_window(tmp_path):
    import copy
    import dataclasses

    from twin.compare.engine import compare
    from twin.compare.report import render_json, render_junit, render_text
    from twin.compare.tolerances import Tolerances

    a = tmp_path / "a.mcap"
    assert main(["run", "pick_place", "--cycles", "1", "--record", str(a)]) == 0
    golden = load(a)
    moved = copy.deepcopy(golden)
    i = next(k for k, e in enumerate(moved.events) if e.kind == "release")
    moved.events[i] = dataclasses.replace(moved.events[i], step=moved.events[i].step + 30)
    result = compare(golden, moved, Tolerances.from_preset("physical"))  # window 12 steps
    e, s = golden.events[i].step, moved.events[i].step
    dt_s = golden.config.dt_ns * 1e-9
    text = render_text(result)
    assert (
        f"moved    release box: expected step {e} (t = {e * dt_s:.3f} s), actual step "
        f"{s} (t = {s * dt_s:.3f} s)" in text
    )
    data = json.loads(render_json(result))
    assert data["first"]["channel"] == "events" and data["first"]["field"] == "moved"
    assert data["first"]["tolerance"] == 12 == data["tolerances"]["event_window_steps"]
    suite = ET.fromstring(render_junit(result)).find("testsuite")
    failures = [
        c.find("failure") for c in suite.findall("testcase") if c.find("failure") is not None
    ]
    assert failures and all(
        "MISMATCH" not in f.text and "final object poses" not in f.text for f in failures
    )
    assert suite.find("system-out").text == text  # the whole report once, for the suite


def test_physical_flags_a_sub_millimetre_change_with_a_margin(capsys, tmp_path):
    from twin.compare.engine import compare
    from twin.compare.tolerances import Tolerances

    a = tmp_path / "a.mcap"
    assert main(["run", "pick_place", "--cycles", "1", "--record", str(a)]) == 0
    rec = load(a)
    for offset_m in (0.001, 0.000999, 0.0003):
        moved = load(a)
        moved.frames.object_poses[:, 0, 0] += offset_m
        result = compare(rec, moved, Tolerances.from_preset("physical"))
        assert not result.match and result.first.name == "objects.position", offset_m
    nudged = load(a)
    nudged.frames.object_poses[:, 0, 0] += 0.0001  # 0.1 mm: inside the 0.25 mm margin
    assert compare(rec, nudged, Tolerances.from_preset("physical")).match


def test_a_task_that_calls_sys_exit_0_fails(tmp_path):
    (tmp_path / "quits.py").write_text(
        "import sys\n\n\ndef run(twin):\n    twin.wait(0.1)\n    sys.exit(0)\n"
    )
    done = cli("run", "quits.py", "--record", "q.mcap", cwd=tmp_path)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert done.stderr.strip() == "twin: error: the task called sys.exit(0) instead of returning"
    assert load(tmp_path / "q.mcap").meta["twin.finalized"]["outcome"] == "error"


def test_non_finite_event_data_is_null_in_memory_as_in_the_file(tmp_path):
    from twin.model.config import TwinConfig
    from twin.record import open_recorders
    from twin.sim.twin import Twin

    path = tmp_path / "nan.mcap"
    with open_recorders(
        TwinConfig(), {"source": "task", "task": "", "params": {}}, mcap_path=path
    ) as sinks:
        t = Twin(sinks=sinks)
        said = t.event(
            "placed", "box", "nan error", error_m=float("nan"), limits=[1.0, float("-inf")]
        )
        t.step(2)
        t.close()
    assert said.data == {"error_m": None, "limits": [1.0, None]}
    assert next(e for e in load(path).events if e.kind == "placed").data == said.data


def test_a_timeout_is_part_of_the_run_so_check_reruns_with_it(tmp_path, capsys):
    (tmp_path / "endless.py").write_text("def run(twin):\n    while True:\n        twin.step(10)\n")
    golden = tmp_path / "endless.mcap"
    assert (
        main(["run", str(tmp_path / "endless.py"), "--timeout", "2", "--record", str(golden)]) == 1
    )
    rec = load(golden)
    assert rec.run["timeout_s"] == 2.0 and rec.meta["twin.finalized"]["outcome"] == "error"
    capsys.readouterr()
    code, out, _ = twin(capsys, "check", golden)
    assert code == 0 and "1 match" in out, out


def test_diff_outputs_are_checked_before_any_work_and_never_overwrite_an_input(tmp_path, capsys):
    a = tmp_path / "a.mcap"
    assert main(["run", "pick_place", "--cycles", "1", "--record", str(a)]) == 0
    before = a.read_bytes()
    capsys.readouterr()
    for args in (
        ["--rrd", str(a)],
        ["--rrd", str(tmp_path / "no" / "d.rrd")],
        ["--report", str(tmp_path / "no" / "r.md")],
    ):
        code, out, err = twin(capsys, "diff", a, a, *args)
        assert (
            code == 2 and out == "" and err.count("\n") == 1 and err.startswith("twin: error:")
        ), (args, err)
    assert a.read_bytes() == before
    code, out, _ = twin(capsys, "diff", a, a, "--rrd", tmp_path / "d.rrd")
    assert (
        code == 0
        and (tmp_path / "d.rrd").stat().st_size > 0
        and not (tmp_path / "d.rrd.partial").exists()
    )
