"""Never destroy a recording: output paths are checked before any work, files are written beside
their place and renamed in when finalized, a killed run's `.partial` file is what `twin recover`
finds. Everything through the real `twin` command, as subprocesses."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

import twin

pytestmark = pytest.mark.slow  # seconds each: `-m "not slow"` leaves them out

from support.cli import ENDLESS_TASK as ENDLESS
from support.cli import TWIN


def _twin(*args: str, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*TWIN, *args], capture_output=True, text=True, timeout=timeout, cwd=cwd, check=False
    )


def _one_line_error(done: subprocess.CompletedProcess, *words: str) -> None:
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("twin: error:"), done.stderr
    for word in words:
        assert word in lines[0], lines[0]


@pytest.fixture(scope="module")
def golden(pick_place_cli) -> Path:
    """One pick_place cycle recorded by the real `twin run` (the session's shared recording)."""
    return pick_place_cli["mcap"]


def test_view_refuses_to_convert_onto_its_source_also_through_a_hard_link(golden, tmp_path):
    source = tmp_path / "src.mcap"
    shutil.copy(golden, source)
    before = source.read_bytes()
    _one_line_error(_twin("view", str(source), "--rrd", str(source)), "should end in .rrd")
    link = tmp_path / "link.rrd"
    os.link(source, link)
    _one_line_error(
        _twin("view", str(source), "--rrd", str(link)), "would overwrite its input", "same file"
    )
    assert source.read_bytes() == before


def test_an_explicit_missing_folder_is_an_error_before_any_work(tmp_path):
    missing = tmp_path / "no" / "such"
    for args in (
        ["--record", str(missing / "x.mcap")],
        ["--no-record", "--rrd", str(missing / "x.rrd")],
    ):
        done = _twin("run", "pick_place", *args)
        _one_line_error(done, str(missing))
        assert done.stdout == ""  # nothing ran
    assert not (tmp_path / "no").exists()
    folder = tmp_path / "taken.mcap"
    folder.mkdir()
    _one_line_error(_twin("run", "pick_place", "--record", str(folder)), "is a folder")


def test_the_default_folder_is_still_created_and_its_file_not_replaced(tmp_path):
    done = _twin("run", "pick_place", "--cycles", "1", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    path = tmp_path / "runs" / "pick_place_mtb.mcap"
    assert twin.load(path).finalized
    before = path.read_bytes()
    _one_line_error(
        _twin("run", "pick_place", "--cycles", "1", cwd=tmp_path),
        "runs/pick_place_mtb.mcap",
        "--force",
    )
    assert path.read_bytes() == before


def test_an_existing_output_is_refused_and_left_byte_identical_until_force(golden, tmp_path):
    """run --record, replay --record, export -o and view --rrd onto an existing file: exit 2, one
    line naming it, the file unchanged; --force replaces it with the new one."""
    src = tmp_path / "src.mcap"
    shutil.copy(golden, src)
    taken = {suffix: tmp_path / f"taken{suffix}" for suffix in (".mcap", ".parquet", ".rrd")}
    for path in taken.values():
        path.write_bytes(b"the user's own bytes")
    commands = [
        ("run", "pick_place", "--cycles", "1", "--record", str(taken[".mcap"])),
        ("run", "pick_place", "--cycles", "1", "--no-record", "--rrd", str(taken[".rrd"])),
        ("replay", str(src), "--record", str(taken[".mcap"])),
        ("export", str(src), "--format", "parquet", "-o", str(taken[".parquet"])),
        ("view", str(src), "--rrd", str(taken[".rrd"])),
    ]
    for command in commands:
        done = _twin(*command)
        _one_line_error(done, repr(str(command[-1])), "exists already", "--force")
        assert done.stdout == ""  # refused before any work
    assert all(p.read_bytes() == b"the user's own bytes" for p in taken.values())
    done = _twin(*commands[0], "--force")
    assert done.returncode == 0, done.stderr
    assert twin.load(taken[".mcap"]).frames.t_ns[-1] > 0  # the new recording, complete
    done = _twin(*commands[3], "--force")
    assert done.returncode == 0, done.stderr
    assert taken[".parquet"].read_bytes()[:4] == b"PAR1"
    assert not list(tmp_path.glob(".*.tmp")) and not list(tmp_path.glob("*.partial"))


def _start_endless(tmp_path: Path, *record: str) -> subprocess.Popen:
    task = tmp_path / "endless.py"
    task.write_text(ENDLESS)
    proc = subprocess.Popen(
        [*TWIN, "run", str(task), *record],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    for line in proc.stdout:
        if line.startswith("t_s=") and float(line[4:]) >= 3.0:
            break
    return proc


def _kill_group(proc: subprocess.Popen) -> None:
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    time.sleep(0.2)  # the recorder, in the same group, is gone too: nothing writes any more


def test_a_killed_re_record_leaves_the_old_file_and_a_partial_file_recover_finds(golden, tmp_path):
    target = tmp_path / "g.mcap"
    shutil.copy(golden, target)
    before = target.read_bytes()
    run = _start_endless(
        tmp_path, "--record", str(target), "--rrd", str(tmp_path / "g.rrd"), "--force"
    )
    # the Rerun writer starts beside the run (3 s of simulated time can pass first on a busy
    # machine): the kill comes once both writers have their files
    deadline = time.monotonic() + 30
    while not (tmp_path / "g.rrd.partial").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    _kill_group(run)
    assert target.read_bytes() == before  # the golden is untouched
    partial = tmp_path / "g.mcap.partial"
    assert (
        partial.is_file()
        and (tmp_path / "g.rrd.partial").is_file()
        and not (tmp_path / "g.rrd").exists()
    )
    # g.mcap exists: recover needs to be told where to write
    _one_line_error(_twin("recover", str(target)), "-o")
    done = _twin("recover", str(partial), "-o", str(tmp_path / "fixed.mcap"))
    assert done.returncode == 0, done.stderr
    assert len(twin.load(tmp_path / "fixed.mcap").frames) > 240


def test_recover_of_a_killed_run_finds_its_partial_file_and_writes_the_recording(tmp_path):
    target = tmp_path / "k.mcap"
    _kill_group(_start_endless(tmp_path, "--record", str(target)))
    assert not target.exists()
    info = _twin("info", str(target))
    _one_line_error(info, "k.mcap.partial", "twin recover")
    done = _twin("recover", str(target))
    assert done.returncode == 0, done.stderr
    assert "k.mcap.partial" in done.stdout
    rec = twin.load(target)
    assert not rec.finalized and rec.frames.t_ns[-1] >= 2_000_000_000
    assert (tmp_path / "k.mcap.partial").is_file()  # kept: recover never destroys its input
    assert not list(tmp_path.glob("*.recovering"))


def test_recover_checks_its_output_path(golden, tmp_path):
    source = tmp_path / "s.mcap"
    shutil.copy(golden, source)
    os.link(source, tmp_path / "link.mcap")
    before = source.read_bytes()
    _one_line_error(
        _twin("recover", str(source), "-o", str(tmp_path / "link.mcap")),
        "would overwrite its input",
    )
    _one_line_error(
        _twin("recover", str(source), "-o", str(tmp_path / "none" / "x.mcap")), "does not exist"
    )
    _one_line_error(
        _twin("recover", str(source), "-o", str(tmp_path / "x.rrd")), "should end in .mcap"
    )
    assert source.read_bytes() == before
    assert not (tmp_path / "none").exists()


def test_check_update_names_one_golden_twice_without_a_race(golden, tmp_path):
    shutil.copy(golden, tmp_path / "G.mcap")
    done = _twin("check", "-j", "2", "--update", "G.mcap", "./G.mcap", str(tmp_path), cwd=tmp_path)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.count("G.mcap") == 1 and "1 match" in done.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["G.mcap"]


def test_start_writeback_leaves_the_file_as_written_and_takes_any_descriptor(tmp_path):
    """The writers call it as their files grow: it only asks the OS to start writing them out, on a
    regular file and on whatever else a path may name (a pipe), without an error."""
    from twin.record.outputs import start_writeback

    path = tmp_path / "x.bin"
    data = os.urandom(1 << 20)
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        start_writeback(f.fileno())
        f.write(data[:10])
    assert path.read_bytes() == data + data[:10]
    read_end, write_end = os.pipe()
    try:
        start_writeback(write_end)
    finally:
        os.close(read_end)
        os.close(write_end)


def test_a_writeback_is_started_once_another_share_of_the_file_is_written(tmp_path):
    """Writeback asks the OS only every `every_bytes` of growth (each ask costs CPU), counting from
    the size at the last one."""
    from twin.record.outputs import Writeback

    with open(tmp_path / "x.bin", "wb") as f:
        writeback = Writeback(f.fileno(), every_bytes=1000)
        sizes = []
        for size in (500, 999, 1000, 1500, 1999, 2000, 5000):
            writeback.grew_to(size)
            sizes.append(writeback._started_at)
    assert sizes == [0, 0, 1000, 1000, 1000, 2000, 5000]
