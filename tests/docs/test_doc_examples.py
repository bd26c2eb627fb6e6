"""Every shell and Python example in README.md and docs/ runs as written, page by page, and prints
what the page quotes (tests/support/docs_examples.py: how a page marks files, outputs, exits)."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support.docs_examples import (
    PageRun,
    blocks,
    check_output,
    is_example,
    page_file,
    run_workflow,
)
from support.shared import made_once

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
CI_PAGE = ROOT / "docs" / "how-to" / "ci-goldens.md"  # its own test runs the workflow it shows
TUTORIAL = ROOT / "docs" / "tutorial.md"
WORKFLOW = ".github/workflows/twin.yml"
WITH_EXAMPLES = [p for p in PAGES if any(is_example(b) for b in blocks(p, ROOT)) and p != CI_PAGE]


def readme_first_run() -> list[str]:
    """The twin part of the README's first command (after `pip install -e . &&`)."""
    first = (
        (ROOT / "README.md").read_text(encoding="utf-8").split("```bash\n", 1)[1].splitlines()[0]
    )
    return shlex.split(first.split("&&")[-1].strip())


@pytest.fixture(scope="session")
def first_run(tmp_path_factory) -> Path:
    """A folder whose runs/ holds what the README's first command records (both files), made once
    for the run's workers."""
    return made_once(tmp_path_factory, "first-run", _record_first_run) / "runs"


def _record_first_run(folder: Path) -> None:
    argv = readme_first_run()
    done = subprocess.run(
        [sys.executable, "-m", "twin.cli", *argv[1:]],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr


def _env(home: Path) -> dict[str, str]:
    """A user's environment, with home as HOME (made here)."""
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "TWIN_"))}
    bin_dir = Path(sys.executable).parent  # twin's own interpreter first, as after `pip install`
    return {
        **env,
        "HOME": str(home),
        "MPLBACKEND": "Agg",
        "PATH": f"{bin_dir}:{env.get('PATH', '')}",
    }


@pytest.fixture
def docs_env(tmp_path) -> dict[str, str]:
    return _env(tmp_path / "home")


def _workdir(tmp_path: Path, first_run: Path) -> Path:
    """A user's folder: the goldens (a copy: examples may rewrite them), tools/, the first run."""
    work = tmp_path / "work"
    shutil.copytree(ROOT / "recordings", work / "recordings")
    (work / "tools").symlink_to(ROOT / "tools")
    (work / "tests").mkdir()
    (work / "tests" / "fixtures").symlink_to(ROOT / "tests" / "fixtures")  # the reports' programs
    (work / "docs" / "img").mkdir(parents=True)
    shutil.copytree(first_run, work / "runs")
    return work


def _run_page(page: Path, work: Path, env: dict[str, str]) -> None:
    run = PageRun(work, env)
    try:
        for block in blocks(page, ROOT):
            run.run(block)
    finally:
        run.close()


@pytest.fixture(scope="module")
def ci_page_done(tmp_path_factory, first_run) -> Path:
    """A user's folder after every example of the CI page ran in it, once for the CI tests below:
    each works on a copy."""
    folder = tmp_path_factory.mktemp("ci-page")
    work = _workdir(folder, first_run)
    _run_page(CI_PAGE, work, _env(folder / "home"))
    return work


def _ci_page_work(ci_page_done: Path, tmp_path: Path) -> Path:
    work = tmp_path / "work"
    shutil.copytree(ci_page_done, work, symlinks=True)  # tools/ and tests/fixtures stay links
    return work


@pytest.mark.parametrize("page", WITH_EXAMPLES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_example_on_the_page_runs_as_written(page, tmp_path, first_run, docs_env):
    _run_page(page, _workdir(tmp_path, first_run), docs_env)


def test_the_readme_and_the_pages_have_examples_and_skip_almost_none():
    every = [b for p in PAGES for b in blocks(p, ROOT) if b.lang in ("bash", "python")]
    skipped = [b.where for b in every if "skip" in b.options]
    assert len(every) > 40 and len(skipped) <= 3, skipped  # each names its reason
    for b in every:
        if "skip" in b.options:
            assert b.options["skip"] == "" and b.options.get("reason"), (
                f"{b.where}: a skip says why"
            )


def test_the_readmes_set_up_is_ci_s_test_command():
    setup = next(b for b in blocks(ROOT / "README.md", ROOT) if "setup" in b.options)
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").strip().splitlines()[-1]
    assert setup.code.splitlines()[1] == ci


def _held(job, artifact: str, work: Path) -> set[str]:
    """The files an artifact of the job holds (its paths, folders walked), relative to work."""
    held = set()
    for path in job.artifacts[artifact].paths:
        found = work / path
        files = [f for f in found.rglob("*") if f.is_file()] if found.is_dir() else [found]
        held |= {f.relative_to(work).as_posix() for f in files if f.is_file()}
    return held


def _twin(work: Path, env: dict[str, str], *argv: str) -> int:
    done = subprocess.run(
        ["twin", *argv], cwd=work, env=env, capture_output=True, timeout=300, check=False
    )
    return done.returncode


def _careless_edit(work: Path) -> None:
    """The tutorial's careless edit of carry.py: the place point 2 mm further along x."""
    task = work / "carry.py"
    edited = task.read_text().replace("place_x_m: float = -0.3,", "place_x_m: float = -0.302,")
    assert edited != task.read_text()
    task.write_text(edited)


def test_the_ci_job_passes_then_fails_on_a_changed_task_and_keeps_its_artifacts(
    tmp_path, ci_page_done, docs_env
):
    work = _ci_page_work(ci_page_done, tmp_path)
    workflow = page_file(CI_PAGE, WORKFLOW)
    assert (work / WORKFLOW).read_text() == workflow
    job = run_workflow(workflow, work, docs_env)
    check = job.step("Check the goldens")
    assert not job.failed and check.code == 0, check.output
    assert 'failures="0"' in (work / "twin-check.xml").read_text()
    assert check.summary.startswith("## twin check: every golden matched (1 of 1)\n"), check.summary
    when = {name: upload.when for name, upload in job.artifacts.items()}
    assert when == {"twin-check": "always()", "twin-diff": "failure()"}, when
    assert job.artifacts["twin-check"].runs and not job.artifacts["twin-diff"].runs
    (report,) = job.reports  # the JUnit report, published whatever the verdict
    assert report.when == "always()" and report.reads == ["twin-check.xml"], report
    _careless_edit(work)
    job = run_workflow(workflow, work, docs_env)
    check = job.step("Check the goldens")
    assert job.failed and check.code == 1, check.output
    assert job.artifacts["twin-diff"].runs and job.reports[0].runs
    assert 'failures="1"' in (work / "twin-check.xml").read_text()
    assert "differ" in (work / "twin-check.txt").read_text()
    assert _held(job, "twin-check", work) == {"twin-check.xml", "twin-check.html"}
    page = (work / "twin-check.html").read_text()
    assert "twin check: 1 differ" in page and '<div class="chart' in page
    # the job summary: GitHub's file for the step, appended to without being asked
    assert "| `goldens/carry.mcap` | differ | **FAIL** |" in check.summary, check.summary
    kept = {"twin-diff/carry.mcap", "twin-diff/carry.md", "twin-diff/carry.rrd"}
    assert _held(job, "twin-diff", work) >= {"twin-check.txt", *kept}
    assert _twin(work, docs_env, "info", "twin-diff/carry.mcap") == 0
    assert _twin(work, docs_env, "diff", "goldens/carry.mcap", "twin-diff/carry.mcap") == 1
    assert "carry" in (work / "twin-diff" / "carry.md").read_text()
    rrd = work / "twin-diff" / "carry.rrd"
    assert rrd.read_bytes()[:3] == b"RRF" and rrd.stat().st_size > 10_000


def test_without_shell_bash_the_ci_job_stays_green_on_a_changed_task(
    tmp_path, ci_page_done, docs_env
):
    """The page's job with its `shell: bash` lines removed, as GitHub would run it: `twin check`
    finds the changed golden and exits 1, `tee` exits 0, the job passes. The line matters."""
    work = _ci_page_work(ci_page_done, tmp_path)
    workflow, removed = re.subn(r"(?m)^ *shell: bash\n", "", page_file(CI_PAGE, WORKFLOW))
    assert removed >= 1
    _careless_edit(work)
    job = run_workflow(workflow, work, docs_env)
    check = job.step("Check the goldens")
    assert not job.failed and check.code == 0, check.output
    assert "differ" in (work / "twin-check.txt").read_text(), check.output
    assert not job.artifacts["twin-diff"].runs


def test_the_ci_page_builds_on_the_tutorial_s_task_and_its_golden():
    assert page_file(CI_PAGE, "carry.py") == page_file(TUTORIAL, "carry.py")

    def record_lines(page: Path) -> list[str]:
        code = "".join(b.code for b in blocks(page, ROOT) if b.lang == "bash")
        return [
            line
            for line in code.splitlines()
            if line.startswith("twin run carry.py") and "--record" in line
        ]

    assert record_lines(CI_PAGE) == record_lines(TUTORIAL) != [], record_lines(TUTORIAL)


HIDDEN = """\
jobs:
  job:
    runs-on: ubuntu-latest
    steps:
      - name: twin-like
        run: false | tee x.txt
      - name: on failure
        if: ${{ failure() }}
        run: touch failure.txt
      - name: always
        if: always()
        run: touch always.txt
"""


def test_the_workflow_harness_runs_steps_under_github_s_shell_rules(tmp_path, docs_env):
    job = run_workflow(HIDDEN, tmp_path, docs_env)  # no shell: `bash -e`, tee's status wins
    assert not job.failed and job.step("twin-like").code == 0
    assert not job.step("on failure").runs and not (tmp_path / "failure.txt").exists()
    assert (tmp_path / "always.txt").exists()
    strict = HIDDEN.replace("run: false |", "shell: bash\n        run: false |")
    job = run_workflow(strict, tmp_path, docs_env)
    assert job.failed and job.step("twin-like").code == 1
    assert job.step("on failure").runs and (tmp_path / "failure.txt").exists()
    pwsh = HIDDEN.replace("run: false |", "shell: pwsh\n        run: false |")
    with pytest.raises(ValueError, match="pwsh"):
        run_workflow(pwsh, tmp_path, docs_env)
    with pytest.raises(ValueError, match="cancelled"):
        run_workflow(HIDDEN.replace("always()", "cancelled()"), tmp_path, docs_env)


def test_a_quoted_output_the_example_does_not_print_fails_the_page(tmp_path, docs_env):
    page = tmp_path / "page.md"
    quoted = "<!-- doctest: output -->\n```text\nok 4 of 4\n```\n"
    page.write_text('```bash\necho "ok 3 of 4"\n```\n\n' + quoted)
    run = PageRun(tmp_path, docs_env)
    with pytest.raises(AssertionError, match="line not printed"):
        for block in blocks(page, tmp_path):
            run.run(block)
    assert check_output("a ... c\nlast", "x\na b c\nlast\n") is None
    assert check_output("last\na ... c", "a b c\nlast\n") is not None  # order counts
