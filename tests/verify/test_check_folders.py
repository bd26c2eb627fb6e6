"""`twin check FOLDER` takes every golden under the folder: .mcap recordings, sweep goldens and
search goldens, in sub-folders too, and says how many of each it took."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from support.cli import twin

from twin.model.errors import ConfigError
from twin.verify.check import find_goldens

ROOT = Path(__file__).resolve().parents[2]
TOP = sorted(p.name for p in (ROOT / "recordings").glob("*.mcap"))


@pytest.fixture
def recs(tmp_path) -> Path:
    """A copy of recordings/, with what a folder of goldens also holds: leftovers, a hidden folder,
    a robot profile, a golden nested deeper."""
    recs = tmp_path / "recs"
    shutil.copytree(ROOT / "recordings", recs)
    (recs / "pick_place_mtb.obtained.mcap").write_bytes(b"left by the pytest plugin")
    (recs / "x.mcap.partial").write_bytes(b"a recording killed part-way")
    (recs / "x.mcap.tmp").write_bytes(b"an --update killed part-way")
    (recs / ".hidden.mcap").write_bytes(b"an editor's")
    (recs / ".cache").mkdir()
    (recs / ".cache" / "old.mcap").write_bytes(b"")
    (recs / "arm.toml").write_text('urdf = "arm.urdf"\n')  # a robot profile: no definition
    (recs / "more" / "deeper").mkdir(parents=True)
    shutil.copy(recs / "session_seed002.mcap", recs / "more" / "deeper" / "s.mcap")
    return recs


def test_a_folder_means_every_golden_under_it(recs):
    found = find_goldens([str(recs)])
    assert found.recordings == [str(recs / name) for name in TOP] + [
        str(recs / "more" / "deeper" / "s.mcap")
    ]
    # the search golden's own recording is part of it, not a golden of its own
    assert found.searches == [str(recs / "search" / "pick_place_reach.toml")]
    assert found.sweeps == [str(recs / "sweeps" / "pick_place_jitter.toml")]
    assert found.count_line() == "checking 16 goldens: 14 recordings, 1 sweep, 1 search"
    assert found.folders == [str(recs)]


def test_each_golden_once_however_it_is_named(recs, monkeypatch):
    monkeypatch.chdir(recs.parent)
    (recs / "link.mcap").symlink_to(recs / "pick_place_mtb.mcap")
    (recs / "more" / "up").symlink_to(recs, target_is_directory=True)  # a loop
    found = find_goldens(
        [
            "recs/sweeps",
            "recs",
            "./recs/pick_place_mtb.mcap",
            "recs/search/../search/pick_place_reach.toml",
        ]
    )
    assert found.count_line() == "checking 16 goldens: 14 recordings, 1 sweep, 1 search"
    assert found.sweeps == ["recs/sweeps/pick_place_jitter.toml"]  # in the order named
    # a named file is taken as it is: the search golden's recording too
    named = find_goldens(["recs/search/pick_place_reach.mcap", "recs/session_seed002.mcap"])
    assert named.count_line() == "checking 2 goldens: 2 recordings"


def test_no_path_means_recordings(recs, monkeypatch):
    monkeypatch.chdir(recs.parent)
    os.rename(recs, recs.parent / "recordings")
    assert find_goldens([]).count_line() == "checking 16 goldens: 14 recordings, 1 sweep, 1 search"


def test_a_toml_beside_a_summary_must_be_a_definition(recs):
    (recs / "more" / "old.toml").write_text('task = "pick_place"\nscenarios = 3\n')
    (recs / "more" / "old.summary.json").write_text("{}")
    with pytest.raises(ConfigError, match=r"old.toml' \(beside old.summary.json\) lacks seed"):
        find_goldens([str(recs)])


def test_a_small_folder_through_the_cli_prints_its_count_first(recs, capsys):
    small = recs.parent / "small"
    (small / "search").mkdir(parents=True)
    shutil.copy(recs / "session_seed002.mcap", small)
    for name in ("pick_place_reach.toml", "pick_place_reach.expect.json", "pick_place_reach.mcap"):
        shutil.copy(recs / "search" / name, small / "search")
    code, out, err = twin(capsys, "check", small)
    assert code == 0, out + err
    lines = out.splitlines()
    assert lines[0] == "checking 2 goldens: 1 recording, 1 search"
    assert "session_seed002.mcap" in lines[2] and "search/pick_place_reach.toml" in lines[3]
    assert lines[-1] == "2 match"


@pytest.mark.parametrize("holds", [[], ["README.md", "notes.txt", "profile.toml"]])
def test_a_folder_without_goldens_is_one_line_exit_2(tmp_path, capsys, holds):
    for name in holds:
        (tmp_path / name).write_text('urdf = "arm.urdf"\n')
    code, out, err = twin(capsys, "check", tmp_path)
    assert (code, out) == (2, "")
    assert err == (
        f"twin: error: folder {str(tmp_path)!r} holds no goldens; expected .mcap recordings, "
        "sweep goldens (NAME.toml with NAME.summary.json) or search goldens (NAME.toml with "
        "NAME.expect.json) in it or a sub-folder\n"
    )
