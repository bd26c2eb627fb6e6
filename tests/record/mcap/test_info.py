"""`twin info` and bad input to the recording commands: one clear line, exit code 2, no
traceback."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader

import twin
from twin.cli import main
from twin.record.mcap import schemas as S
from twin.record.mcap.info import read_info


@pytest.fixture(scope="module")
def whole(pick_place_mcap) -> Path:
    """One finalized pick_place cycle (the session's shared recording)."""
    return pick_place_mcap[0]


def test_info_of_a_finalized_recording(whole, capsys):
    assert main(["info", str(whole)]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    assert "finalized: yes (run outcome ok)" in out
    rec = twin.load(whole)
    assert f"steps 0..{rec.frames.step[-1]}, {len(rec.frames):,} frames recorded" in out
    with open(whole, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    info = read_info(whole)
    counts = {topic: n for topic, _, _, n in info.channels}
    assert sum(counts.values()) == stats.message_count
    assert counts[S.COMMANDS.topic] == len(rec.commands) == info.commands
    assert info.events == {
        k: sum(e.kind == k for e in rec.events) for k in {e.kind for e in rec.events}
    }
    for topic, n in counts.items():
        assert f"{topic}" in out and f"{n:>7,} messages" in out
    assert "twin.versions: mcap=1.6.0" in out and "robot.urdf" in out
    assert 'run: task pick_place params {"cycles": 1}' in out


def test_info_of_a_file_cut_short_says_not_finalized(whole, tmp_path, capsys):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    assert main(["info", str(cut)]) == 2
    out, err = capsys.readouterr()
    assert "finalized: no" in out and "frames recorded" in out
    assert err.count("\n") == 1 and err.startswith("twin: error: ") and "twin recover" in err


def _bad_inputs(tmp_path: Path, whole: Path) -> dict[str, Path]:
    (tmp_path / "empty.mcap").write_bytes(b"")
    (tmp_path / "truncated.mcap").write_bytes(whole.read_bytes()[:20])
    (tmp_path / "text.mcap").write_text("this is not a recording\n")
    (tmp_path / "folder.mcap").mkdir()
    return {
        "is empty": tmp_path / "empty.mcap",
        "no complete MCAP header": tmp_path / "truncated.mcap",
        "is not an MCAP file": tmp_path / "text.mcap",
        "does not exist": tmp_path / "missing.mcap",
        "is a directory": tmp_path / "folder.mcap",
    }


@pytest.mark.parametrize("command", ["info", "recover"])
def test_bad_input_is_one_clear_line_and_exit_code_2(whole, tmp_path, capsys, command):
    for why, path in _bad_inputs(tmp_path, whole).items():
        extra = ["-o", str(tmp_path / "out.mcap")] if command == "recover" else []
        assert main([command, str(path), *extra]) == 2, why
        out, err = capsys.readouterr()
        assert out == ""
        assert err.count("\n") == 1 and err.startswith("twin: error: "), err
        assert why in err and str(path) in err
        assert not (tmp_path / "out.mcap").exists()


def test_load_names_the_file_and_the_problem(whole, tmp_path):
    for why, path in _bad_inputs(tmp_path, whole).items():
        with pytest.raises(twin.model.errors.RecordingError, match=why):
            twin.load(path)
