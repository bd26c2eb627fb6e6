"""One atomic write (twin.record.outputs.atomic_path, write_atomic): a temporary file beside the
target, fsynced and renamed into place; removed on any error or Ctrl-C; a failed write is one
OutputError naming the path and the system's reason."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from support.read_only import read_only

from twin.model.errors import OutputError
from twin.record.outputs import atomic_path, write_atomic


def test_writes_the_bytes_and_leaves_nothing_beside_them(tmp_path):
    target = tmp_path / "a.json"
    write_atomic(target, "héllo\n")
    assert target.read_bytes() == "héllo\n".encode()
    write_atomic(target, b"\x00\x01")
    assert target.read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]


def test_a_new_file_gets_the_umask_mode_and_a_rewritten_one_keeps_its_own(tmp_path):
    umask = os.umask(0o022)
    try:
        write_atomic(tmp_path / "new.txt", "x")
        assert (tmp_path / "new.txt").stat().st_mode & 0o777 == 0o644
        (tmp_path / "new.txt").chmod(0o600)
        write_atomic(tmp_path / "new.txt", "y")
        assert (tmp_path / "new.txt").stat().st_mode & 0o777 == 0o600
    finally:
        os.umask(umask)


def test_the_temporary_is_hidden_beside_the_target(tmp_path):
    with atomic_path(tmp_path / "out.parquet") as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".out.parquet.")
        tmp.write_text("done")
    assert (tmp_path / "out.parquet").read_text() == "done" and not tmp.exists()


@pytest.mark.parametrize("stop", [KeyboardInterrupt, ValueError])
def test_an_error_or_ctrl_c_removes_the_temporary_and_keeps_the_old_file(tmp_path, stop):
    target = tmp_path / "golden.json"
    target.write_text("old")
    with pytest.raises(stop), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise stop()
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["golden.json"]


def test_a_read_only_folder_is_one_output_error_naming_the_path_and_why(tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    (folder / "old.json").write_text("old")
    with read_only(folder):
        with pytest.raises(OutputError) as err:
            write_atomic(folder / "old.json", "new")
        message = str(err.value)
        assert "\n" not in message and err.value.exit_code == 2
        assert message.startswith(f"cannot write {str(folder / 'old.json')!r}: ")
        assert "ermission" in message or "not permitted" in message
        assert (folder / "old.json").read_text() == "old"
        assert sorted(p.name for p in folder.iterdir()) == ["old.json"]


def test_a_folder_that_is_a_file_is_an_output_error_even_for_root(tmp_path):
    (tmp_path / "plain").write_text("")
    with pytest.raises(OutputError, match=r"cannot write .*plain/x.json.*: Not a directory"):
        write_atomic(tmp_path / "plain" / "x.json", "x")


def test_a_failed_write_in_the_body_is_an_output_error(tmp_path):
    target = tmp_path / "t.txt"
    missing = "cannot write .*t.txt.*: No such file or directory"
    with pytest.raises(OutputError, match=missing), atomic_path(target) as tmp:
        Path(tmp.parent / "missing" / "x").write_text("")
    assert list(tmp_path.iterdir()) == []
