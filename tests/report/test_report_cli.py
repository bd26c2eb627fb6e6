"""`twin check --html/--summary`, `twin diff --html`: a golden whose pick point moved 2 mm gives a
self-contained page (no resource from any host, charts, the onset step) and a Markdown job summary
naming it; a green check's page says every golden matched; $GITHUB_STEP_SUMMARY is appended to;
a bad path is one line and exit 2, before any work."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support.carry import CARRY as TUTORIAL_CARRY
from support.cli import twin

# the tutorial's task, holding 0.2 s and without its placement event
CARRY = TUTORIAL_CARRY.replace("hold_s: float = 0.5", "hold_s: float = 0.2").split("    x, y = ")[0]
MOVED = CARRY.replace("twin.move_to(0.2, 0.7)", "twin.move_to(0.202, 0.7)")  # the pick, 2 mm on
# a resource the page would fetch: src=, href=, CSS url() or @import naming a host
REMOTE = re.compile(r"""(src|href)\s*=\s*["']?\s*(https?:)?//|url\(\s*["']?(https?:)?//|@import""",
                    re.IGNORECASE)


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """carry.py and goldens/carry.mcap recorded from it."""
    work = tmp_path_factory.mktemp("report")
    (work / "carry.py").write_text(CARRY)
    (work / "goldens").mkdir()
    done = subprocess.run(
        [sys.executable, "-m", "twin.cli", "run", "carry.py", "--record", "goldens/carry.mcap"],
        cwd=work, capture_output=True, text=True, check=False,
    )
    assert done.returncode == 0, done.stderr
    return work


@pytest.fixture(scope="module")
def moved(work, tmp_path_factory) -> Path:
    """A copy of the work folder whose task picks 2 mm further in x, checked with --html and
    --summary: the folder, holding r.html, s.md and out.txt (what the check printed)."""
    folder = tmp_path_factory.mktemp("moved") / "w"
    shutil.copytree(work, folder)
    (folder / "carry.py").write_text(MOVED)
    done = subprocess.run(
        [sys.executable, "-m", "twin.cli", "check", "goldens", "--html", "r.html", "--summary",
         "s.md"],
        cwd=folder, capture_output=True, text=True, check=False,
        env={k: v for k, v in os.environ.items() if k != "GITHUB_STEP_SUMMARY"},
    )
    assert done.returncode == 1, done.stdout + done.stderr
    (folder / "out.txt").write_text(done.stdout)
    return folder


def _onset(summary: str) -> int:
    return int(re.search(r"\| step (\d+) \(t = ", summary).group(1))


def test_a_2mm_move_gives_a_self_contained_page_and_a_summary(moved):
    page = (moved / "r.html").read_text()
    summary = (moved / "s.md").read_text()
    assert "report: r.html, s.md" in (moved / "out.txt").read_text()
    assert not REMOTE.search(page), REMOTE.search(page)
    assert "http" not in page  # not even a comment names a host
    assert page.count('<div class="chart') >= 3
    onset = _onset(summary)
    assert f"step {onset} (t = " in page  # the onset in the page's text, not only drawn
    assert '"label":"onset step ' in page
    assert "goldens/carry.mcap" in page and "differ" in page
    # the summary: a Markdown table naming the golden, what changed, well under GitHub's 1 MiB
    assert summary.startswith("## twin check: 1 differ\n")
    assert "| golden | status | verdict | onset | what changed |" in summary
    assert "| `goldens/carry.mcap` | differ | **FAIL** |" in summary
    assert "joint_target MTB_axis1 q 0.765450 -> 0.763858 rad" in summary  # what changed
    assert len(summary.encode()) < 1024 * 1024 and "<img" not in summary


@pytest.mark.skipif(shutil.which("chromium") is None,
                    reason="needs Debian's chromium (tools/setup_test_system.sh)")
def test_chromium_draws_the_page_offline(moved, tmp_path):
    """Headless Chromium opens the page from the file system with every other request refused: no
    console error, no request but the file, every chart drawn (a canvas with more than a few
    colours), the onset step shown; the screenshot is kept beside the page."""
    from PIL import Image
    from playwright.sync_api import sync_playwright

    errors, asked = [], []
    shot = moved / "r.png"
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=shutil.which("chromium"),
                                    args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 900})
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))

            def only_files(route):
                asked.append(route.request.url)
                if route.request.url.startswith("file:"):
                    route.continue_()
                else:
                    route.abort()

            page.route("**/*", only_files)
            page.goto((moved / "r.html").as_uri())
            page.wait_for_function("document.querySelectorAll('div.chart').length > 0 && "
                                   "document.querySelectorAll('div.chart:not([data-drawn])')"
                                   ".length === 0", timeout=30_000)
            charts = page.locator("div.chart").count()
            canvases = page.locator("div.chart canvas").count()
            onset = _onset((moved / "s.md").read_text())
            shown = page.get_by_text("diverges at step", exact=False).first.is_visible()
            first = page.get_by_text(f"step {onset} (t = ", exact=False).first.is_visible()
            page.screenshot(path=shot, full_page=True)
            chart_shot = tmp_path / "chart.png"
            page.locator("div.chart").first.screenshot(path=chart_shot)
        finally:
            browser.close()
    assert errors == [] and asked == [(moved / "r.html").as_uri()], (errors, asked)
    assert charts >= 3 and canvases == charts
    assert shown and first
    colours = Image.open(chart_shot).convert("RGB").getcolors(maxcolors=1 << 20)
    assert len(colours) > 20, "the first chart is blank"
    full = Image.open(shot).convert("L")
    assert full.getextrema()[0] < 100 and full.height > 1500  # drawn ink, the whole report


def test_a_green_check_says_every_golden_matched(work, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("GITHUB_STEP_SUMMARY", raising=False)
    monkeypatch.chdir(work)
    code, out, _ = twin(capsys, "check", "goldens", "--html", tmp_path / "g.html")
    assert code == 0, out
    page = (tmp_path / "g.html").read_text()
    assert "every golden matched (1 of 1)" in page
    assert "<div class=\"chart" not in page and "uPlot" not in page  # short: no charts to draw
    assert len(page) < 10_000


def test_the_step_summary_is_appended_to_without_being_asked(work, tmp_path, capsys,
                                                             monkeypatch):
    step = tmp_path / "step_summary.md"
    step.write_text("an earlier step's summary\n")
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(step))
    monkeypatch.chdir(work)
    code, out, _ = twin(capsys, "check", "goldens")
    assert code == 0
    text = step.read_text()
    assert text.startswith("an earlier step's summary\n## twin check: every golden matched")
    assert "| `goldens/carry.mcap` | match | pass |" in text
    assert "$GITHUB_STEP_SUMMARY" in out


@pytest.mark.parametrize(
    ("option", "path", "expected"),
    [
        ("--html", "r.htm", "--html 'r.htm' should end in .html"),
        ("--summary", "s.txt", "--summary 's.txt' should end in .md"),
        ("--html", "missing/r.html", "folder 'missing' does not exist"),
        ("--summary", "goldens/carry.mcap", "should end in .md"),
    ],
)
def test_a_bad_report_path_is_one_line_before_any_work(work, capsys, monkeypatch, option, path,
                                                       expected):
    monkeypatch.chdir(work)
    code, out, err = twin(capsys, "check", "goldens", option, path)
    assert code == 2
    assert expected in err and len(err.strip().splitlines()) == 1, err
    assert "checking" not in out  # refused before any golden was run


def test_replay_html_of_a_golden_that_replays_the_same(work, tmp_path, capsys):
    code, _, err = twin(capsys, "replay", work / "goldens/carry.mcap", "--html",
                        tmp_path / "p.html")
    assert code == 0, err
    page = (tmp_path / "p.html").read_text()
    assert "<title>twin replay</title>" in page and "every golden matched (1 of 1)" in page


def test_diff_html_draws_two_files(work, moved, tmp_path, capsys):
    candidate = tmp_path / "moved.mcap"
    done = subprocess.run(
        [sys.executable, "-m", "twin.cli", "run", "carry.py", "--record", str(candidate)],
        cwd=moved, capture_output=True, text=True, check=False,
    )
    assert done.returncode == 0, done.stderr
    code, _out, err = twin(capsys, "diff", work / "goldens/carry.mcap", candidate, "--html",
                          tmp_path / "d.html")
    assert code == 1, err
    page = (tmp_path / "d.html").read_text()
    assert "<title>twin diff</title>" in page and page.count('<div class="chart') >= 3
    assert f"twin diff {work / 'goldens/carry.mcap'} {candidate} --rrd diff.rrd" in page
