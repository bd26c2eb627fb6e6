"""Report files are users' files too: every report, picture and summary a command writes refuses an
existing path before any work (exit 2, one line naming the option and the file, the file left as it
was, nothing else written) and replaces it whole with --force. Real `twin` processes on a one-cycle
run and the shipped sweep golden."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest
from support.cli import TWIN

import twin

ROOT = Path(__file__).resolve().parents[2]
SWEEP = ROOT / "recordings" / "sweeps" / "pick_place_jitter.toml"  # a golden with its results
OLD = b"the user's own bytes\n"


def _twin(*args, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*TWIN, *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=300, check=False
    )


@pytest.fixture
def src(pick_place_cli, tmp_path) -> Path:
    """A copy of the session's one-cycle `twin run pick_place` recording, in this test's folder."""
    path = tmp_path / "src.mcap"
    shutil.copy(pick_place_cli["mcap"], path)
    return path


# (command, the option refused, the existing file it names, other outputs given that stay unwritten)
REFUSED = [
    ("diff {src} {src}", "--report", "r.md", ["--rrd", "new.rrd", "--html", "new.html"]),
    ("diff {src} {src}", "--rrd", "r.rrd", ["--report", "new.md", "--html", "new.html"]),
    ("diff {src} {src}", "--html", "r.html", ["--report", "new.json", "--rrd", "new.rrd"]),
    ("replay {src}", "--html", "r.html", ["--report", "new.md", "--record", "new.mcap"]),
    ("check {src}", "--html", "r.html", ["--summary", "new.md", "--junit", "new.xml"]),
    ("check {src}", "--summary", "r.md", ["--html", "new.html", "--junit", "new.xml"]),
    ("check {src}", "--junit", "r.xml", ["--html", "new.html", "--summary", "new.md"]),
    ("sweep compare {sweep} {sweep}", "--report", "r.json", ["--html", "new.html"]),
    ("sweep compare {sweep} {sweep}", "--plot", "r.png", ["--report", "new.md"]),
    ("sweep compare {sweep} {sweep}", "--html", "r.html", ["--plot", "new.png"]),
    ("sweep plot {sweep}", "--out", "r.png", []),
    ("bisect --good HEAD", "--json", "r.json", []),  # refused before it looks for a repository
    ("recover {src}", "-o", "r.mcap", []),
    ("view {src}", "--screenshot", "r.png", []),
]


@pytest.mark.parametrize(
    ("command", "option", "name", "others"),
    REFUSED,
    ids=[
        f"{c.split()[0]}{' ' + c.split()[1] if c.startswith('sweep') else ''} {o}"
        for c, o, _, _ in REFUSED
    ],
)
def test_an_existing_report_is_refused_before_any_work(
    src, tmp_path, command, option, name, others
):
    taken = tmp_path / name
    taken.write_bytes(OLD)
    before = sorted(p.name for p in tmp_path.iterdir())
    argv = command.format(src=src, sweep=SWEEP).split()
    done = _twin(*argv, option, taken, *others, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stdout == ""  # nothing ran
    shown = "output" if option == "-o" else option  # recover's -o, in export -o's words
    assert done.stderr == (
        f"twin: error: {shown} {str(taken)!r} exists already; expected a new path, "
        "or --force to replace it\n"
    )
    assert taken.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing else written


def _replaced(tmp_path: Path, *names: str) -> dict[str, bytes]:
    """Each file's new bytes, after checking that none is the old file and no temporary is left."""
    new = {name: (tmp_path / name).read_bytes() for name in names}
    assert all(data != OLD and data for data in new.values()), new
    assert not list(tmp_path.glob(".*.tmp")) and not list(tmp_path.glob("*.partial"))
    return new


def _existing(tmp_path: Path, *names: str) -> list[Path]:
    for name in names:
        (tmp_path / name).write_bytes(OLD)
    return [tmp_path / name for name in names]


def test_diff_and_replay_force_replace_their_reports(src, tmp_path):
    md, js, xml, rrd, html = _existing(tmp_path, "r.md", "r.json", "r.xml", "r.rrd", "r.html")
    done = _twin(
        "diff",
        src,
        src,
        "--report",
        md,
        "--report",
        js,
        "--report",
        xml,
        "--rrd",
        rrd,
        "--html",
        html,
        "--force",
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    new = _replaced(tmp_path, "r.md", "r.json", "r.xml", "r.rrd", "r.html")
    assert new["r.md"].startswith(b"# twin diff: MATCH")
    assert json.loads(new["r.json"])["match"] is True
    assert b"<testsuite" in new["r.xml"] and new["r.rrd"].startswith(b"RRF2")
    assert b"<!doctype html>" in new["r.html"].lower()
    html.write_bytes(OLD)
    done = _twin("replay", src, "--html", html, "--force", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "twin replay" in _replaced(tmp_path, "r.html")["r.html"].decode()


def test_check_force_replaces_html_summary_and_junit(src, tmp_path):
    html, md, xml = _existing(tmp_path, "r.html", "r.md", "r.xml")
    done = _twin(
        "check", src, "--html", html, "--summary", md, "--junit", xml, "--force", cwd=tmp_path
    )
    assert done.returncode == 0, done.stdout + done.stderr
    new = _replaced(tmp_path, "r.html", "r.md", "r.xml")
    assert b"twin check" in new["r.html"] and b"src.mcap" in new["r.md"]
    assert b'<testcase name="src.mcap"' in new["r.xml"] or b"src.mcap" in new["r.xml"]


def test_sweep_compare_and_plot_force_replace_their_files(tmp_path):
    md, png, html = _existing(tmp_path, "r.md", "r.png", "r.html")
    done = _twin(
        "sweep",
        "compare",
        SWEEP,
        SWEEP,
        "--report",
        md,
        "--plot",
        png,
        "--html",
        html,
        "--force",
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    new = _replaced(tmp_path, "r.md", "r.png", "r.html")
    assert new["r.png"].startswith(b"\x89PNG") and b"<html" in new["r.html"].lower()
    assert new["r.md"].startswith(b"#")
    png.write_bytes(OLD)
    done = _twin("sweep", "plot", SWEEP, "--out", png, "--force", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert _replaced(tmp_path, "r.png")["r.png"].startswith(b"\x89PNG")


def test_recover_force_replaces_its_output(src, tmp_path):
    (out,) = _existing(tmp_path, "r.mcap")
    done = _twin("recover", src, "-o", out, "--force", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    _replaced(tmp_path, "r.mcap")
    assert len(twin.load(out).frames) == len(twin.load(src).frames)


def test_force_alone_says_what_it_replaces(src, tmp_path):
    done = _twin("check", src, "--force", cwd=tmp_path)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr == (
        "twin: error: --force replaces files in the --keep folder and existing --html, --summary, "
        "--junit files; expected --keep DIR, --html, --summary or --junit too\n"
    )
