"""`twin run --param`: task parameters checked against the task function's signature and recorded,
so `twin check` re-runs them; an unknown one (also `--cycles` for a task without cycles) is exit
2."""

from __future__ import annotations

import math
import subprocess
import sys

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from twin.cli.args import param_pair
from twin.cli.main import build_parser, main
from twin.record.mcap.reader import load
from twin.sweep.dists import parse_dist
from twin.sweep.sampling import RandomSampler
from twin.sweep.spec import SweepSpec, prepare


def test_param_values_are_json_when_they_parse_and_are_recorded(tmp_path, capsys):
    out = tmp_path / "p.mcap"
    assert (
        main(
            [
                "run",
                "pick_place",
                "--param",
                "cycles=1",
                "--param",
                "pause_s=0.25",
                "--param",
                "box=box",
                "--record",
                str(out),
            ]
        )
        == 0
    )
    assert load(out).run["params"] == {"cycles": 1, "pause_s": 0.25, "box": "box"}
    capsys.readouterr()
    assert main(["check", str(out)]) == 0  # the stored params re-run the same task


def test_unknown_params_are_one_line_exit_2(capsys):
    assert main(["run", "pick_place", "--param", "speed=2", "--no-record"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "twin: error: task 'pick_place' takes no parameter 'speed'; its parameters: "
        "cycles, pause_s, "
        "box, keep_going, max_error_m\n"
    )
    assert main(["run", "seed002", "--robot", "seed002", "--cycles", "3", "--no-record"]) == 2
    assert (
        capsys.readouterr().err
        == "twin: error: task 'seed002' takes no parameter 'cycles'; its parameters: none\n"
    )
    assert main(["run", "pick_place", "--cycles", "1", "--param", "cycles=2", "--no-record"]) == 2
    assert "--cycles and --param cycles" in capsys.readouterr().err
    assert main(["run", "pick_place", "--param", "=1", "--no-record"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_cycles_default_still_reaches_tasks_that_take_it(tmp_path):
    out = tmp_path / "s.mcap"
    assert main(["run", "seed002", "--robot", "seed002", "--record", str(out)]) == 0
    assert load(out).run["params"] == {}
    assert main(["run", "pick_place", "--record", str(out), "--force"]) == 0
    assert load(out).run["params"] == {"cycles": 2}


# Values are checked for everything they meet (a Parquet int64 column, numpy's arithmetic, a task's
# float), before anything runs: an integer outside int64, NaN, an infinity or a distribution whose
# arithmetic overflows is one line, exit 2, and no scenario or task runs.

INT_TASK = "def run(twin, k: int = 0, x: float = 0.0):\n    twin.wait(0.01)\n"
LONG = "1" + "0" * 5000  # more digits than Python's int() reads by default


@pytest.mark.parametrize(
    ("vary", "message"),
    [
        (
            "task.k=choice(9223372036854775808)",
            (
                "--vary task.k=choice(9223372036854775808) is invalid: "
                "9223372036854775808 is outside int64; "
                "expected a whole number -2**63..2**63-1 (int64)"
            ),
        ),
        ("task.k=choice(1,-9223372036854775809)", "-9223372036854775809 is outside int64"),
        ("task.k=9223372036854775808", "9223372036854775808 is outside int64"),
        pytest.param(
            f"task.k={LONG}", "...(5001 characters) is outside int64", id="task.k=<5001 digits>"
        ),
        (
            "task.x=uniform(-1.7e308,1.7e308)",
            (
                "--vary task.x=uniform(-1.7e308,1.7e308) is invalid; expected "
                "uniform(a,b) with b - a finite (at most +-1.8e308)"
            ),
        ),
        (
            "task.x=normal(0,1e308)",
            (
                "--vary task.x=normal(0,1e308) is invalid; expected normal(mu,sigma) with "
                "mu +- 40*sigma finite (at most +-1.8e308)"
            ),
        ),
        ("task.x=normal(1.79e308,1e307)", "with mu +- 40*sigma finite"),
        (
            "task.x=uniform(0,1e400)",
            "1e400 is not a finite number; expected a finite number (at most +-1.8e308)",
        ),
        ("task.x=choice(0.5,-Infinity)", "-Infinity is not a finite number"),
        ("task.x=choice(0.5,nan)", "nan is not a finite number"),
        ("task.x=inf", "inf is not a finite number"),
    ],
)
def test_values_that_cannot_be_carried_are_refused_before_any_scenario_runs(
    tmp_path, capsys, vary, message
):
    task, out = tmp_path / "task.py", tmp_path / "out"
    task.write_text(INT_TASK)
    assert (
        main(
            [
                "sweep",
                str(task),
                "--scenarios",
                "4",
                "--jobs",
                "1",
                "--quiet",
                "--vary",
                vary,
                "--out",
                str(out),
            ]
        )
        == 2
    )
    captured = capsys.readouterr()
    assert captured.err.startswith("twin: error: ") and captured.err.count("\n") == 1, captured.err
    assert message in captured.err and len(captured.err) < 300
    assert captured.out == "" and not out.exists()  # nothing ran, nothing was written


def test_sweep_param_values_are_checked_like_run_params(tmp_path, capsys):
    out = tmp_path / "out"
    assert (
        main(
            [
                "sweep",
                "pick_place",
                "--scenarios",
                "2",
                "--param",
                "cycles=9223372036854775808",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert (
        "--param cycles=9223372036854775808 is invalid: 9223372036854775808 is outside int64" in err
    )
    assert err.count("\n") == 1 and not out.exists()


def test_the_int64_ends_and_the_widest_finite_distributions_are_accepted_and_stay_finite(
    tmp_path, capsys
):
    top, bottom = 2**63 - 1, -(2**63)
    assert parse_dist(f"choice({bottom}, {top})").args == (bottom, top)
    spec = SweepSpec(
        "pick_place",
        10,
        vary=(
            ("task.pause_s", "uniform(-8.9e307, 8.9e307)"),
            ("task.max_error_m", "normal(1e308, 1.9e306)"),
        ),
    )
    sampler = RandomSampler(0, prepare(spec).keys)
    draws = [v for i in range(2000) for v in sampler.values(i).values()]
    assert all(math.isfinite(v) for v in draws)
    task, out = tmp_path / "task.py", tmp_path / "out"  # the ends reach results.parquet as int64
    task.write_text(INT_TASK)
    assert (
        main(
            [
                "sweep",
                str(task),
                "--scenarios",
                "6",
                "--jobs",
                "1",
                "--quiet",
                "--vary",
                f"task.k=choice({bottom},{top})",
                "--out",
                str(out),
            ]
        )
        == 0
    ), capsys.readouterr().err
    table = pq.read_table(out / "results.parquet")
    assert table.schema.field("task.k").type == pa.int64()
    assert set(table.column("task.k").to_pylist()) <= {bottom, top}


@pytest.mark.parametrize(
    ("param", "message"),
    [
        (
            "cycles=1e400",
            (
                "--param cycles=1e400 is invalid: 1e400 is not a finite number; expected a "
                "finite number"
            ),
        ),
        ("pause_s=NaN", "--param pause_s=NaN is invalid: NaN is not a finite number"),
        ("pause_s=nan", "--param pause_s=nan is invalid: nan is not a finite number"),
        ("pause_s=-Infinity", "-Infinity is not a finite number"),
        (
            "pause_s=[0.1,1e999]",
            "--param pause_s=[0.1,1e999] is invalid: 1e999 is not a finite number",
        ),
        (
            "cycles=9223372036854775808",
            (
                "--param cycles=9223372036854775808 is invalid: 9223372036854775808 is "
                "outside int64; expected a whole number -2**63..2**63-1 (int64)"
            ),
        ),
        ("cycles=-9223372036854775809", "-9223372036854775809 is outside int64"),
        pytest.param(
            f"cycles={LONG}", "...(5001 characters) is outside int64", id="cycles=<5001 digits>"
        ),
        pytest.param(
            "pause_s=" + "[" * 100_000 + "]" * 100_000,
            "nest more than 64 levels deep",
            id="deep-100000",
        ),
        pytest.param(
            "pause_s=" + "[" * 65 + "]" * 65, "nest more than 64 levels deep", id="deep-65"
        ),
    ],
)
def test_run_params_that_are_not_finite_or_beyond_int64_are_one_line_exit_2(
    tmp_path, capsys, param, message
):
    out = tmp_path / "p.mcap"
    assert main(["run", "pick_place", "--param", param, "--record", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("twin: error: ") and captured.err.count("\n") == 1, captured.err
    assert message in captured.err and len(captured.err) < 300
    assert captured.out == "" and not out.exists()  # the task never started


def test_run_param_values_at_the_limits_and_the_help_text():
    assert param_pair("cycles=9223372036854775807") == ("cycles", 2**63 - 1)
    assert param_pair("k=-9223372036854775808") == ("k", -(2**63))
    assert param_pair("x=1.7e308") == ("x", 1.7e308)
    assert param_pair('box="nan"') == ("box", "nan")  # quoted: text
    assert param_pair("box=inf_box") == ("box", "inf_box")  # not a number: text
    assert param_pair("xs=[1, 2.5, true]") == ("xs", [1, 2.5, True])
    text = " ".join(
        build_parser()._subparsers._group_actions[0].choices["run"].format_help().split()
    )
    assert "NaN, infinities (1e400, inf) and integers outside int64 are refused" in text


def test_a_refused_param_from_a_real_process_has_no_traceback(tmp_path):
    for args in (
        ["run", "pick_place", "--param", "cycles=1e400"],
        [
            "sweep",
            "pick_place",
            "--scenarios",
            "2",
            "--vary",
            "task.pause_s=uniform(-1.7e308,1.7e308)",
            "--out",
            str(tmp_path / "out"),
        ],
    ):
        done = subprocess.run(
            [sys.executable, "-m", "twin", *args],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
        assert done.returncode == 2 and done.stdout == "" and done.stderr.count("\n") == 1, (
            done.stderr
        )
        assert "Traceback" not in done.stderr and "OverflowError" not in done.stderr
    assert list(tmp_path.iterdir()) == []  # no recording, no sweep folder
