"""The examples in README.md and docs/: found, run in order page by page, quoted output checked.

A fenced block in bash or python is run as written, in the page's working folder (a fresh folder
with a copy of recordings/, and runs/ holding the README's first run). An HTML comment on the line
before a fence changes that:

    <!-- doctest: exit=1 -->                   the block must exit 1 (default 0)
    <!-- doctest: file=my_task.py -->          write the block to this file (any language)
    <!-- doctest: output -->                   a text block: the lines the previous block printed
                                                (in order, among others; `...` matches anything)
    <!-- doctest: background ready="REGEX" --> start it, wait for REGEX in its output, go on; it is
                                                stopped (SIGTERM) at the end of the page, or at
                                                once with `stop`
    <!-- doctest: tty keys="q" -->             run it on a terminal and type these keys
    <!-- doctest: setup -->                    README's set-up: its twin run is the session's run
    <!-- doctest: skip reason="..." -->        not run (the reason says why; the test lists them)
"""

from __future__ import annotations

import os
import pty
import re
import select
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

RUNNABLE = {"bash": "bash", "sh": "bash", "shell": "bash", "python": "python"}
FENCE = re.compile(r"^```([\w+-]*)(?:\s+[^`]*)?$")  # a language, then attributes (title=...)
DIRECTIVE = re.compile(r"^<!--\s*doctest:(.*?)-->\s*$")
BLOCK_TIMEOUT_S = 300


@dataclass
class Block:
    page: str
    line: int  # 1-based line of the opening fence
    lang: str
    code: str
    options: dict[str, str] = field(default_factory=dict)

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def _options(text: str) -> dict[str, str]:
    out = {}
    for token in shlex.split(text):
        key, _, value = token.partition("=")
        out[key] = value
    return out


def blocks(path: Path, root: Path) -> list[Block]:
    """Every fenced block of a Markdown file with the directive above it, if any."""
    lines = path.read_text(encoding="utf-8").splitlines()
    found, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        start, lang = i, m.group(1)
        end = next(j for j in range(i + 1, len(lines)) if lines[j].rstrip() == "```")
        directive = DIRECTIVE.match(lines[start - 1]) if start > 0 else None
        options = _options(directive.group(1)) if directive else {}
        found.append(
            Block(
                str(path.relative_to(root)),
                start + 1,
                lang,
                "\n".join(lines[start + 1 : end]) + "\n",
                options,
            )
        )
        i = end + 1
    return found


def is_example(b: Block) -> bool:
    return b.lang in RUNNABLE or bool(b.options)


def check_output(expected: str, actual: str) -> str | None:
    """None when the expected lines appear in the actual output in order, else what is missing."""
    got = [line.strip() for line in actual.splitlines()]
    at = 0
    for want in expected.splitlines():
        want = want.strip()
        if not want or want == "...":
            continue
        pattern = re.compile(".*".join(re.escape(part) for part in want.split("...")))
        while at < len(got) and not pattern.fullmatch(got[at]):
            at += 1
        if at == len(got):
            return f"line not printed (in this order): {want!r}"
        at += 1
    return None


@dataclass
class Done:
    code: int
    output: str


def captured(argv: list[str], cwd: Path, env: dict[str, str]) -> Done:
    """Run to the end; its exit status and its output (stdout and stderr, interleaved)."""
    done = subprocess.run(
        argv,
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=BLOCK_TIMEOUT_S,
        check=False,
    )
    return Done(done.returncode, done.stdout)


class PageRun:
    """One page's examples, in order, in one working folder."""

    def __init__(self, workdir: Path, env: dict[str, str]) -> None:
        self.workdir, self.env = workdir, env
        self.background: list[subprocess.Popen] = []
        self.last: Done | None = None

    def _argv(self, b: Block) -> list[str]:
        if RUNNABLE[b.lang] == "python":
            return [sys.executable, "-c", b.code]
        return ["bash", "-e", "-c", b.code]  # as a shell a user types into: no pipefail

    def run(self, b: Block) -> None:
        o = b.options
        if "skip" in o or "setup" in o:
            return
        if "file" in o:
            target = self.workdir / o["file"]
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(b.code, encoding="utf-8")
            return
        if "output" in o:
            assert self.last is not None, f"{b.where}: an output block with no example before it"
            problem = check_output(b.code, self.last.output)
            assert problem is None, f"{b.where}: {problem}\n--- printed:\n{self.last.output}"
            return
        if b.lang not in RUNNABLE:
            return
        if "background" in o:
            self._start(b, o.get("ready", "."))
            if "stop" in o:  # seen to start is enough (a serving viewer keeps a core busy)
                self._stop(self.background.pop())
            return
        self.last = self._tty(b, o["keys"]) if "tty" in o else self._plain(b)
        want = int(o.get("exit", "0"))
        assert self.last.code == want, (
            f"{b.where}: exit {self.last.code}, expected {want}\n--- block:\n{b.code}"
            f"--- printed:\n{self.last.output}"
        )

    def _plain(self, b: Block) -> Done:
        return captured(self._argv(b), self.workdir, self.env)

    def _start(self, b: Block, ready: str) -> None:
        proc = subprocess.Popen(
            self._argv(b),
            cwd=self.workdir,
            env=self.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        self.background.append(proc)
        seen, deadline = [], time.monotonic() + 60
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                raise AssertionError(f"{b.where}: ended before it was ready:\n{''.join(seen)}")
            seen.append(line)
            if re.search(ready, line):
                self.last = Done(0, "".join(seen))
                return
        raise AssertionError(f"{b.where}: not ready within 60 s:\n{''.join(seen)}")

    def _tty(self, b: Block, keys: str) -> Done:
        master, slave = pty.openpty()
        proc = subprocess.Popen(
            self._argv(b),
            cwd=self.workdir,
            env={**self.env, "TERM": "xterm"},
            stdin=slave,
            stdout=slave,
            stderr=slave,
            start_new_session=True,
        )
        os.close(slave)
        out, typed, deadline = b"", False, time.monotonic() + BLOCK_TIMEOUT_S
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.2)
            if ready:
                try:
                    chunk = os.read(master, 65536)
                except OSError:  # the terminal closed: the program ended
                    break
                out += chunk
                if not typed and len(out) > 200:  # its screen is up: type
                    time.sleep(0.5)
                    os.write(master, keys.encode())
                    typed = True
            elif proc.poll() is not None:
                break
        os.close(master)
        code = proc.wait(timeout=30)
        text = re.sub(
            r"\x1b\[[0-9;?]*[A-Za-z]|\x1b[()][A-Z0-9]|\r", "", out.decode(errors="replace")
        )
        return Done(code, text)

    def close(self) -> None:
        for proc in self.background:
            self._stop(proc)

    @staticmethod
    def _stop(proc: subprocess.Popen) -> None:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        proc.stdout.close()


def page_file(page: Path, name: str) -> str:
    """The block a page writes to the file `name` (its `<!-- doctest: file=NAME -->` block)."""
    found = [b.code for b in blocks(page, page.parent) if b.options.get("file") == name]
    assert len(found) == 1, f"{page}: {len(found)} blocks write {name}"
    return found[0]


# How GitHub's Linux runners run a `run:` step's script, written to a file ({0}), by its `shell:`
# (workflow syntax, jobs.<job_id>.steps[*].shell). No `shell:` is not `shell: bash`: no pipefail.
SHELLS = {
    None: ("bash", "-e", "{0}"),
    "bash": ("bash", "--noprofile", "--norc", "-eo", "pipefail", "{0}"),
    "sh": ("sh", "-e", "{0}"),
}
CONDITIONS = ("success()", "failure()", "always()")
STEP_KEYS = {"name", "id", "if", "run", "shell", "uses", "with"}  # any other is refused
JOB_KEYS = {"name", "runs-on", "permissions", "defaults", "steps"}
PASSED_ACTIONS = ("actions/checkout@", "actions/setup-python@")  # the folder; this Python
TEST_REPORT_ACTIONS = {  # action -> the input that names the report files it reads
    "mikepenz/action-junit-report": "report_paths",
    "dorny/test-reporter": "path",
    "EnricoMi/publish-unit-test-result-action": "files",
}


@dataclass
class StepRun:
    name: str
    when: str  # success(), failure() or always()
    runs: bool  # its `if:` held: GitHub runs it
    code: int | None = None  # the exit status of a run step this harness ran
    output: str = ""  # its stdout and stderr
    summary: str = ""  # what it wrote to $GITHUB_STEP_SUMMARY (the job summary)


@dataclass
class Upload:
    """An actions/upload-artifact step: its paths (relative to the working folder) and whether
    its `if:` held."""

    paths: list[str]
    when: str
    runs: bool


@dataclass
class ReportStep:
    """A test-report action's step: the report files it reads and whether its `if:` held."""

    uses: str
    reads: list[str]
    when: str
    runs: bool


@dataclass
class JobRun:
    failed: bool = False
    steps: list[StepRun] = field(default_factory=list)
    artifacts: dict[str, Upload] = field(default_factory=dict)
    reports: list[ReportStep] = field(default_factory=list)

    def step(self, name: str) -> StepRun:
        return next(s for s in self.steps if s.name == name)


def _condition(step: dict, name: str) -> str:
    """A step's `if:`, bare or as `${{ ... }}`; one this harness cannot decide is refused."""
    text = str(step.get("if", "success()")).strip()
    if text.startswith("${{") and text.endswith("}}"):
        text = text[3:-2].strip()
    if text not in CONDITIONS:
        raise ValueError(f"step {name!r}: if: {text!r} is none of {CONDITIONS}")
    return text


def _shell_run(
    script: str, shell: str | None, workdir: Path, env: dict[str, str]
) -> tuple[Done, str]:
    """A step's script as GitHub runs it: written to a file, run by the shell's command line, with
    an empty $GITHUB_STEP_SUMMARY file of its own; its result and what it wrote there."""
    if shell not in SHELLS:
        raise ValueError(f"shell: {shell!r} is not one this harness runs ({list(SHELLS)[1:]})")
    with tempfile.TemporaryDirectory(prefix="step-") as tmp:  # GitHub's RUNNER_TEMP
        script_file = Path(tmp) / "step.sh"
        script_file.write_text(script, encoding="utf-8")
        summary = Path(tmp) / "step_summary.md"
        summary.touch()
        argv = [part.replace("{0}", str(script_file)) for part in SHELLS[shell]]
        step_env = {**env, "CI": "true", "GITHUB_ACTIONS": "true",
                    "GITHUB_STEP_SUMMARY": str(summary)}
        return captured(argv, workdir, step_env), summary.read_text(encoding="utf-8")


def _uses(step: dict, name: str, when: str, runs: bool, job: JobRun) -> None:
    """A `uses:` step is not run: an upload is collected, a test report recorded; the checkout
    and setup-python are what this folder and this Python already are; any other is refused."""
    uses, inputs = step["uses"], step.get("with") or {}
    action = uses.partition("@")[0]
    if action == "actions/upload-artifact":
        paths = [line.strip() for line in str(inputs["path"]).splitlines() if line.strip()]
        job.artifacts[inputs.get("name", "artifact")] = Upload(paths, when, runs)
    elif action in TEST_REPORT_ACTIONS:
        reads = str(inputs.get(TEST_REPORT_ACTIONS[action], "")).split()
        job.reports.append(ReportStep(uses, reads, when, runs))
    elif not uses.startswith(PASSED_ACTIONS):
        raise ValueError(f"step {name!r}: uses: {uses!r} is not an action this harness knows")
    job.steps.append(StepRun(name, when, runs))


def run_workflow(text: str, workdir: Path, env: dict[str, str]) -> JobRun:
    """A GitHub Actions workflow's one job, as GitHub's Linux runner takes it: its steps in order,
    each `run:` script under its `shell:` (no `shell:`: `bash -e`, no pipefail), each step only
    when its `if:` holds (success() by default, failure() once a step failed, always()). The
    install step (`run: pip install ...`) is passed over: twin is installed here. What it does
    not follow (env, working-directory, continue-on-error, matrices, ...) it refuses."""
    import yaml

    workflow = yaml.safe_load(text)
    (job_spec,) = workflow["jobs"].values()
    unknown = set(job_spec) - JOB_KEYS
    assert not unknown, f"job keys this harness does not follow: {sorted(unknown)}"
    defaults = job_spec.get("defaults") or workflow.get("defaults") or {}
    assert set(defaults) <= {"run"} and set(defaults.get("run") or {}) <= {"shell"}, defaults
    default_shell = (defaults.get("run") or {}).get("shell")
    job = JobRun()
    for i, step in enumerate(job_spec["steps"]):
        name = step.get("name") or step.get("uses") or f"step {i + 1}"
        unknown = set(step) - STEP_KEYS
        assert not unknown, f"step {name!r}: keys this harness does not follow: {sorted(unknown)}"
        when = _condition(step, name)
        runs = when == "always()" or (when == "failure()") == job.failed
        if "uses" in step:
            _uses(step, name, when, runs, job)
            continue
        if not runs or step["run"].startswith("pip install"):
            job.steps.append(StepRun(name, when, runs))
            continue
        done, summary = _shell_run(step["run"], step.get("shell", default_shell), workdir, env)
        job.steps.append(StepRun(name, when, True, done.code, done.output, summary))
        job.failed = job.failed or done.code != 0
    return job
