"""Recording.to_arrow / to_pandas and `twin export --format parquet|csv` on real runs: one row per
recorded frame, values equal to twin.load(...).frames, units in the column names."""

from __future__ import annotations

import csv
import os
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from support.cli import twin

import twin as twin_pkg
from twin.model.fields import FRAME_FIELDS
from twin.record.tables import frame_column_names

GOLDEN = str(Path(__file__).resolve().parents[2] / "recordings" / "pick_place_mtb.mcap")


def _frame_values(rec) -> np.ndarray:
    """Every Frame field of every frame as one float64 matrix, in field order (as the table lays
    them)."""
    n = len(rec.frames)
    return np.column_stack(
        [getattr(rec.frames, f.name).reshape(n, -1).astype(np.float64) for f in FRAME_FIELDS]
    )


def test_frames_table_has_one_row_per_frame_and_the_frames_values(pick_place_mcap):
    path, _ = pick_place_mcap
    rec = twin_pkg.load(path)
    table = rec.to_arrow()
    assert table.num_rows == len(rec.frames)
    names = frame_column_names(["box"])
    assert table.column_names == [*names, "suction.command"]
    got = np.column_stack(
        [table.column(c).to_numpy(zero_copy_only=False).astype(np.float64) for c in names]
    )
    assert got.tobytes() == _frame_values(rec).tobytes()
    assert table.column("step").type == "int64" and table.column("suction.on").type == "bool"
    assert table.column("suction.held").type == "int32"


def test_column_names_carry_units_by_joint_type():
    names = frame_column_names(["box", "pad"])
    for expected in (
        "joint.shoulder.position_rad",
        "joint.z.position_m",
        "joint.z.velocity_m_s",
        "joint.elbow.effort_Nm",
        "joint.z.effort_N",
        "joint.wrist.target_rad",
        "hold.force_z_N",
        "hold.torque_x_Nm",
        "pad.qw",
        "box.x_m",
        "object.pad.z_m",
    ):
        assert expected in names
    assert len(names) == len(set(names))


def test_suction_command_follows_the_commands(pick_place_mcap):
    """The commanded suction (from the signal Commands) is what the pad did on pick_place: it is on
    from the step after the command that switched it on (no break in this run)."""
    path, _ = pick_place_mcap
    rec = twin_pkg.load(path)
    table = rec.to_arrow()
    command = table.column("suction.command").to_numpy(zero_copy_only=False)
    assert command.any() and not command.all()
    assert np.array_equal(command, table.column("suction.on").to_numpy(zero_copy_only=False))
    on_steps = [c.step for c in rec.commands if c.kind == "signal" and c.args["value"] == 1]
    first_on = int(rec.frames.step[np.argmax(command)])
    assert first_on == on_steps[0] + 1


def test_suction_command_of_a_key_session(tmp_path, capsys):
    """Keys switch suction through the recording's key map (seed001: `3` on and down, `5` off)."""
    mcap = tmp_path / "keys.mcap"
    assert (
        twin(capsys, "teleop", "--robot", "seed001", "--keys", "3 wait*2 5 wait", "--record", mcap)[
            0
        ]
        == 0
    )
    rec = twin_pkg.load(mcap)
    assert {c.kind for c in rec.commands} == {"key"}
    table = rec.to_arrow()
    command = table.column("suction.command").to_numpy(zero_copy_only=False)
    assert command.any() and not command[-1]
    assert np.array_equal(command, table.column("suction.on").to_numpy(zero_copy_only=False))


def test_a_recording_without_frames_gives_an_empty_table(pick_place_mcap):
    rec = twin_pkg.load(pick_place_mcap[0])
    rec.frames = rec.frames.slice(0, 0)
    table = rec.to_arrow()
    assert table.num_rows == 0 and table.num_columns == len(frame_column_names(["box"])) + 1


def test_events_and_commands_tables(pick_place_mcap):
    path, _ = pick_place_mcap
    rec = twin_pkg.load(path)
    events = rec.to_pandas("events")
    assert list(events["kind"]) == [e.kind for e in rec.events]
    assert list(events.columns) == ["step", "t_ns", "kind", "body", "message", "data_json"]
    commands = rec.to_pandas("commands")
    assert len(commands) == len(rec.commands)
    assert (commands["t_ns"] == commands["step"] * rec.config.dt_ns).all()
    with pytest.raises(ValueError, match="unknown"):
        rec.to_arrow("poses")


def test_to_pandas_without_pandas_is_one_clear_line(pick_place_mcap, monkeypatch):
    rec = twin_pkg.load(pick_place_mcap[0])
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas now raises ImportError
    with pytest.raises(ImportError, match=r"needs the pandas package: pip install pandas"):
        rec.to_pandas()


def test_export_parquet_and_csv_of_a_golden(tmp_path, capsys):
    rec = twin_pkg.load(GOLDEN)
    out = tmp_path / "golden.parquet"
    code, stdout, _ = twin(capsys, "export", GOLDEN, "--format", "parquet", "-o", out)
    assert code == 0 and f"{len(rec.frames)} rows" in stdout
    assert pq.read_metadata(out).num_rows == len(rec.frames) == 2518
    assert pq.read_table(out).equals(rec.to_arrow())
    out_csv = tmp_path / "golden.csv"
    assert twin(capsys, "export", GOLDEN, "--format", "csv", "-o", out_csv)[0] == 0
    with open(out_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(rec.frames)
    table = rec.to_arrow()
    assert list(rows[0]) == table.column_names
    # every CSV value reads back to the same value (floats: the same doubles)
    for name in table.column_names:
        want = table.column(name).to_pylist()
        got = [
            r[name] == "true" if isinstance(w, bool) else type(w)(r[name])
            for r, w in zip(rows, want, strict=True)
        ]
        assert got == want, name
    assert not list(tmp_path.glob("*.partial"))


def test_export_parquet_of_a_decimated_run(tmp_path, capsys):
    mcap = tmp_path / "rate4.mcap"
    assert (
        twin(capsys, "run", "pick_place", "--cycles", "1", "--rate", "4", "--record", mcap)[0] == 0
    )
    rec = twin_pkg.load(mcap)
    out = tmp_path / "rate4.parquet"
    assert twin(capsys, "export", mcap, "--format", "parquet", "-o", out)[0] == 0
    table = pq.read_table(out)
    assert table.num_rows == len(rec.frames)
    steps = table.column("step").to_numpy()
    assert np.all(np.diff(steps)[:-1] == 4) and steps[-1] == rec.frames.step[-1]
    assert table.schema.metadata[b"twin.rate_steps"] == b"4"
    events = tmp_path / "events.csv"
    assert (
        twin(capsys, "export", mcap, "--format", "csv", "--table", "events", "-o", events)[0] == 0
    )
    with open(events, newline="") as f:
        assert len(list(csv.DictReader(f))) == len(rec.events)


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["--format", "xlsx", "-o", "x.xlsx"], "invalid choice: 'xlsx'"),
        (["--format", "parquet", "-o", "x.csv"], "should end in .parquet"),
        (["--format", "csv", "--fps", "30", "-o", "x.csv"], "--fps is for --format lerobot"),
        (
            ["--format", "parquet", "--verify", "-o", "x.parquet"],
            "--verify is for --format lerobot",
        ),
        (["--format", "parquet", "-o", "missing/x.parquet"], "folder 'missing' does not exist"),
    ],
)
def test_bad_table_exports_are_one_line_exit_2(tmp_path, capsys, monkeypatch, argv, expected):
    monkeypatch.chdir(tmp_path)
    code, _, err = twin(capsys, "export", GOLDEN, *argv)
    assert (
        code == 2 and err.count("\n") == 1 and err.startswith("twin: error: ") and expected in err
    ), err
    assert list(tmp_path.iterdir()) == []


def test_export_of_two_files_or_a_missing_one_is_refused(tmp_path, capsys):
    code, _, err = twin(
        capsys, "export", GOLDEN, GOLDEN, "--format", "parquet", "-o", tmp_path / "x.parquet"
    )
    assert code == 2 and "writes one recording; got 2 files" in err
    code, _, err = twin(
        capsys, "export", tmp_path / "nope.mcap", "--format", "csv", "-o", tmp_path / "x.csv"
    )
    assert code == 2 and err.startswith("twin: error: ") and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_encoding_video_leaves_the_process_scheduling_as_it_was(tmp_path):
    """SVT-AV1 (run as root) switches the calling thread to SCHED_FIFO 99; every process started
    afterwards inherits it, and one that spins (rerun's server does) starves the machine. encode_mp4
    puts the policy back."""
    import numpy as np

    from twin.export.video import encode_mp4

    before = (os.sched_getscheduler(0), os.sched_getparam(0))
    frames = [np.full((240, 320, 3), i * 20, np.uint8) for i in range(6)]
    assert encode_mp4(tmp_path / "a.mp4", frames, 30, 320, 240) == 6
    assert (os.sched_getscheduler(0), os.sched_getparam(0)) == before
