"""The README's first command, as a new user runs it: in a folder with no runs/ yet (a fresh clone
has none), it records a pick-and-place session to both files. runs/ is the one folder twin makes
when it is missing; any other folder named for an output must exist."""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

import twin

README = Path(__file__).resolve().parents[2] / "README.md"


def _readme_main_command() -> list[str]:
    """The twin part of the README's first line of code (after `pip install ... &&`)."""
    text = README.read_text(encoding="utf-8")
    first = text.split("```bash\n", 1)[1].splitlines()[0]
    command = first.split("&&")[-1].strip()
    assert command.startswith("twin run "), first
    return shlex.split(command)[1:]


def _twin(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "twin.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_the_first_command_records_both_files_where_there_is_no_runs_folder(tmp_path):
    args = _readme_main_command()
    assert not (tmp_path / "runs").exists()
    done = _twin(*args, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    mcap = tmp_path / args[args.index("--record") + 1]
    rrd = tmp_path / args[args.index("--rrd") + 1]
    assert mcap.parent == tmp_path / "runs" and rrd.parent == tmp_path / "runs"
    recording = twin.load(mcap)
    assert recording.outcome == "ok" and len(recording.frames) > 1000
    with open(mcap, "rb") as f:  # the stock reader opens it too
        assert sum(1 for _ in make_reader(f).iter_messages(topics=["/twin/events"])) > 0
    assert rrd.stat().st_size > 0 and not list((tmp_path / "runs").glob("*.partial"))


def test_a_sweep_may_write_into_a_missing_runs_folder(tmp_path):
    done = _twin(
        "sweep",
        "pick_place",
        "--scenarios",
        "2",
        "--param",
        "cycles=1",
        "--vary",
        "box.x_m=uniform(0.19,0.21)",
        "--out",
        "runs/jitter",
        "--jobs",
        "1",
        "--quiet",
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "runs" / "jitter" / "summary.json").is_file()


def test_any_other_missing_folder_is_still_an_error(tmp_path):
    done = _twin("run", "pick_place", "--cycles", "1", "--record", "elsewhere/x.mcap", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "twin: error: cannot write recording 'elsewhere/x.mcap': folder 'elsewhere' "
        "does not exist; create it first"
    )
    assert not (tmp_path / "runs").exists() and not (tmp_path / "elsewhere").exists()
    nested = _twin(
        "run", "pick_place", "--cycles", "1", "--record", "runs/deeper/x.mcap", cwd=tmp_path
    )
    assert nested.returncode == 2 and "folder 'runs/deeper' does not exist" in nested.stderr
