"""The one line a check prints says what changed and by how much: both values at the onset with
the difference in its unit, a timing shift named as one, the annotation whose data changed, the
task file or the scene that differs; and under `outcome` it never speaks of numerical noise."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support.cli import twin

from twin.cli import main
from twin.compare.explain import si
from twin.record import open_recorders
from twin.record.mcap.reader import load
from twin.sim.world import engine_versions
from twin.verify.check import rerun

GOLDEN = Path(__file__).resolve().parents[2] / "recordings" / "pick_place_mtb.mcap"

# a task with a staging point on the way to the place point: moving it 2 mm changes three joint
# targets and shortens the next move by a step, after which the run is the golden's, one step early
STAGED_TASK = """\
def run(twin, stage_x_m: float = {stage_x_m}, stage_y_m: float = 0.6, hold_s: float = 0.2):
    twin.raise_()
    twin.move_to(0.2, 0.7)
    twin.suction(True)
    twin.lower()
    twin.wait(hold_s)
    twin.raise_()
    twin.move_to(stage_x_m, stage_y_m)
    twin.move_to(-0.3, -0.55)
    twin.lower()
    twin.suction(False)
    twin.wait(hold_s)
    twin.raise_()
    x, y = twin.object_pose("box")[:2]
    error_m = ((x + 0.3) ** 2 + (y + 0.55) ** 2) ** 0.5
    twin.event("placed", "box", f"{{error_m * 1000:.2f}} mm off", error_m=error_m)
"""


@pytest.fixture(scope="module")
def staged(tmp_path_factory):
    """goldens/staged.mcap recorded with the staging point at x = 0, and the task file then moved
    2 mm (the candidate a check makes), also recorded as moved.mcap."""
    d = tmp_path_factory.mktemp("staged")
    (d / "goldens").mkdir()
    task = d / "staged.py"
    task.write_text(STAGED_TASK.format(stage_x_m=0.0))
    assert main(["run", str(task), "--record", str(d / "goldens" / "staged.mcap")]) == 0
    task.write_text(STAGED_TASK.format(stage_x_m=0.002))
    assert main(["run", str(task), "--record", str(d / "moved.mcap")]) == 0
    return d


def test_the_check_line_gives_both_commanded_values_and_names_the_timing_shift(staged, capsys):
    golden, moved = load(staged / "goldens" / "staged.mcap"), load(staged / "moved.mcap")
    g = [c for c in golden.commands if c.kind != "event"]
    c = [c for c in moved.commands if c.kind != "event"]
    first = next(i for i, (a, b) in enumerate(zip(g, c, strict=True)) if a != b)
    a, b = g[first], c[first]
    code, out, _ = twin(capsys, "check", staged / "goldens")
    line = next(x for x in out.splitlines() if "staged.mcap" in x)
    assert code == 1 and " differ " in line
    # both commanded values at the onset, and the difference in mrad with its sign
    assert f"step {a.step}: joint_target {a.args['joint']} q " in line
    assert f"{a.args['q']:.6f} -> {b.args['q']:.6f} rad" in line
    assert f"({si(b.args['q'] - a.args['q'], 'rad', signed=True)})" in line
    assert "mrad)" in line
    # the tail of the run is the golden's, a step early: said as such
    tail = next(
        i
        for i in range(len(g))
        if all(x.step - y.step == -1 for x, y in zip(c[i:], g[i:], strict=True))
    )
    assert f"then the same motion, 1 step earlier from step {g[tail].step}" in line
    assert re.search(r"placed box #1 error_m [0-9.]+ -> [0-9.]+ m \([+-][0-9.]+ [nµm]?m\)", line)
    assert "task file changed" in line
    assert "joints.target worst" not in line


def test_the_report_and_its_json_carry_the_explanation(staged, capsys, tmp_path):
    report = tmp_path / "r.json"
    code, out, _ = twin(
        capsys,
        "diff",
        staged / "goldens" / "staged.mcap",
        staged / "moved.mcap",
        "--report",
        report,
    )
    assert code == 1 and "  what changed: step " in out
    data = json.loads(report.read_text())["explanation"]
    assert data["shift"]["steps"] == -1 and data["shift"]["same_motion"] is True
    assert data["headline"] in out and data["task_file_changed"] is True
    # recorded twice from the same file, nothing is shifted and nothing is explained
    code, out, _ = twin(capsys, "diff", staged / "moved.mcap", staged / "moved.mcap")
    assert code == 0 and "what changed" not in out


def test_outcome_never_says_numerical_noise(staged, capsys):
    code, out, _ = twin(
        capsys,
        "diff",
        "--tolerance",
        "outcome",
        staged / "goldens" / "staged.mcap",
        staged / "moved.mcap",
        "-q",
    )
    assert code == 0 and "numerical noise" not in out
    code, out, _ = twin(
        capsys, "check", "--tolerance", "outcome", staged / "goldens" / "staged.mcap", "-v"
    )
    assert code == 0 and "numerical noise" not in out
    assert re.search(r"same outcome; box [0-9.]+ mm from the golden's place, within 5 mm", out)


def test_a_moved_box_is_named_as_the_scene_change_and_the_likely_cause(tmp_path, capsys):
    golden = load(GOLDEN)
    box = dataclasses.replace(golden.config.objects[0], pos_m=(0.201, 0.7, 0.025))
    config = dataclasses.replace(golden.config, objects=(box, *golden.config.objects[1:]))
    moved = tmp_path / "moved.mcap"
    with open_recorders(config, golden.run, mcap_path=str(moved), engine=engine_versions()) as s:
        rerun(dataclasses.replace(golden, config=config), sinks=s)
    code, out, _ = twin(capsys, "diff", GOLDEN, moved)
    assert code == 1
    assert "likely cause: scene changed: box.x_m 0.2 -> 0.201" in out
    assert "signal(name='pad_switch'" not in out.split("likely cause")[1].splitlines()[0]
    what = next(x for x in out.splitlines() if x.startswith("  what changed:"))
    assert "objects.position box (0.200000, 0.700000, 0.025000) -> (0.201000, 0.700000, " in what
    assert "(1 mm apart)" in what and what.endswith("scene changed: box.x_m 0.2 -> 0.201")


@pytest.mark.parametrize(
    ("value", "unit", "text"),
    [
        (0.00099997, "m", "+1 mm"),  # rounds before it picks the prefix: not 1e+03 µm
        (4.41e-3, "rad", "+4.41 mrad"),
        (-1.42e-3, "rad", "-1.42 mrad"),
        (7.5e-6, "m", "+7.5 µm"),
        (1.9e-10, "N·m", "+1.9e-10 N·m"),
        (0.0, "m", "0 m"),
    ],
)
def test_differences_read_in_their_unit(value, unit, text):
    assert si(value, unit, signed=True) == text


def test_a_pick_point_moved_2_mm_in_the_built_in_task_shows_both_commanded_values(tmp_path):
    """The built-in pick_place with its pick point 2 mm further along x (a copy of the package,
    edited, imported ahead of the installed one) checked against the committed golden."""
    package = Path(__file__).resolve().parents[2] / "twin"
    shutil.copytree(package, tmp_path / "edited" / "twin", ignore=shutil.ignore_patterns("*.pyc"))
    task = tmp_path / "edited" / "twin" / "tasks" / "pick_place.py"
    source = task.read_text()
    assert "POINT_A_M = (0.2, 0.7)\n" in source
    task.write_text(source.replace("POINT_A_M = (0.2, 0.7)\n", "POINT_A_M = (0.202, 0.7)\n"))
    done = subprocess.run(
        [sys.executable, "-m", "twin.cli", "check", str(GOLDEN)],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(tmp_path / "edited")},
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    line = next(x for x in done.stdout.splitlines() if "pick_place_mtb.mcap" in x)
    assert done.returncode == 1 and " differ " in line, done.stdout + done.stderr
    golden = load(GOLDEN)
    first = next(c for c in golden.commands if c.kind == "joint_target" and c.step > 0)
    assert re.search(
        rf"step {first.step}: joint_target {first.args['joint']} q {first.args['q']:.6f} -> "
        r"-?[0-9.]+ rad \([+-][0-9.]+ mrad\)",
        line,
    ), line
    assert "placed box #1 error_m 0.000000 -> 0.002000 m (+2 mm)" in line
    assert line.rstrip().endswith("task file changed")
