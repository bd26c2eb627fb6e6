"""Statistical goldens: `twin check NAME.toml` (and a folder of them) re-runs a sweep and judges its
summary by the golden's Wilson interval and the placement-error tolerances; --update writes it."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support.read_only import read_only

from twin.cli.main import main
from twin.model.errors import ConfigError
from twin.sweep import golden as golden_module
from twin.sweep.golden import check_summary, judge
from twin.sweep.spec import load_spec
from twin.sweep.stats import wilson
from twin.verify.check import find_goldens

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
    # a golden's rate lies in its own interval (the summary is validated)
    ok = 0 if summary["ok"] > 6 else 12
    summary.update(
        ok=ok,
        failed=12 - ok,
        success_rate=ok / 12,
        wilson95=list(wilson(ok, 12)),
        failures_by_reason={"suction on at (#, #), nothing sensed": 12 - ok} if ok < 12 else {},
    )
    summary["placement_error_mm"]["p95"] -= 0.4
    (tmp_path / "moved.summary.json").write_text(json.dumps(summary))
    capsys.readouterr()
    assert main(["check", str(tmp_path / "moved.toml")]) == 1
    out = capsys.readouterr().out
    assert (
        "differ" in out
        and "success_rate" in out
        and "outside the golden's Wilson 95 % interval" in out
    )
    assert "placement_error_mm.p95 moved +0.400 mm" in out and "tolerance 0.25 mm" in out
    assert main(["check", str(tmp_path / "moved.toml"), "--update"]) == 0
    assert json.loads((tmp_path / "moved.summary.json").read_text()) == json.loads(
        (golden / "small.summary.json").read_text()
    )


def test_update_into_a_read_only_folder_is_one_output_error(golden, tmp_path, capsys):
    """The new summary cannot be written: exit 2 (OutputError's), one line naming the file, the
    golden as it was and nothing left beside it."""
    folder = tmp_path / "locked"
    folder.mkdir()
    shutil.copy(golden / "small.toml", folder / "small.toml")
    summary = json.loads((golden / "small.summary.json").read_text())
    summary["placement_error_mm"]["p95"] -= 0.4
    (folder / "small.summary.json").write_text(json.dumps(summary))
    before = sorted((p.name, p.read_bytes()) for p in folder.iterdir())
    capsys.readouterr()
    with read_only(folder):
        assert main(["check", str(folder / "small.toml"), "--update"]) == 2
        out = capsys.readouterr().out
        assert sorted((p.name, p.read_bytes()) for p in folder.iterdir()) == before
    lines = [line for line in out.splitlines() if "cannot write" in line]
    assert len(lines) == 1 and str(folder / "small.summary.json") in lines[0], out
    assert "Traceback" not in out


def test_keep_writes_the_report_and_the_new_summary_of_a_moved_sweep(golden, tmp_path, capsys):
    definition = _copy(
        golden,
        tmp_path,
        summary=lambda d: d["placement_error_mm"].update(p95=d["placement_error_mm"]["p95"] - 0.4),
    )
    keep = tmp_path / "K"
    capsys.readouterr()
    assert main(["check", str(definition), "--keep", str(keep)]) == 1
    assert f"kept: {keep}/g.md, {keep}/g.summary.json" in capsys.readouterr().out
    assert sorted(os.listdir(keep)) == ["g.md", "g.summary.json"]  # no results: not paired
    # the new run's summary: the one the module's golden was written with
    assert json.loads((keep / "g.summary.json").read_text()) == json.loads(
        (golden / "small.summary.json").read_text()
    )
    report = (keep / "g.md").read_text()
    assert report.startswith("# sweep golden g: differ\n")
    assert "placement_error_mm.p95 moved +0.400 mm" in report and "success_rate" in report


def test_judge_allows_moves_within_tolerance():
    golden = {
        "scenarios": 100,
        "success_rate": 0.9,
        "wilson95": [0.82, 0.95],
        "placement_error_mm": {"p50": 1.0, "p95": 2.0, "max": 3.0},
    }
    near = {
        "scenarios": 100,
        "success_rate": 0.86,
        "placement_error_mm": {"p50": 1.4, "p95": 2.9, "max": 1.5},
    }
    tol = {"placement_p50_mm": 0.5, "placement_p95_mm": 1.0, "placement_max_mm": 2.0}
    assert judge(golden, near, tol) == []
    far = {**near, "success_rate": 0.8, "placement_error_mm": {"p50": 1.6, "p95": 2.9, "max": 1.5}}
    assert judge(golden, far, tol) == [
        (
            "success_rate 0.8000 is outside the golden's Wilson 95 % interval [0.8200, "
            "0.9500] (golden 0.9000, moved -0.1000)"
        ),
        "placement_error_mm.p50 moved +0.600 mm (golden 1.000, now 1.600; tolerance 0.5 mm)",
    ]


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


def _copy(golden, folder, name="g", *, toml=None, summary=None):
    """The module's golden copied into folder as NAME.toml and NAME.summary.json; toml edits the
    definition's text, summary edits the summary (a dict) in place."""
    text = (golden / "small.toml").read_text()
    (folder / f"{name}.toml").write_text(toml(text) if toml else text)
    data = json.loads((golden / "small.summary.json").read_text())
    if summary:
        summary(data)
    (folder / f"{name}.summary.json").write_text(json.dumps(data, indent=2))
    return folder / f"{name}.toml"


def _check(path, *options):
    """`python -m twin check PATH` in a fresh process (a hang fails the test after 120 s)."""
    return subprocess.run(
        [sys.executable, "-m", "twin", "check", str(path), *options],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )


@pytest.mark.parametrize("value", ["nan", "inf", "-0.5"])
def test_a_tolerance_that_is_not_a_finite_number_ge_0_is_exit_2(golden, tmp_path, capsys, value):
    definition = _copy(
        golden,
        tmp_path,
        toml=lambda t: t.replace("placement_p95_mm = 0.25", f"placement_p95_mm = {value}"),
    )
    capsys.readouterr()
    assert main(["check", str(definition)]) == 2  # a NaN tolerance passed any move before (exit 0)
    out = capsys.readouterr().out
    shown = repr(float(value))
    assert f"tolerance placement_p95_mm = {shown} is invalid; expected one of" in out
    assert "a finite number >= 0 (mm)" in out and "g.toml" in out


def test_a_nan_in_the_golden_statistics_is_exit_2_not_within_tolerance(golden, tmp_path):
    # the case measured: p95 976 mm away and NaN in the golden read "within tolerance"
    def moved_far(data):
        data["placement_error_mm"].update(p50=math.nan, p95=math.nan, max=math.nan)

    definition = _copy(golden, tmp_path, summary=moved_far)
    done = _check(definition)
    assert done.returncode == 2, done.stdout + done.stderr
    line = next(line for line in done.stdout.splitlines() if "g.toml" in line)
    assert (
        " error " in line
        and "g.summary.json': placement_error_mm.p50 NaN is invalid; expected a finite number "
        "of mm (count is 12)"
        in line
    )
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda d: d.update(wilson95=[-math.inf, math.inf]),
            "wilson95 [-Infinity, Infinity] is invalid; expected [lo, hi], two finite numbers",
        ),
        (
            lambda d: d.update(wilson95=None),
            "wilson95 null is invalid; expected [lo, hi], two finite numbers",
        ),
        (
            lambda d: d.update(wilson95=[0.0]),
            "wilson95 [0.0] is invalid; expected [lo, hi], two finite numbers",
        ),
        (
            lambda d: d.update(wilson95=[0.2, 0.5]),
            "wilson95 [0.2, 0.5] is invalid; expected 0 <= lo <= success_rate",
        ),
        (
            lambda d: d.update(wilson95=[-0.1, 1.0]),
            "wilson95 [-0.1, 1.0] is invalid; expected 0 <= lo",
        ),
        (
            lambda d: d.update(success_rate="0.9"),
            "success_rate '0.9' is invalid; expected a finite number 0..1",
        ),
        (
            lambda d: d.update(success_rate=math.nan),
            "success_rate NaN is invalid; expected a finite number 0..1",
        ),
        (
            lambda d: d.update(success_rate=0.5),
            "success_rate 0.5 is invalid; expected ok / scenarios",
        ),
        (
            lambda d: d.update(scenarios=True),
            "scenarios true is invalid; expected a whole number >= 0",
        ),
        (lambda d: d.update(ok=1.5), "ok 1.5 is invalid; expected a whole number >= 0"),
        (lambda d: d.pop("failed"), "failed null is invalid; expected a whole number >= 0"),
        (
            lambda d: d.update(failed=d["failed"] + 1),
            "ok + failed 13 is invalid; expected scenarios (12)",
        ),
        (
            lambda d: d.update(placement_error_mm=[1, 2]),
            "placement_error_mm [1, 2] is invalid; expected an object",
        ),
        (
            lambda d: d["placement_error_mm"].update(count=-1),
            "placement_error_mm.count -1 is invalid; expected a whole",
        ),
        # numbers with count 0
        (lambda d: d["placement_error_mm"].update(count=0), "placement_error_mm.p50 "),
        (
            lambda d: d["placement_error_mm"].update(p95=math.inf),
            "placement_error_mm.p95 Infinity is invalid",
        ),
        (
            lambda d: d["placement_error_mm"].update(max="2"),
            "placement_error_mm.max '2' is invalid; expected a finite",
        ),
        (lambda d: d["placement_error_mm"].update(p50=1e6), "expected p50 <= p95 <= max"),
        (
            lambda d: d.update(failures_by_reason=None),
            "failures_by_reason null is invalid; expected an object",
        ),
        (
            lambda d: d.update(failures_by_reason={"x": 1}),
            'failures_by_reason {"x": 1} is invalid; expected counts',
        ),
    ],
)
def test_a_malformed_golden_summary_is_one_line_naming_field_value_and_expectation(
    golden, edit, message
):
    data = json.loads((golden / "small.summary.json").read_text())
    # the real one is valid
    assert check_summary(json.loads(json.dumps(data)), "g.summary.json") == data
    edit(data)
    with pytest.raises(ConfigError) as err:
        check_summary(json.loads(json.dumps(data)), "g.summary.json")
    assert str(err.value).startswith("sweep golden summary 'g.summary.json': ") and "\n" not in str(
        err.value
    )
    assert message in str(err.value)


def test_a_malformed_golden_summary_is_exit_2_through_the_cli(golden, tmp_path, capsys):
    for name, edit in (
        ("nulled", lambda d: d.update(wilson95=None)),
        ("texts", lambda d: d.update(success_rate="1")),
        ("listed", None),
    ):
        definition = _copy(golden, tmp_path, name, summary=edit)
        if edit is None:
            (tmp_path / "listed.summary.json").write_text("[1, 2]")
        capsys.readouterr()
        # tracebacks before (TypeError, ValueError, AttributeError)
        assert main(["check", str(definition)]) == 2
        out = capsys.readouterr().out
        assert f"{name}.summary.json': " in out and "is invalid; expected" in out
    # no placements at all: count 0, nulls
    empty = json.loads((golden / "small.summary.json").read_text())
    empty["placement_error_mm"] = {"count": 0, "p50": None, "p95": None, "max": None}
    assert check_summary(empty, "e.summary.json") is empty


def test_a_datetime_in_params_is_one_line_exit_2(golden, tmp_path, capsys):
    for value, shown in (
        ("1979-05-27T07:32:00Z", "1979-05-27T07:32:00+00:00 (a TOML datetime)"),
        ("1979-05-27", "1979-05-27 (a TOML date)"),
        ("[1, 07:32:00]", "07:32:00 (a TOML time)"),
        ("{ at = nan }", "nan"),
        ("9223372036854775808", "9223372036854775808 (beyond int64)"),
    ):
        definition = _copy(
            golden,
            tmp_path,
            toml=lambda t, v=value: t.replace("[params]\n", f"[params]\nbox = {v}\n"),
        )
        with pytest.raises(ConfigError, match="params.box holds ") as err:
            load_spec(definition)
        assert str(err.value) == (
            f"sweep definition {str(definition)!r}: params.box holds {shown}; expected a finite "
            "number, an int64 whole number, true/false, text, or a list or table of them"
        )
        capsys.readouterr()
        # a TypeError traceback from json.dumps before
        assert main(["check", str(definition), "--update"]) == 2
        assert "params.box holds" in capsys.readouterr().out
    definition = _copy(
        golden, tmp_path, toml=lambda t: t.replace("seed = 3", "seed = 3\nrate_hz = true")
    )
    with pytest.raises(ConfigError, match="rate_hz = True is invalid; expected a number"):
        load_spec(definition)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_fifo_is_refused_not_waited_on(golden, tmp_path):
    definition = _copy(golden, tmp_path)
    (tmp_path / "g.summary.json").unlink()
    os.mkfifo(tmp_path / "g.summary.json")
    done = _check(definition)  # waited for a writer for ever before
    assert done.returncode == 2, done.stdout + done.stderr
    assert (
        "g.summary.json' is not a regular file (a FIFO, device or folder); expected a file"
        in done.stdout
    )
    os.mkfifo(tmp_path / "pipe.toml")
    with pytest.raises(ConfigError, match="'.*pipe.toml' is not a regular file"):
        find_goldens([str(tmp_path / "pipe.toml")])
    # a folder's FIFO is no definition: skipped
    assert _found(tmp_path) == ([], [str(definition)])


def test_an_oversized_summary_is_refused(golden, tmp_path, capsys, monkeypatch):
    definition = _copy(golden, tmp_path)
    size = (tmp_path / "g.summary.json").stat().st_size
    monkeypatch.setattr(golden_module, "MAX_BYTES", size - 1)
    capsys.readouterr()
    assert main(["check", str(definition)]) == 2
    assert (
        f"g.summary.json' holds {size} bytes; expected at most {size - 1}"
        in capsys.readouterr().out
    )


def test_update_replaces_the_summary_atomically(golden, tmp_path, capsys, monkeypatch):
    definition = _copy(
        golden,
        tmp_path,
        summary=lambda d: d["placement_error_mm"].update(max=d["placement_error_mm"]["max"] + 5),
    )
    os.chmod(tmp_path / "g.summary.json", 0o640)
    before = (tmp_path / "g.summary.json").read_text()
    renames = []
    real_replace = os.replace

    # the new summary is complete before it takes the golden's name; the old one intact
    def replace(src, dst):
        if str(dst).endswith(".json"):  # the summary (the results beside it are Parquet)
            renames.append(
                (
                    os.path.basename(src),
                    os.path.basename(dst),
                    Path(src).read_text(),
                    Path(dst).read_text(),
                )
            )
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    assert main(["check", str(definition), "--update"]) == 0
    after = (tmp_path / "g.summary.json").read_text()
    assert after == (golden / "small.summary.json").read_text() != before
    [(src, _, new_text, old_text)] = [r for r in renames if r[1] == "g.summary.json"]
    assert (
        src.startswith(".g.summary.json.")  # hidden, beside it (twin.record.outputs.atomic_path)
        and src.endswith(".tmp")
        and new_text == after
        and old_text == before
    )
    assert oct((tmp_path / "g.summary.json").stat().st_mode & 0o777) == oct(0o640)
    # nothing left beside it; the per-scenario results were written too (a paired golden from now
    # on)
    assert sorted(f.name for f in tmp_path.iterdir()) == [
        "g.results.parquet",
        "g.summary.json",
        "g.toml",
    ]

    def fail(src, dst):
        raise OSError(28, "No space left on device")

    (tmp_path / "g.summary.json").write_text(before)
    monkeypatch.setattr(os, "replace", fail)
    capsys.readouterr()
    assert main(["check", str(definition), "--update"]) == 2
    assert "g.summary.json': No space left on device" in capsys.readouterr().out
    # untouched, and no partial file left
    assert (tmp_path / "g.summary.json").read_text() == before
    assert sorted(f.name for f in tmp_path.iterdir()) == [
        "g.results.parquet",
        "g.summary.json",
        "g.toml",
    ]


PROFILE = """\
# a robot profile kept beside the goldens (twin/robot/profile_files.py)
urdf = "arm.urdf"
pad_link = "pad"

[joints]
base = "j1"
"""


def _found(path) -> tuple[list[str], list[str]]:
    """The .mcap and sweep goldens `twin check PATH` takes."""
    goldens = find_goldens([str(path)])
    return goldens.recordings, goldens.sweeps


def test_a_folder_takes_only_its_sweep_definitions(golden, tmp_path, capsys):
    shutil.copytree(ROOT / "recordings" / "sweeps", tmp_path / "sweeps")
    (tmp_path / "sweeps" / "arm.toml").write_text(PROFILE)
    shipped = str(tmp_path / "sweeps" / "pick_place_jitter.toml")
    # the profile: skipped, silently
    assert _found(tmp_path / "sweeps") == ([], [shipped])
    (tmp_path / "recs").mkdir()
    # beside .mcap goldens: `twin check recordings`
    (tmp_path / "recs" / "arm.toml").write_text(PROFILE)
    (tmp_path / "recs" / "a.mcap").write_bytes(b"")
    assert _found(tmp_path / "recs") == ([str(tmp_path / "recs" / "a.mcap")], [])
    with pytest.raises(
        ConfigError,
        match=r"^sweep definition '.*arm.toml' lacks task, scenarios, seed; expected a "
        r"sweep definition with task, scenarios, seed$",
    ):
        find_goldens([str(tmp_path / "recs" / "arm.toml")])  # named: must be one
    (tmp_path / "sweeps" / "old.toml").write_text('task = "pick_place"\nscenarios = 3\n')
    (tmp_path / "sweeps" / "old.summary.json").write_text("{}")
    with pytest.raises(
        ConfigError, match=r"old.toml' \(beside old.summary.json\) lacks seed; expected"
    ):
        # a golden (its summary beside it) that is no definition: never skipped
        find_goldens([str(tmp_path / "sweeps")])
    (tmp_path / "sweeps" / "old.toml").write_text("task = \n")
    with pytest.raises(ConfigError, match="old.toml' .* is not valid TOML"):
        find_goldens([str(tmp_path / "sweeps")])
    (tmp_path / "sweeps" / "old.summary.json").unlink()
    assert _found(tmp_path / "sweeps") == ([], [shipped])

    # what the CLI does with it: the profile is not a golden, exit 0 (2 before)
    folder = tmp_path / "mixed"
    folder.mkdir()
    _copy(golden, folder, "small")
    (folder / "arm.toml").write_text(PROFILE)
    capsys.readouterr()
    assert main(["check", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "small.toml" in out and "arm.toml" not in out
    capsys.readouterr()
    assert main(["check", str(folder / "arm.toml")]) == 2
    assert "arm.toml' lacks task, scenarios, seed" in capsys.readouterr().err


def test_deep_nesting_in_a_definition_or_summary_is_one_line_exit_2(tmp_path, capsys):
    definition = tmp_path / "deep.toml"
    definition.write_text(
        'task = "pick_place"\nscenarios = 2\nseed = 0\n[params]\nx = '
        + "[" * 5000
        + "]" * 5000
        + "\n"
    )
    assert main(["sweep", str(definition), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "nest more than 64 levels deep" in err and err.count("\n") == 1
    (tmp_path / "g.toml").write_text('task = "pick_place"\nscenarios = 2\nseed = 0\n')
    (tmp_path / "g.summary.json").write_text("[" * 100_000)
    assert main(["check", str(tmp_path / "g.toml")]) == 2
    assert (
        "is not valid JSON: arrays or tables nest more than 64 levels deep"
        in capsys.readouterr().out
    )
