"""`twin search`: the same answer on 1 or 2 local workers and on Dask, a boundary that a dense
sweep of the same key confirms, bad input refused before anything runs, Ctrl-C keeping what was
found, and a saved failure that checks green until the boundary moves."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from support.read_only import read_only

from twin.cli.main import main
from twin.jobs.executors import LocalExecutor
from twin.search.search import Probes, probe_spec
from twin.sweep.spec import SweepSpec

FAST = ["--param", "cycles=1", "--param", "pause_s=0.1"]
REACH = [
    "pick_place",
    "--vary",
    "box.x_m=0.17..0.23",
    *FAST,
    "--param",
    "max_error_m=0.03",
    "--precision",
    "0.02",
    "--budget",
    "24",
    "--quiet",
]


def _search(tmp_path, name: str, args: list[str], capsys) -> dict:
    assert main(["search", *args, "--out", str(tmp_path / name)]) == 0
    capsys.readouterr()
    return json.loads((tmp_path / name / "search.json").read_text())


@pytest.fixture(scope="module")
def reach(tmp_path_factory):
    """The pick_place boundary in box.x_m, searched with one local worker."""
    out = tmp_path_factory.mktemp("reach")
    assert main(["search", *REACH, "--out", str(out / "one")]) == 0
    return out / "one", json.loads((out / "one" / "search.json").read_text())


def test_search_is_the_same_on_one_or_two_workers_and_on_dask(reach, tmp_path, capsys):
    folder, one = reach
    assert _search(tmp_path, "two", [*REACH, "-j", "2"], capsys) == one
    assert _search(tmp_path, "dask", [*REACH, "-j", "2", "--executor", "dask"], capsys) == one
    assert one["runs"] <= 24 and one["stopped"] is None
    minimal = one["minimal"]
    assert "nothing sensed" in minimal["reason"] and minimal["shrunk"]
    x = minimal["values"]["box.x_m"]
    assert minimal["size"] == pytest.approx(abs(x - 0.2) / 0.03)
    b = one["boundary"]["box.x_m"]
    assert (
        b["failing"] == x and b["converged"] and abs(b["failing"] - b["passing"]) <= b["precision"]
    )
    assert b["precision"] == pytest.approx(0.03 * 0.02)
    assert (folder / "minimal.mcap").is_file()


def test_the_boundary_agrees_with_a_dense_sweep(reach):
    """Brute force: 21 evenly spaced values over the range, each run; the last passing and first
    failing value on each side bracket the bisection's boundary (the dense grid is coarser)."""
    _, one = reach
    grid = [0.17 + 0.003 * i for i in range(21)]
    spec = SweepSpec("pick_place", 1, params={"cycles": 1, "pause_s": 0.1, "max_error_m": 0.03})
    executor = LocalExecutor(2)
    try:
        done = dict(
            executor.map_unordered(
                Probes(tuple(probe_spec(spec, ["box.x_m"], [x]) for x in grid)), len(grid)
            )
        )
    finally:
        executor.close()
    ok = [done[i][0] == "ok" for i in range(len(grid))]
    assert ok[10] and not ok[0] and not ok[-1]
    inner = [x for x, good in zip(grid, ok, strict=True) if good]
    assert all(ok[grid.index(inner[0]) : grid.index(inner[-1]) + 1])  # one passing interval
    sides = one["boundary"]["box.x_m"]
    precision = sides["precision"]
    high, low = sides["high"], sides["low"]
    assert (
        inner[-1] - precision <= high["passing"] < high["failing"] <= inner[-1] + 0.003 + precision
    )
    assert inner[0] - 0.003 - precision <= low["failing"] < low["passing"] <= inner[0] + precision
    assert (
        0.025 < high["failing"] - 0.2 < 0.028
    )  # the sensor ray at the pad's centre: a 50 mm box's half


@pytest.mark.parametrize(
    ("vary", "message"),
    [
        ("box.x_m=0.3..0.2", "--vary box.x_m=0.3..0.2 is invalid; expected a range LOW..HIGH"),
        ("box.x_m=normal(0.2,0.01)", "expected a range LOW..HIGH"),
        ("box.q_m=0.1..0.3", "--vary key 'box.q_m' is unknown"),
        ("box.x_m=0.3..0.4", "the nominal value 0.2 lies outside"),
        ("box.mass_kg=-1..1", "box.mass_kg = -1.0 is invalid"),
        ("engine.num_solver_iterations=10..60", "search varies real-valued keys"),
    ],
)
def test_bad_ranges_and_keys_are_one_line_before_anything_runs(tmp_path, capsys, vary, message):
    out = tmp_path / "never"
    assert main(["search", "pick_place", "--vary", vary, "--budget", "5", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_ctrl_c_keeps_what_was_found(tmp_path):
    out = tmp_path / "stopped"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "search",
            "pick_place",
            "--vary",
            "box.x_m=0.1..0.3",
            "--vary",
            "box.y_m=0.6..0.8",
            *FAST,
            "--budget",
            "500",
            "--out",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        first = proc.stderr.readline()
        assert first.startswith("search: "), first + proc.stderr.read()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, stderr
    data = json.loads((out / "search.json").read_text())
    assert data["stopped"] == "interrupted" and data["runs"] >= 5
    assert data["nominal"]["outcome"] == "ok" and "(interrupted)" in stdout
    if data["minimal"] is not None:  # said, not left for the user to find missing
        assert f"not recorded: {out / 'minimal.mcap'}" in stdout
    assert not (out / "minimal.mcap").exists()


def test_a_saved_failure_checks_green_then_red_when_the_boundary_moves(
    tmp_path, monkeypatch, capsys
):
    """pick_place's placement limit (2 mm by default): the smallest failure is a box about 2 mm off.
    A looser limit moves the boundary past it (now passes); a box far off fails another way."""
    monkeypatch.chdir(tmp_path)
    assert (
        main(
            [
                "search",
                "pick_place",
                "--vary",
                "box.x_m=0.19..0.21",
                *FAST,
                "--precision",
                "0.05",
                "--budget",
                "20",
                "--save-golden",
                "placement",
                "--out",
                "runs/placement",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "beyond 2 mm" in out and "recordings/search/placement.toml" in out
    definition = tmp_path / "recordings" / "search" / "placement.toml"
    expect = json.loads((tmp_path / "recordings" / "search" / "placement.expect.json").read_text())
    assert (
        expect["outcome"] == "error" and expect["reason"] == "placed # mm from (#, #), beyond # mm"
    )
    assert main(["replay", "recordings/search/placement.mcap"]) == 0
    capsys.readouterr()
    before = definition.read_bytes()
    again = ["search", "pick_place", "--vary", "box.x_m=0.19..0.21", *FAST, "--budget", "20"]
    assert main([*again, "--save-golden", "placement", "--out", "runs/other"]) == 2
    assert "'recordings/search/placement.toml' exists already" in capsys.readouterr().err
    assert main([*again, "--out", "runs/placement"]) == 2  # not empty
    assert "--out 'runs/placement' is a folder that is not empty" in capsys.readouterr().err
    assert definition.read_bytes() == before and not (tmp_path / "runs" / "other").exists()

    assert main(["check", "recordings/search"]) == 0
    assert "fails the same way: cycle 1: placed" in capsys.readouterr().out

    text = definition.read_text()
    assert "max_error_m" not in text  # the task's default, 2 mm
    definition.write_text(text.replace("[params]\n", '[params]\n"max_error_m" = 0.01\n'))
    assert main(["check", str(definition)]) == 1
    assert "now passes: the boundary moved; `--update` to accept" in capsys.readouterr().out

    definition.write_text(re.sub(r'"box.x_m" = "[^"]*"', '"box.x_m" = "0.26"', text))
    assert main(["check", str(definition)]) == 1
    assert (
        "fails differently: expected 'placed # mm from (#, #), beyond # mm', "
        "now 'cycle 1: suction on" in capsys.readouterr().out
    )
    assert main(["check", "--update", str(definition)]) == 0
    capsys.readouterr()
    assert main(["check", str(definition)]) == 0
    assert (
        "fails the same way: cycle 1: suction on at (0.2, 0.7), nothing sensed"
        in capsys.readouterr().out
    )


def test_save_golden_into_a_read_only_folder_is_one_output_error(tmp_path, monkeypatch, capsys):
    """The search runs and writes search.json; its golden cannot be written: exit 2, one line naming
    the file, no traceback, nothing left in the folder."""
    monkeypatch.chdir(tmp_path)
    folder = tmp_path / "recordings" / "search"
    folder.mkdir(parents=True)
    args = ["pick_place", "--vary", "box.x_m=0.19..0.21", *FAST, "--precision", "0.05"]
    with read_only(folder):
        code = main(
            ["search", *args, "--budget", "20", "--save-golden", "placement", "--out", "runs/p"]
        )
        assert list(folder.iterdir()) == []
    captured = capsys.readouterr()
    assert code == 2 and (tmp_path / "runs" / "p" / "search.json").is_file()
    assert [line for line in captured.err.splitlines() if "error" in line] == [
        "twin: error: cannot write 'recordings/search/placement.toml': "
        + ("Permission denied" if os.geteuid() else "Operation not permitted")
    ]
    assert "Traceback" not in captured.err


def test_a_search_of_the_seeing_task_finds_a_wider_boundary(reach, tmp_path, capsys):
    _, blind = reach
    seeing = _search(
        tmp_path,
        "vision",
        [
            "pick_place_vision",
            "--vary",
            "box.x_m=0.17..0.8",
            *FAST,
            "--precision",
            "0.02",
            "--budget",
            "16",
            "--quiet",
        ],
        capsys,
    )
    b = seeing["boundary"]["box.x_m"]
    assert b["side"] == "high" and b["converged"] and b["low"]["failing"] is None
    assert 0.5 < b["passing"] < b["failing"] < 0.53  # the arm's reach: (x, 0.7) beyond 0.8675 m
    assert "outside the reach annulus" in seeing["minimal"]["reason"]
    assert b["passing"] - 0.2 > 8 * (blind["boundary"]["box.x_m"]["passing"] - 0.2)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([os.path.abspath(__file__), "-q"]))


def test_keep_records_a_search_golden_that_now_behaves_otherwise(tmp_path, capsys):
    """The shipped search golden, expected to pass: it differs (it still fails), and --keep leaves
    its scenario recorded again and its report; the golden's own files stay as they were."""
    shipped = Path(__file__).resolve().parents[2] / "recordings" / "search"
    folder = tmp_path / "search"
    folder.mkdir()
    for suffix in (".toml", ".expect.json", ".mcap"):
        shutil.copy(shipped / ("pick_place_reach" + suffix), folder)
    expect = folder / "pick_place_reach.expect.json"
    expect.write_text(json.dumps({**json.loads(expect.read_text()), "outcome": "ok"}))
    before = {f: f.read_bytes() for f in folder.iterdir()}
    keep = tmp_path / "K"
    capsys.readouterr()
    assert main(["check", str(folder), "--keep", str(keep)]) == 1
    out = capsys.readouterr().out
    assert out.startswith("checking 1 golden: 1 search\n") and "now fails: cycle 1:" in out
    assert sorted(os.listdir(keep)) == ["pick_place_reach.mcap", "pick_place_reach.md"]
    assert {f: f.read_bytes() for f in folder.iterdir()} == before
    assert main(["info", str(keep / "pick_place_reach.mcap")]) == 0
    assert "finalized: yes (run outcome error: cycle 1: suction on" in capsys.readouterr().out
    report = (keep / "pick_place_reach.md").read_text()
    assert report.startswith("# search golden pick_place_reach: differ\n")
    assert "expected: ok" in report and "now:      error 'cycle 1: suction on" in report
