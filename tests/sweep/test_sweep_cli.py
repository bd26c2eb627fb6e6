"""`twin sweep` end to end: the same results whatever the job count, failures recorded, replayable
and byte-identical when re-run with --only, bad input refused before anything runs, --fail-under,
Ctrl-C keeping the results so far."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pyarrow.parquet as pq
import pytest

from twin.cli.main import main

SWEEP = ["pick_place", "--scenarios", "10", "--seed", "5", "--vary", "box.x_m=uniform(0.17,0.23)",
         "--vary", "box.y_m=uniform(0.67,0.73)", "--vary", "box.mass_kg=choice(0.1,0.5)",
         "--param", "cycles=1", "--param", "pause_s=0.1", "--param", "max_error_m=0.02", "--quiet"]


def results(folder) -> pq.Table:
    return pq.read_table(folder / "results.parquet").drop(["wall_s"])


def test_one_or_two_jobs_give_the_same_results_and_failures_replay(tmp_path, capsys):
    assert main(["sweep", *SWEEP, "--out", str(tmp_path / "one"), "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    assert main(["sweep", *SWEEP, "--out", str(tmp_path / "two"), "--jobs", "2"]) == 0
    capsys.readouterr()
    table = results(tmp_path / "one")
    assert table.equals(results(tmp_path / "two"))
    assert table.column_names == [
        "scenario",
        "seed",
        "box.x_m",
        "box.y_m",
        "box.mass_kg",
        "outcome",
        "error",
        "placement_error_mm",
        "attach",
        "release",
        "break",
        "suction_empty",
        "sim_s",
    ]
    rows = table.to_pylist()
    assert [r["scenario"] for r in rows] == list(range(10)) and {r["seed"] for r in rows} == {5}
    failed = [r["scenario"] for r in rows if r["outcome"] == "error"]
    assert 0 < len(failed) < 10  # this jitter: some boxes are placed within 2 mm, most are not
    summary = json.loads((tmp_path / "one" / "summary.json").read_text())
    assert summary["scenarios"] == 10 and summary["failed"] == len(failed)
    assert summary["wilson95"][0] <= summary["success_rate"] <= summary["wilson95"][1]
    assert sum(summary["failures_by_reason"].values()) == len(failed)
    assert f"ok {10 - len(failed)}, failed {len(failed)}: success rate" in out
    for folder in ("one", "two"):
        assert sorted(p.name for p in (tmp_path / folder / "failures").iterdir()) == sorted(
            f"scenario-{i}.mcap" for i in failed
        )
    i = failed[0]
    golden = (tmp_path / "one" / "failures" / f"scenario-{i}.mcap").read_bytes()
    assert (tmp_path / "two" / "failures" / f"scenario-{i}.mcap").read_bytes() == golden
    assert (
        main(
            [
                "sweep",
                str(tmp_path / "one" / "sweep.toml"),
                "--only",
                str(i),
                "--out",
                str(tmp_path / "again"),
            ]
        )
        == 0
    )
    assert f"scenario {i}: error: " in capsys.readouterr().out
    assert (tmp_path / "again" / "failures" / f"scenario-{i}.mcap").read_bytes() == golden
    # --only leaves a sweep's results alone
    assert not (tmp_path / "again" / "results.parquet").exists()
    assert main(["replay", str(tmp_path / "one" / "failures" / f"scenario-{i}.mcap")]) == 0
    assert main(["check", str(tmp_path / "one" / "failures" / f"scenario-{i}.mcap")]) == 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--vary", "box.x_m=uniform(0.3)"],
            "--vary box.x_m=uniform(0.3) is invalid; expected uniform(two finite numbers)",
        ),
        (["--vary", "bx.x_m=0.2"], "--vary key 'bx.x_m' is unknown"),
        (["--vary", "box.x_m"], "--vary 'box.x_m' is invalid; expected KEY=DIST"),
        (["--param", "speed=2"], "task 'pick_place' takes no parameter 'speed'"),
        (
            ["--vary", "task.cycles=choice(1,2)", "--param", "cycles=1"],
            "task parameter 'cycles' is both --param and --vary",
        ),
        (["--only", "10"], "--only 10 is out of range; the sweep has scenarios 0..9"),
        (["--scheduler", "tcp://127.0.0.1:1"], "--scheduler needs --executor dask"),
        (["--dashboard"], "--dashboard needs --executor dask without --scheduler"),
        (
            ["--executor", "dask", "--scheduler", "udp://127.0.0.1:1"],
            "--scheduler 'udp://127.0.0.1:1' is invalid",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2_before_anything_runs(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    assert main(["sweep", "pick_place", "--scenarios", "10", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("twin: error: ") and message in err and err.count("\n") == 1
    assert not (out / "results.parquet").exists()


def test_missing_folder_and_fail_under(tmp_path, capsys):
    assert main(["sweep", *SWEEP, "--out", str(tmp_path / "no" / "out")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert (
        main(
            [
                "sweep",
                *SWEEP,
                "--jobs",
                "1",
                "--save",
                "none",
                "--out",
                str(tmp_path / "gate"),
                "--fail-under",
                "0.95",
            ]
        )
        == 1
    )
    err = capsys.readouterr().err
    assert err.startswith("twin: error: success rate 0.") and err.endswith(
        "is under --fail-under 0.95\n"
    )
    assert (tmp_path / "gate" / "summary.json").exists() and not (
        tmp_path / "gate" / "failures"
    ).exists()
    # the folder of a sweep: the same sweep again continues only with --resume, another is
    # refused (the summary left byte-identical) until --force
    before = (tmp_path / "gate" / "summary.json").read_bytes()
    again = ["sweep", *SWEEP, "--save", "none", "--out", str(tmp_path / "gate")]
    assert main(again) == 2
    assert "holds this sweep already; expected --resume" in capsys.readouterr().err
    other = [*again, "--seed", "6", "--scenarios", "1"]
    assert main(other) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--out {str(tmp_path / 'gate')!r} is a folder that" in err
    assert (tmp_path / "gate" / "summary.json").read_bytes() == before
    assert main([*other, "--force"]) == 0
    assert json.loads((tmp_path / "gate" / "summary.json").read_text())["scenarios"] == 1


def test_ctrl_c_stops_cleanly_and_keeps_the_results_so_far(tmp_path):
    out = tmp_path / "out"
    args = [a for a in SWEEP if a != "--quiet"]
    args[args.index("10")] = "400"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "sweep",
            *args,
            "--jobs",
            "2",
            "--save",
            "none",
            "--out",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    first = proc.stderr.readline()  # the first progress line: some batches are done
    assert first.startswith("sweep: "), first
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert stderr.endswith("twin: interrupted\n") and "Traceback" not in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert (
        summary["interrupted"] is True
        and summary["planned"] == 400
        and 0 < summary["scenarios"] < 400
    )
    assert pq.read_table(out / "results.parquet").num_rows == summary["scenarios"]
    assert "(stopped part-way)" in stdout


@pytest.mark.slow  # two sweeps of 40 scenarios
def test_a_killed_local_worker_is_replaced_and_changes_nothing(tmp_path):
    import psutil

    args = [a for a in SWEEP if a != "--quiet"]
    args[args.index("10")] = "40"
    assert main(["sweep", *args, "--quiet", "--jobs", "1", "--out", str(tmp_path / "one")]) == 0
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "sweep",
            *args,
            "--jobs",
            "2",
            "--batch",
            "2",
            "--out",
            str(tmp_path / "two"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stderr.readline().startswith("sweep: ")  # batches are coming back
        workers = psutil.Process(proc.pid).children()
        assert len(workers) == 2
        workers[0].kill()  # SIGKILL: the pool breaks; a new one takes the unfinished batches
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert results(tmp_path / "two").equals(results(tmp_path / "one"))


def test_save_all_records_every_scenario_and_timeout_fails_scenarios(tmp_path, capsys):
    out = tmp_path / "all"
    assert (
        main(
            [
                "sweep",
                *SWEEP[:2],
                "4",
                *SWEEP[3:],
                "--jobs",
                "1",
                "--save",
                "all",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rows = pq.read_table(out / "results.parquet").to_pylist()
    assert sorted(p.name for p in (out / "scenarios").iterdir()) == [
        f"scenario-{i}.mcap" for i in range(4)
    ]
    for r in rows:
        if r["outcome"] == "error":
            name = f"scenario-{r['scenario']}.mcap"
            assert (out / "failures" / name).read_bytes() == (out / "scenarios" / name).read_bytes()
    capsys.readouterr()
    assert (
        main(
            [
                "sweep",
                "pick_place",
                "--scenarios",
                "2",
                "--param",
                "cycles=2",
                "--timeout",
                "6",
                "--jobs",
                "1",
                "--save",
                "none",
                "--out",
                str(tmp_path / "slow"),
                "--quiet",
            ]
        )
        == 0
    )
    summary = json.loads((tmp_path / "slow" / "summary.json").read_text())
    assert summary["failures_by_reason"] == {
        "task ran past --timeout # s of simulated time (stopped at t = # s)": 2
    }
