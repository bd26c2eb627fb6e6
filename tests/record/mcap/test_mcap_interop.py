"""A second, independent reader: Rerun's own MCAP importer (Rust) checks and converts our files."""

from __future__ import annotations

import subprocess

import pytest

from twin.record.rerun.rrd_file import rerun_executable, verify_rrd

TOPICS = (
    "/robot_description",
    "/twin/joints",
    "/twin/suction",
    "/twin/poses",
    "/tf",
    "/events",
    "/twin/events",
    "/commands",
)


@pytest.fixture()
def env(tmp_path, monkeypatch):
    """The rerun CLI writes an analytics config under the home directory: keep it in a tmp dir."""
    home = tmp_path / "home"
    for var, value in (
        ("HOME", home),
        ("XDG_CONFIG_HOME", home / "config"),
        ("XDG_DATA_HOME", home / "data"),
        ("XDG_CACHE_HOME", home / "cache"),
    ):
        monkeypatch.setenv(var, str(value))


def _rerun(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [rerun_executable(), *args], capture_output=True, text=True, timeout=120, check=False
    )


def test_rerun_checks_every_channel_ok_and_converts_the_file(env, tmp_path, pick_place_cli):
    # `twin run pick_place --cycles 1 --record`, checked there to exit 0
    recording = pick_place_cli["mcap"]
    checked = _rerun("mcap", "check", str(recording))
    assert checked.returncode == 0, checked.stderr
    rows = {
        line.split()[3]: line.split()[0]
        for line in checked.stdout.splitlines()
        if len(line.split()) >= 4 and line.split()[3].startswith("/")
    }
    assert rows == {topic: "ok" for topic in TOPICS}
    converted = tmp_path / "run.rrd"
    done = _rerun("mcap", "convert", str(recording), "-o", str(converted))
    assert done.returncode == 0, done.stderr
    verify_rrd(converted)


def test_rerun_refuses_a_cut_file(env, tmp_path, pick_place_cli):
    # `twin run pick_place --cycles 1 --record`, checked there to exit 0
    recording = pick_place_cli["mcap"]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(recording.read_bytes()[: recording.stat().st_size // 2])
    assert _rerun("mcap", "check", str(cut)).returncode != 0
