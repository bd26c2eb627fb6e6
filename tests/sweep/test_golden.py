"""Statistical goldens: `twin check NAME.toml` (and a folder of them) re-runs a sweep and judges its
summary by the golden's Wilson interval and the placement-error tolerances; --update writes it."""

from __future__ import annotations

import json
import shutil

import pytest

from twin.cli.main import main
from twin.sweep.golden import judge

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]
DEFINITION = """\
task = "pick_place"
seed = 3
scenarios = 12

[params]
cycles = 1
pause_s = 0.1
max_error_m = 0.03

[vary]
"box.x_m" = "normal(0.2, 0.012)"
"box.y_m" = "normal(0.7, 0.012)"

[tolerance]
placement_p95_mm = 0.25
"""


@pytest.fixture(scope="module")
def golden(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sweeps")
    (folder / "small.toml").write_text(DEFINITION)
    assert main(["check", str(folder / "small.toml"), "--update", "--jobs", "2"]) == 0
    return folder


def test_update_writes_the_summary_and_check_matches_it(golden, tmp_path, capsys):
    summary = json.loads((golden / "small.summary.json").read_text())
    assert summary["scenarios"] == 12 and summary["seed"] == 3 and 0 < summary["ok"] <= 12
    capsys.readouterr()
    assert main(["check", str(golden)]) == 0  # the folder's definitions
    out = capsys.readouterr().out
    assert "small.toml" in out and " match " in out and "matches" in out


def test_a_moved_statistic_is_exit_1_naming_it_and_by_how_much(golden, tmp_path, capsys):
    shutil.copy(golden / "small.toml", tmp_path / "moved.toml")
    summary = json.loads((golden / "small.summary.json").read_text())
    summary["wilson95"] = [0.0, summary["success_rate"] / 2]
    summary["placement_error_mm"]["p95"] -= 0.4
    (tmp_path / "moved.summary.json").write_text(json.dumps(summary))
    capsys.readouterr()
    assert main(["check", str(tmp_path / "moved.toml")]) == 1
    out = capsys.readouterr().out
    assert "differ" in out and "success_rate" in out and "outside the golden's Wilson 95 % interval" in out
    assert "placement_error_mm.p95 moved +0.400 mm" in out and "tolerance 0.25 mm" in out
    assert main(["check", str(tmp_path / "moved.toml"), "--update"]) == 0
    assert json.loads((tmp_path / "moved.summary.json").read_text()) == json.loads(
        (golden / "small.summary.json").read_text())


def test_judge_allows_moves_within_tolerance():
    golden = {"scenarios": 100, "success_rate": 0.9, "wilson95": [0.82, 0.95],
              "placement_error_mm": {"p50": 1.0, "p95": 2.0, "max": 3.0}}
    near = {"scenarios": 100, "success_rate": 0.86, "placement_error_mm": {"p50": 1.4, "p95": 2.9, "max": 1.5}}
    tol = {"placement_p50_mm": 0.5, "placement_p95_mm": 1.0, "placement_max_mm": 2.0}
    assert judge(golden, near, tol) == []
    far = {**near, "success_rate": 0.8, "placement_error_mm": {"p50": 1.6, "p95": 2.9, "max": 1.5}}
    assert judge(golden, far, tol) == [
        "success_rate 0.8000 is outside the golden's Wilson 95 % interval [0.8200, 0.9500] (golden 0.9000, moved -0.1000)",
        "placement_error_mm.p50 moved +0.600 mm (golden 1.000, now 1.600; tolerance 0.5 mm)"]


def test_bad_sweep_goldens_are_exit_2(tmp_path, capsys):
    (tmp_path / "lone.toml").write_text(DEFINITION)
    assert main(["check", str(tmp_path / "lone.toml")]) == 2
    assert "has no lone.summary.json beside it; `twin check --update" in capsys.readouterr().out
    (tmp_path / "lone.toml").write_text(DEFINITION.replace('"box.x_m"', '"box.w"'))
    assert main(["check", str(tmp_path / "lone.toml"), "--update"]) == 2
    assert "--vary key 'box.w' is unknown" in capsys.readouterr().out
    assert main(["check", str(tmp_path / "none.toml")]) == 2
    assert "sweep definition" in capsys.readouterr().err


@pytest.mark.slow  # 150 scenarios: 7-20 s here, with the machine shared
def test_the_shipped_sweep_golden_checks():
    assert main(["check", str(ROOT / "recordings" / "sweeps"), "--jobs", "2"]) == 0
