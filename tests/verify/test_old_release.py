"""Goldens recorded by an earlier release (2ffeb44, tests/fixtures/release_2ffeb44: its README says
how) checked by this one. That release's `task_start` named the task by its module, this one by its
source's sha256: only `--tolerance exact` judges that. Each check runs in a child process, here,
with glibc's libm off its FMA code paths and with OpenBLAS's SkylakeX kernel (as in
test_travel.py)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.conftest import FIXTURES
from tests.support.cli import twin, twin_child

RELEASE = FIXTURES / "release_2ffeb44"
OLD = ("carry_mtb", "pick_place_mtb", "pick_place_seed001")
MACHINES = {
    "here": {},
    "no-fma libm": {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA"},
    "SkylakeX BLAS": {"OPENBLAS_CORETYPE": "SkylakeX"},
}
EARLIER = "recorded by an earlier release"


@pytest.fixture
def old(tmp_path) -> Path:
    """A copy of the earlier release's goldens and their task file."""
    shutil.copytree(RELEASE, tmp_path / "old")
    return tmp_path / "old"


def _rows(stdout: str) -> dict[str, str]:
    """`twin check`'s summary table: golden name -> its row."""
    rows = [r for r in stdout.splitlines() if r.split() and r.split()[0].endswith(".mcap")]
    return {Path(r.split()[0]).stem: r for r in rows}


def test_the_fixtures_stay_small():
    sizes = {p.stem: p.stat().st_size for p in RELEASE.glob("*.mcap")}
    assert sorted(sizes) == sorted(OLD)
    assert all(10_000 < size < 300_000 for size in sizes.values()), sizes


@pytest.mark.slow  # seconds: three goldens and their noise runs, in child processes
@pytest.mark.parametrize("machine", MACHINES)
def test_the_earlier_release_goldens_check_green(old, machine):
    """Default preset: all three match, with the note. The built-in pick_place's `placed` message
    was worded '0.00 mm' then, '0.000 mm' now: an earlier release's wording is excused, not its
    numbers (the placement error compares as before)."""
    done = twin_child("check", old, env=MACHINES[machine])
    assert done.returncode == 0, done.stdout + done.stderr
    rows = _rows(done.stdout)
    for name in OLD:
        assert " match " in rows[name], done.stdout
        assert rows[name].endswith(f"; {EARLIER}, behaviour identical"), rows[name]
    # the report says what was excused: against the same task recorded now
    now = old / "now.mcap"
    done = twin_child("run", "pick_place", "--cycles", "1", "--record", now)
    assert done.returncode == 0, done.stdout + done.stderr
    done = twin_child("diff", old / "pick_place_mtb.mcap", now, env=MACHINES[machine])
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"note: {EARLIER}, behaviour identical" in done.stdout
    assert "1 other annotation message worded as that release did" in done.stdout


@pytest.mark.slow  # seconds: three goldens in a child process
def test_exact_still_fails_the_earlier_release_goldens(old):
    done = twin_child("check", "-v", "--tolerance", "exact", old)
    assert done.returncode == 1, done.stdout + done.stderr
    rows = _rows(done.stdout)
    assert all(" differ " in rows[name] for name in OLD), done.stdout
    assert done.stdout.count(f"note: {EARLIER}: task_start names the task ") == 3, done.stdout
    assert "'twin_user_task_carry' in the golden" in done.stdout
    assert "'twin.tasks.pick_place' in the golden" in done.stdout


@pytest.mark.slow  # seconds: a run, two diffs and three replays with their noise runs
def test_diff_and_replay_judge_an_earlier_release_golden_the_same_way(old, capsys):
    """`twin diff` against the same task recorded now: green, but under exact; `twin replay` says
    what the golden said, identity included."""
    again = old / "again.mcap"
    code, out, err = twin(capsys, "run", old / "carry.py", "--param", "hold_s=0.2", "--rate", "4",
                          "--record", again)
    assert code == 0, out + err
    code, out, _ = twin(capsys, "diff", old / "carry_mtb.mcap", again)
    assert code == 0, out
    assert f"note: {EARLIER}, behaviour identical (within the verdict): " in out
    code, out, _ = twin(capsys, "diff", old / "carry_mtb.mcap", again, "--tolerance", "exact")
    assert code == 1, out
    for name in OLD:
        code, out, _ = twin(capsys, "replay", old / f"{name}.mcap")
        assert code == 0 and EARLIER not in out, out
