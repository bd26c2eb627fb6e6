"""`twin check --keep DIR`: a golden that differs leaves its re-run, report and diff view in DIR,
one that matches leaves nothing, a file already there is replaced only with --force, and an
interrupted check leaves no partial file."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from support.carry import CARRY
from support.cli import twin

from twin.model.errors import ConfigError
from twin.verify.keep import keep_names

ROOT = Path(__file__).resolve().parents[2]
MOVED = CARRY.replace("place_x_m: float = -0.3,", "place_x_m: float = -0.302,")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """carry.py and goldens/carry.mcap, recorded as the tutorial does."""
    work = tmp_path_factory.mktemp("carry")
    (work / "carry.py").write_text(CARRY)
    (work / "goldens").mkdir()
    code = subprocess.run(
        [sys.executable, "-m", "twin.cli", "run", "carry.py", "--param", "hold_s=0.2"]
        + ["--record", "goldens/carry.mcap"],
        cwd=work,
        capture_output=True,
        check=False,
    ).returncode
    assert code == 0
    return work


def _copy(recorded: Path, folder: Path, task: str) -> Path:
    """A copy of the work folder whose carry.py is task: its golden is goldens/carry.mcap."""
    shutil.copytree(recorded, folder)
    (folder / "carry.py").write_text(task)
    return folder / "goldens"


@pytest.mark.slow  # three runs of carry: 3-4 s here
def test_a_golden_2mm_off_keeps_its_run_report_and_view(recorded, tmp_path, capsys):
    goldens, keep = _copy(recorded, tmp_path / "w", MOVED), tmp_path / "K"
    code, out, _ = twin(capsys, "check", goldens, "--keep", keep)
    assert code == 1
    assert f"kept: {keep}/carry.mcap, {keep}/carry.md, {keep}/carry.rrd" in out
    assert sorted(os.listdir(keep)) == ["carry.mcap", "carry.md", "carry.rrd"]  # no leftovers
    code, out, _ = twin(capsys, "info", keep / "carry.mcap")
    assert code == 0 and "finalized: yes (run outcome ok)" in out
    report = (keep / "carry.md").read_text()
    assert "## First divergence" in report
    assert "- candidate: `carry.mcap (mtb, " in report  # the kept file beside it, not <memory>
    assert (keep / "carry.rrd").stat().st_size > 10_000
    assert (keep / "carry.rrd").read_bytes()[:4] == b"RRF2"
    code, out, _ = twin(capsys, "diff", goldens / "carry.mcap", keep / "carry.mcap", "-q")
    assert code == 1 and "first divergence: step 1326" in out
    # the kept run is the file --update writes over the golden
    assert twin(capsys, "check", goldens, "--update")[0] == 0
    assert (goldens / "carry.mcap").read_bytes() == (keep / "carry.mcap").read_bytes()


def test_a_golden_that_matches_keeps_nothing(recorded, tmp_path, capsys):
    goldens, keep = _copy(recorded, tmp_path / "w", CARRY), tmp_path / "K"
    code, out, _ = twin(capsys, "check", goldens, "--keep", keep)
    assert code == 0 and "kept" not in out
    assert os.listdir(keep) == []  # made, and left empty: no temporary file either


def test_a_refused_update_keeps_the_failed_run(recorded, tmp_path, capsys):
    """--update --keep: a golden whose re-run failed is not rewritten; its run is kept."""
    broken = CARRY.replace('twin.phase("pick")', 'raise RuntimeError("broken")')
    goldens, keep = _copy(recorded, tmp_path / "w", broken), tmp_path / "K"
    before = (goldens / "carry.mcap").read_bytes()
    code, out, _ = twin(capsys, "check", goldens, "--update", "--keep", keep)
    assert code == 1 and " refused " in out
    assert (goldens / "carry.mcap").read_bytes() == before
    assert sorted(os.listdir(goldens)) == ["carry.mcap"]  # no .tmp left beside it
    assert sorted(os.listdir(keep)) == ["carry.mcap", "carry.md", "carry.rrd"]
    code, out, _ = twin(capsys, "info", keep / "carry.mcap")
    assert code == 0 and "run outcome error" in out


def test_keep_refuses_to_replace_a_file_unless_forced(recorded, tmp_path, capsys):
    goldens, keep = _copy(recorded, tmp_path / "w", MOVED), tmp_path / "K"
    keep.mkdir()
    (keep / "carry.md").write_text("my notes\n")
    code, out, err = twin(capsys, "check", goldens, "--keep", keep)
    assert (code, out) == (2, "")  # refused before any work: not even the count line
    assert err == (
        f"twin: error: --keep would replace {str(keep / 'carry.md')!r}; --force replaces files "
        "in the --keep folder\n"
    )
    assert os.listdir(keep) == ["carry.md"] and (keep / "carry.md").read_text() == "my notes\n"
    assert twin(capsys, "check", goldens, "--keep", keep, "--force")[0] == 1
    assert "## First divergence" in (keep / "carry.md").read_text()
    assert sorted(os.listdir(keep)) == ["carry.mcap", "carry.md", "carry.rrd"]


@pytest.mark.parametrize(
    ("keep", "extra", "expected"),
    [
        ("nope/K", [], "--keep '{t}/nope/K': its folder '{t}/nope' does not exist; create it"),
        ("w/carry.py", [], "--keep '{t}/w/carry.py' is a file; expected a folder"),
        ("w/goldens/K", [], "--keep '{t}/w/goldens/K' lies in '{t}/w/goldens', which is checked"),
        ("w/goldens", ["--force"], "--keep '{t}/w/goldens' lies in '{t}/w/goldens', which is"),
        (None, ["--force"], "--force replaces files in the --keep folder and existing --html,"),
    ],
)
def test_a_bad_keep_folder_is_one_line_exit_2(recorded, tmp_path, capsys, keep, extra, expected):
    goldens = _copy(recorded, tmp_path / "w", MOVED)
    args = ["--keep", tmp_path / keep] if keep else []
    code, out, err = twin(capsys, "check", goldens, *args, *extra)
    assert (code, out) == (2, "")
    assert err.startswith("twin: error: " + expected.format(t=tmp_path)) and err.count("\n") == 1


def test_keep_never_writes_over_a_golden_even_forced(recorded, tmp_path, capsys):
    goldens = _copy(recorded, tmp_path / "w", MOVED)
    before = (goldens / "carry.mcap").read_bytes()
    code, _, err = twin(capsys, "check", goldens / "carry.mcap", "--keep", goldens, "--force")
    assert code == 2 and "is a golden's file; expected another folder" in err
    assert (goldens / "carry.mcap").read_bytes() == before


@pytest.mark.slow  # two workers start: 2-3 s here
def test_goldens_sharing_a_stem_are_named_by_their_folders(recorded, tmp_path, capsys):
    assert keep_names(["g/a/x.mcap", "g/b/x.mcap", "g/y.toml", "g/z.mcap", "g/sub/z.mcap"]) == {
        "g/a/x.mcap": "a__x",
        "g/b/x.mcap": "b__x",
        "g/y.toml": "y",
        "g/z.mcap": "z",
        "g/sub/z.mcap": "sub__z",
    }
    with pytest.raises(ConfigError, match=r"would name the files of 'g/x.mcap' and 'g/x.toml' al"):
        keep_names(["g/x.mcap", "g/x.toml"])
    # through the CLI, two workers: two goldens named carry.mcap, both 2 mm off
    work = tmp_path / "ab"
    for sub in ("a", "b"):
        (work / sub).mkdir(parents=True)
        shutil.copy(recorded / "goldens" / "carry.mcap", work / sub)  # names ../carry.py
    (work / "carry.py").write_text(MOVED)
    keep = tmp_path / "K"
    code, out, _ = twin(capsys, "check", work, "-j", "2", "--keep", keep)
    assert code == 1 and out.startswith("checking 2 goldens: 2 recordings\n")
    assert sorted(os.listdir(keep)) == [
        f"{sub}__carry.{ext}" for sub in ("a", "b") for ext in ("mcap", "md", "rrd")
    ]


def test_ctrl_c_while_recording_a_candidate_leaves_nothing(tmp_path):
    keep = tmp_path / "K"
    golden = ROOT / "recordings" / "pick_place_mtb.mcap"
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin.cli", "check", str(golden), "--keep", str(keep)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not (keep.is_dir() and os.listdir(keep)) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert os.listdir(keep) == [".pick_place_mtb.partial.mcap.partial"]  # being recorded
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, out + err
    assert err.endswith("twin: interrupted\n") and "Traceback" not in err
    assert os.listdir(keep) == []


@pytest.mark.slow  # a Dask cluster starts: 6 s here
def test_keep_on_dask_workers(recorded, tmp_path, capsys):
    goldens, keep = _copy(recorded, tmp_path / "w", MOVED), tmp_path / "K"
    code, _, _ = twin(capsys, "check", goldens, "--executor", "dask", "-j", "2", "--keep", keep)
    assert code == 1
    assert sorted(os.listdir(keep)) == ["carry.mcap", "carry.md", "carry.rrd"]
    assert twin(capsys, "info", keep / "carry.mcap")[0] == 0
