"""`twin bisect` in real git repositories: a golden recorded at the first commit, 15 commits after
it, one of which moves the task's pick point by 1 mm. Real `twin check` runs, no mocks."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.support.cli import twin_child
from twin.cli import main

TWIN_CHILD = [sys.executable, "-m", "twin"]

GIT_ENV = {
    "GIT_AUTHOR_NAME": "Test",
    "GIT_AUTHOR_EMAIL": "test@example.com",
    "GIT_COMMITTER_NAME": "Test",
    "GIT_COMMITTER_EMAIL": "test@example.com",
}

# the tutorial's carry, short holds: one check is about half a second
TASK = """\
def run(twin, place_x_m: float = -0.3, place_y_m: float = -0.55, hold_s: float = 0.05):
    twin.raise_()
    twin.move_to(0.2, 0.7)
    twin.suction(True)
    twin.lower()
    twin.wait(hold_s)
    twin.raise_()
    twin.move_to(place_x_m, place_y_m)
    twin.lower()
    twin.suction(False)
    twin.wait(hold_s)
"""
MOVED = 9  # "change 9" moves the pick point by 1 mm
BROKEN = 7  # in the skip repository: "change 7" breaks the task's syntax, "change 8" mends it


def git(repo: Path, *args: str) -> str:
    done = subprocess.run(
        ["git", *args],
        cwd=repo,
        env={**os.environ, **GIT_ENV},
        capture_output=True,
        text=True,
        check=True,
    )
    return done.stdout.strip()


def make_repo(path: Path, broken: int | None = None) -> Path:
    """A repository: carry.py committed, golden.mcap recorded from it (not committed), then 15
    commits `change 1` .. `change 15`; the MOVED one moves the pick point by 1 mm, and when broken
    is given that commit breaks carry.py's syntax and the next one mends it."""
    path.mkdir()
    git(path, "init", "-q", "-b", "main")
    git(path, "config", "user.name", GIT_ENV["GIT_AUTHOR_NAME"])
    git(path, "config", "user.email", GIT_ENV["GIT_AUTHOR_EMAIL"])
    task = path / "carry.py"
    task.write_text(TASK)
    git(path, "add", "carry.py")
    git(path, "commit", "-q", "-m", "first: carry")
    assert main(["run", str(task), "--record", str(path / "golden.mcap")]) == 0
    for i in range(1, 16):
        (path / "notes.txt").write_text(f"note {i}\n")
        text = TASK if i < MOVED else TASK.replace("move_to(0.2, 0.7)", "move_to(0.201, 0.7)")
        if i == broken:
            text += "def oops(:\n"
        task.write_text(text)
        git(path, "add", "carry.py", "notes.txt")
        git(path, "commit", "-q", "-m", f"change {i}")
    return path


def state(repo: Path) -> dict:
    """What a bisect must leave as it was."""
    return {
        "status": git(repo, "status", "--porcelain", "--untracked-files=all"),
        "head": git(repo, "rev-parse", "HEAD"),
        "branch": git(repo, "symbolic-ref", "HEAD"),
        "stash": git(repo, "stash", "list"),
        "worktrees": git(repo, "worktree", "list", "--porcelain"),
    }


def bisect(repo: Path, *args: str) -> tuple[subprocess.CompletedProcess, dict | None]:
    report = repo.parent / f"{repo.name}-bisect.json"
    report.unlink(missing_ok=True)
    done = twin_child("bisect", *args, "--json", report, cwd=repo)
    return done, json.loads(report.read_text()) if report.exists() else None


@pytest.fixture(scope="module")
def repo(tmp_path_factory) -> Path:
    return make_repo(tmp_path_factory.mktemp("bisect") / "repo")


@pytest.fixture(scope="module")
def first_bisect(repo):
    """The first bisect over the repository: (state before, its run, its JSON, state after)."""
    before = state(repo)
    done, found = bisect(repo, "--good", "HEAD~15", "--bad", "HEAD", "golden.mcap")
    return before, done, found, state(repo)


@pytest.mark.slow
def test_bisect_names_the_commit_that_moved_the_pick_point_and_leaves_the_repo_alone(
    repo, first_bisect
):
    before, done, found, after = first_bisect
    assert done.returncode == 0, done.stderr
    moved = git(repo, "rev-parse", f"HEAD~{15 - MOVED}")
    assert found["outcome"] == "found"
    assert found["first_bad"]["commit"] == moved
    assert f"first bad commit: {moved} change {MOVED}" in done.stdout
    assert len(found["tried"]) <= 6, [t["subject"] for t in found["tried"]]
    assert found["from_cache"] == 0
    # the golden that flips, in the words of twin check's summary line
    (flip,) = found["flipped"]
    assert flip["golden"] == "golden.mcap" and "joint_target" in flip["summary"]
    assert f"  golden.mcap: {flip['summary']}" in done.stdout
    assert after == before  # work tree, HEAD, branch, stash, no worktree left
    assert (repo / ".twin-bisect" / ".gitignore").read_text() == "*\n"


@pytest.mark.slow
def test_a_second_bisect_over_the_range_takes_every_verdict_from_the_cache(repo, first_bisect):
    _, _, first, _ = first_bisect
    done, again = bisect(repo, "--good", "HEAD~15", "golden.mcap")  # --bad: HEAD by default
    assert done.returncode == 0, done.stderr
    assert again["first_bad"]["commit"] == first["first_bad"]["commit"]
    assert [t["commit"] for t in again["tried"]] == [t["commit"] for t in first["tried"]]
    assert all(t["cached"] for t in again["tried"])
    n = len(again["tried"])
    assert f"({0} checked, {n} from the cache .twin-bisect/)" in done.stdout


@pytest.mark.slow
def test_an_existing_json_is_replaced_only_with_force(repo, first_bisect, tmp_path):
    report = tmp_path / "verdicts.json"
    report.write_text("my notes\n")
    args = ("bisect", "--good", "HEAD~15", "golden.mcap", "--json", report)
    done = twin_child(*args, cwd=repo)
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr == (
        f"twin: error: --json {str(report)!r} exists already; expected a new path, or --force "
        "to replace it\n"
    )
    assert report.read_text() == "my notes\n"
    done = twin_child(*args, "--force", cwd=repo)  # every verdict from the cache: quick
    assert done.returncode == 0, done.stderr
    found = json.loads(report.read_text())["first_bad"]
    assert found["commit"] == first_bisect[2]["first_bad"]["commit"] and found["cached"]
    assert [p.name for p in tmp_path.iterdir()] == ["verdicts.json"]  # no temporary left


@pytest.mark.slow
def test_a_commit_whose_task_does_not_load_is_skipped_and_the_search_goes_on(tmp_path):
    repo = make_repo(tmp_path / "repo", broken=BROKEN)
    before = state(repo)
    done, found = bisect(repo, "--good", "HEAD~15", "golden.mcap")
    assert done.returncode == 0, done.stderr
    broken = git(repo, "rev-parse", f"HEAD~{15 - BROKEN}")
    (skipped,) = [t for t in found["tried"] if t["verdict"] == "skip"]
    assert skipped["commit"] == broken  # the search's first middle: it was tried
    assert "failed to import" in skipped["reason"]
    assert f"skip  {broken[:12]} change {BROKEN}" in done.stdout
    assert found["first_bad"]["commit"] == git(repo, "rev-parse", f"HEAD~{15 - MOVED}")
    assert state(repo) == before


def test_bad_input_is_exit_2_and_one_line(tmp_path, repo):
    outside = tmp_path / "not-a-repo"
    outside.mkdir()
    cases = [
        (outside, ["--good", "HEAD"], "is not in a git repository"),
        (repo, ["--good", "no-such-rev", "golden.mcap"], "'no-such-rev' is no commit"),
        (repo, ["--good", "HEAD", "--bad", "HEAD~3", "golden.mcap"], "is not an ancestor of"),
    ]
    for cwd, args, says in cases:
        done = twin_child("bisect", *args, cwd=cwd)
        assert done.returncode == 2, (args, done.stderr)
        assert done.stderr.count("\n") == 1 and says in done.stderr, done.stderr
        assert "Traceback" not in done.stderr and done.stdout == ""


def test_a_stopped_bisect_removes_its_worktree(tmp_path):
    repo = make_repo(tmp_path / "repo")
    before = state(repo)
    proc = subprocess.Popen(
        [*TWIN_CHILD, "bisect", "--good", "HEAD~15", "golden.mcap"],
        cwd=repo,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while git(repo, "worktree", "list").count("\n") < 1:  # a tried commit checked out
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 143 and "stopped by SIGTERM" in err, err
    assert state(repo) == before  # the worktree removed, the repository as it was


def test_a_worktree_whose_add_was_cut_short_is_removed_too(tmp_path):
    """A SIGTERM during `git worktree add` kills git mid-way: the worktree stays registered and
    locked ("initializing"), which `git worktree prune` skips. remove_worktree unlocks it."""
    from twin.verify.bisect import git, remove_worktree

    repo = make_repo(tmp_path / "repo")
    before = state(repo)
    tmp = tmp_path / "twin-bisect-x"
    tree = tmp / "tree"
    assert git(repo, "worktree", "add", "--detach", "--quiet", str(tree), "HEAD~1").returncode == 0
    git(repo, "worktree", "lock", "--reason", "initializing", str(tree))
    shutil.rmtree(tree)  # what a killed add leaves: the entry, locked, without its files
    assert "locked" in git(repo, "worktree", "list", "--porcelain").stdout
    remove_worktree(repo, tree, tmp)
    assert state(repo) == before and not tmp.exists()
