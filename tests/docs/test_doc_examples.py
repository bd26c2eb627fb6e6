"""Every shell and Python example in README.md and docs/ runs as written, page by page, and prints
what the page quotes (tests/support/docs_examples.py: how a page marks files, outputs, exits)."""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support.docs_examples import PageRun, blocks, check_output, is_example, run_workflow

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
CI_PAGE = ROOT / "docs" / "how-to" / "ci-goldens.md"  # its own test runs the workflow it shows
WITH_EXAMPLES = [p for p in PAGES if any(is_example(b) for b in blocks(p, ROOT)) and p != CI_PAGE]


def readme_first_run() -> list[str]:
    """The twin part of the README's first command (after `pip install -e . &&`)."""
    first = (
        (ROOT / "README.md").read_text(encoding="utf-8").split("```bash\n", 1)[1].splitlines()[0]
    )
    return shlex.split(first.split("&&")[-1].strip())


@pytest.fixture(scope="session")
def first_run(tmp_path_factory) -> Path:
    """A folder whose runs/ holds what the README's first command records (both files)."""
    folder = tmp_path_factory.mktemp("first-run")
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
    return folder / "runs"


@pytest.fixture
def docs_env(tmp_path) -> dict[str, str]:
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "TWIN_"))}
    bin_dir = Path(sys.executable).parent  # twin's own interpreter first, as after `pip install`
    return {
        **env,
        "HOME": str(home),
        "MPLBACKEND": "Agg",
        "PATH": f"{bin_dir}:{env.get('PATH', '')}",
    }


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


@pytest.mark.parametrize("page", WITH_EXAMPLES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_example_on_the_page_runs_as_written(page, tmp_path, first_run, docs_env):
    run = PageRun(_workdir(tmp_path, first_run), docs_env)
    try:
        for block in blocks(page, ROOT):
            run.run(block)
    finally:
        run.close()


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


def test_the_ci_job_passes_then_fails_on_a_changed_task_and_keeps_its_artifacts(
    tmp_path, first_run, docs_env
):
    work = _workdir(tmp_path, first_run)
    run = PageRun(work, docs_env)
    try:
        for block in blocks(CI_PAGE, ROOT):
            run.run(block)
    finally:
        run.close()
    workflow = (work / ".github" / "workflows" / "twin.yml").read_text()
    job = run_workflow(workflow, work, docs_env)
    assert not job.failed and "<testsuite" in (work / "twin-check.xml").read_text()
    task = work / "carry.py"
    task.write_text(
        task.read_text().replace("place_x_m: float = -0.3,", "place_x_m: float = -0.301,")
    )
    job = run_workflow(workflow, work, docs_env)
    check = job.step("Check the goldens")
    assert job.failed and check.code == 1, check.output
    uploads = [work / path for path in job.artifacts["twin-diff"].paths]
    assert job.artifacts["twin-diff"].runs and all(p.exists() for p in uploads), uploads
    assert "differ" in (work / "twin-check.txt").read_text()
    assert 'failures="1"' in (work / "twin-check.xml").read_text()
    report = (work / "twin-diff" / "carry.md").read_text()
    assert "carry" in report and (work / "twin-diff" / "carry.rrd").stat().st_size > 10_000


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
