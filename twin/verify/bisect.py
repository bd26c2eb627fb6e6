"""`twin bisect`: the first commit between a good one and a bad one at which the goldens, as they
are now, stop matching.

Each tried commit is checked out into a temporary worktree (`git worktree add --detach`, removed
afterwards); the goldens of the work tree are copied into it at their place in the repository, so a
golden's task file (named relative to the golden's folder) is the tried commit's. `twin check` runs
there in a child process: with the worktree first on PYTHONPATH when the repository is twin's own
(the tried commit's package runs), else the installed twin. The search is a binary search over
`git rev-list --first-parent --ancestry-path good..bad`, with skips (a commit whose code or task
does not load) and a verdict cache (bisect_cache). The user's work tree, index, branch and stash
are never touched.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from twin.model.errors import ConfigError
from twin.verify.bisect_cache import VerdictCache, golden_sha256
from twin.verify.check import find_goldens


@dataclass
class Tried:
    """One tried commit: good, bad or skip, and each golden's status and one-line summary."""

    commit: str
    subject: str
    verdict: str
    goldens: list[dict] = field(default_factory=list)  # {golden, status, summary}
    cached: bool = False  # every golden's verdict came from the cache
    reason: str = ""  # why skipped

    def as_dict(self) -> dict:
        return {
            "commit": self.commit,
            "subject": self.subject,
            "verdict": self.verdict,
            "cached": self.cached,
            "reason": self.reason,
            "goldens": self.goldens,
        }


@dataclass
class Bisection:
    """What a bisect found: outcome "found" (first_bad), "same" (good and bad do not differ) or
    "undecided" (skipped commits hide it: candidates)."""

    good: str
    bad: str
    path: list[str]  # the commits after good, up to bad, oldest first
    goldens: list[str]
    tried: list[Tried] = field(default_factory=list)
    outcome: str = "undecided"
    first_bad: Tried | None = None
    candidates: list[str] = field(default_factory=list)
    message: str = ""

    @property
    def exit_code(self) -> int:
        return {"found": 0, "same": 1}.get(self.outcome, 3)

    @property
    def flipped(self) -> list[dict]:
        """The goldens that differ at the first bad commit."""
        if self.first_bad is None:
            return []
        return [g for g in self.first_bad.goldens if g["status"] == "differ"]

    def as_dict(self) -> dict:
        return {
            "good": self.good,
            "bad": self.bad,
            "outcome": self.outcome,
            "message": self.message,
            "commits_in_range": len(self.path),
            "goldens": self.goldens,
            "first_bad": self.first_bad.as_dict() if self.first_bad else None,
            "flipped": self.flipped,
            "candidates": self.candidates,
            "tried": [t.as_dict() for t in self.tried],
            "from_cache": sum(t.cached for t in self.tried),
        }


def git(repo: str | os.PathLike, *args: str) -> subprocess.CompletedProcess:
    """git ARGS in repo (hooks off: checking out a worktree must not run the user's hooks)."""
    return subprocess.run(
        ["git", "-c", "core.hooksPath=/dev/null", *args],
        cwd=repo,
        capture_output=True,
        text=True,
        check=False,
    )


def remove_worktree(root: Path, tree: Path, tmp: Path) -> None:
    """Remove a tried commit's worktree and its temporary folder, also one whose `git worktree add`
    a signal cut short: git leaves that one registered and locked ("initializing"), which
    `worktree prune` skips, so it is unlocked first."""
    git(root, "worktree", "remove", "--force", "--force", str(tree))
    shutil.rmtree(tmp, ignore_errors=True)
    git(root, "worktree", "unlock", str(tree))
    git(root, "worktree", "prune")


def repo_root(cwd: str | os.PathLike = ".") -> Path:
    done = git(cwd, "rev-parse", "--show-toplevel")
    if done.returncode != 0 or not done.stdout.strip():
        raise ConfigError(f"{os.path.abspath(cwd)!r} is not in a git repository")
    return Path(done.stdout.strip())


def commit_of(root: Path, rev: str, option: str) -> str:
    done = git(root, "rev-parse", "--verify", "--quiet", "--end-of-options", f"{rev}^{{commit}}")
    if done.returncode != 0:
        raise ConfigError(f"{option} {rev!r} is no commit of this repository")
    return done.stdout.strip()


def commit_range(root: Path, good: str, bad: str) -> list[str]:
    """The commits after good up to bad along bad's first parents, oldest first (bad last)."""
    if good == bad:
        raise ConfigError(f"--good and --bad are the same commit {good[:12]}")
    if git(root, "merge-base", "--is-ancestor", good, bad).returncode != 0:
        raise ConfigError(f"--good {good[:12]} is not an ancestor of --bad {bad[:12]}")
    done = git(root, "rev-list", "--reverse", "--first-parent", "--ancestry-path", f"{good}..{bad}")
    path = done.stdout.split()
    if done.returncode != 0 or not path or path[-1] != bad:
        raise ConfigError(f"no first-parent path from {good[:12]} to {bad[:12]}")
    return path


def subject(root: Path, commit: str) -> str:
    return git(root, "log", "-1", "--format=%s", commit).stdout.strip()


def is_twin_repo(root: Path) -> bool:
    """twin's own repository: twin/__init__.py and a pyproject that names the project twin."""
    try:
        project = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return (root / "twin" / "__init__.py").is_file() and project.get("project", {}).get(
        "name"
    ) == "twin"


@dataclass
class Golden:
    """A golden to check: its path in the repository, its files, their content's sha256."""

    rel: str
    files: list[Path]
    sha256: str


def goldens_in(root: Path, paths: list[str]) -> list[Golden]:
    """The goldens `twin check PATHS` takes here (recordings, then sweeps, then searches: the order
    of its JUnit cases), each by its path relative to the repository's root."""
    found = find_goldens(paths)
    real_root, out = os.path.realpath(root), []
    for path in [*found.recordings, *found.sweeps, *found.searches]:
        rel = os.path.relpath(os.path.realpath(path), real_root)
        if rel.startswith(".."):
            raise ConfigError(f"golden {path!r} lies outside the repository {str(root)!r}")
        p = Path(path)
        # a sweep or search golden NAME.toml with its companions (NAME.summary.json,
        # NAME.expect.json, NAME.mcap, ...); an .mcap golden is one file
        files = sorted(f for f in p.parent.glob(f"{p.stem}.*") if f.is_file())
        files = files if p.suffix == ".toml" else [p]
        out.append(Golden(Path(rel).as_posix(), files, golden_sha256(files)))
    return out


def check_options(tolerance: str, tol: list[str], event_window: int | None) -> list[str]:
    """The verdict options as `twin check` arguments."""
    argv = ["--tolerance", tolerance]
    for t in tol:
        argv += ["--tol", t]
    if event_window is not None:
        argv += ["--event-window", str(event_window)]
    return argv


class Bisector:
    """Tries commits of one repository against its goldens (cached), and searches."""

    def __init__(
        self,
        root: Path,
        goldens: list[Golden],
        options: list[str],
        progress: Callable[[Tried], None] | None = None,
    ) -> None:
        self.root, self.goldens, self.options = root, goldens, options
        self.own = is_twin_repo(root)
        self.cache = VerdictCache(root)
        self.progress = progress
        # the installed twin judges a user's repository: its version is part of the verdict
        self.key_options = {"check": options, "twin": None if self.own else _installed_version()}
        self.tried: dict[str, Tried] = {}

    def verdict(self, commit: str) -> str:
        """good, bad or skip for one commit (tried once per bisect, from the cache when it can)."""
        if commit not in self.tried:
            self.tried[commit] = self._try(commit)
            if self.progress:
                self.progress(self.tried[commit])
        return self.tried[commit].verdict

    def _try(self, commit: str) -> Tried:
        keys = {
            g.rel: VerdictCache.key(commit, g.rel, g.sha256, self.key_options) for g in self.goldens
        }
        known = {rel: self.cache.get(key) for rel, key in keys.items()}
        todo = [g for g in self.goldens if known[g.rel] is None]
        tried = Tried(commit, subject(self.root, commit), "skip", cached=not todo)
        if todo:
            ran, reason = self._check(commit, todo)
            if ran is None:  # the check did not run: nothing cached, the commit skipped
                tried.reason = reason
                return tried
            for g in todo:
                self.cache.put(keys[g.rel], ran[g.rel])
                known[g.rel] = ran[g.rel]
        tried.goldens = [{"golden": g.rel, **known[g.rel]} for g in self.goldens]
        statuses = [v["status"] for v in tried.goldens]
        if "differ" in statuses:
            tried.verdict = "bad"
        elif all(s == "match" for s in statuses):
            tried.verdict = "good"
        else:
            errors = [v for v in tried.goldens if v["status"] != "match"]
            tried.reason = f"{errors[0]['golden']}: {errors[0]['summary']}"
        return tried

    def _check(self, commit: str, goldens: list[Golden]) -> tuple[dict | None, str]:
        """`twin check` of goldens against commit, in a worktree of its own: ({rel: {status,
        summary}}, "") or (None, why it did not run)."""
        tmp = Path(tempfile.mkdtemp(prefix="twin-bisect-"))
        tree = tmp / "tree"
        try:
            added = git(self.root, "worktree", "add", "--detach", "--quiet", str(tree), commit)
            if added.returncode != 0:
                return None, "git worktree add failed: " + _last_line(added.stderr)
            for g in goldens:  # the goldens as they are now, where the repository has them
                folder = tree / Path(g.rel).parent
                folder.mkdir(parents=True, exist_ok=True)
                for f in g.files:
                    shutil.copyfile(f, folder / f.name)
            return self._run_check(tree, tmp / "check.xml", goldens)
        finally:
            remove_worktree(self.root, tree, tmp)

    def _run_check(self, tree: Path, junit: Path, goldens: list[Golden]) -> tuple[dict | None, str]:
        env = dict(os.environ)
        if self.own:  # the tried commit's package runs, not the installed one
            env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tree), env.get("PYTHONPATH")]))
        argv = [sys.executable, "-m", "twin.cli", "check", *(g.rel for g in goldens)]
        done = subprocess.run(
            [*argv, "--junit", str(junit), *self.options],
            cwd=tree,  # -m puts it first on sys.path; outside any other twin checkout
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        cases = _junit_cases(junit)
        names = [Path(g.rel).name for g in goldens]  # JUnit names a case by the file's name
        if cases is None or [case.pop("name") for case in cases] != names:
            why = _last_line(done.stderr) or _last_line(done.stdout)
            return None, f"twin check did not run (exit {done.returncode}): {why}"
        return {g.rel: case for g, case in zip(goldens, cases, strict=True)}, ""

    def search(self, good: str, bad: str, path: list[str]) -> Bisection:
        """Binary search over path (the commits after good, bad last) for the first bad one."""
        out = Bisection(good, bad, path, [g.rel for g in self.goldens])
        try:
            self._search(out)
        finally:
            out.tried = list(self.tried.values())
        return out

    def _search(self, out: Bisection) -> None:
        ends = {"good": out.good, "bad": out.bad}
        for name, commit in ends.items():
            verdict = self.verdict(commit)
            if verdict == "skip":
                out.message = f"the {name} commit {commit[:12]} cannot be checked"
                return
            if verdict != name:
                out.outcome = "same"
                out.message = (
                    f"the goldens match at bad {out.bad[:12]} as at good"
                    if name == "bad"
                    else f"the goldens differ at good {out.good[:12]} already"
                )
                return
        path, lo, hi, skipped = out.path, -1, len(out.path) - 1, set()
        while inside := [i for i in range(lo + 1, hi) if i not in skipped]:
            mid = (lo + hi) // 2
            i = min(inside, key=lambda j: (abs(j - mid), j))
            verdict = self.verdict(path[i])
            if verdict == "good":
                lo = i
            elif verdict == "bad":
                hi = i
            else:
                skipped.add(i)
        out.candidates = [path[i] for i in range(lo + 1, hi) if i in skipped] + [path[hi]]
        if len(out.candidates) == 1:
            out.outcome, out.first_bad = "found", self.tried[path[hi]]
        else:
            out.message = "skipped commits hide the first bad commit; it is one of these"


def bisect(
    good: str,
    bad: str,
    paths: list[str],
    options: list[str],
    progress: Callable[[Tried], None] | None = None,
    cwd: str | os.PathLike = ".",
    announce: Callable[[str], None] | None = None,
) -> Bisection:
    """Find the first commit after good, up to bad, at which the goldens named by paths (as they
    are in the work tree now; `twin check`'s default recordings/ when none) stop matching."""
    root = repo_root(cwd)
    good_c, bad_c = commit_of(root, good, "--good"), commit_of(root, bad, "--bad")
    path = commit_range(root, good_c, bad_c)
    goldens = goldens_in(root, paths)
    if announce:
        noun = "golden" if len(goldens) == 1 else "goldens"
        announce(
            f"bisecting {len(path)} commits after {good_c[:12]} up to {bad_c[:12]}, "
            f"{len(goldens)} {noun}"
        )
    return Bisector(root, goldens, options, progress).search(good_c, bad_c, path)


def _junit_cases(junit: Path) -> list[dict] | None:
    """Each test case of `twin check --junit` as {status, summary}; None when it was not written."""
    try:
        suite = ET.parse(junit).getroot()
    except (OSError, ET.ParseError):
        return None
    cases = []
    for case in suite.iter("testcase"):
        failure, error = case.find("failure"), case.find("error")
        if failure is not None:
            status, summary = "differ", failure.get("message", "")
        elif error is not None:
            status, summary = "error", error.get("message", "")
        else:
            status, summary = "match", "match"
        cases.append({"name": case.get("name"), "status": status, "summary": summary})
    return cases


def _last_line(text: str) -> str:
    lines = [line.strip() for line in (text or "").splitlines() if line.strip()]
    return lines[-1] if lines else ""


def _installed_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("twin")
    except PackageNotFoundError:
        return "unknown"
