"""Readers on a recording with one corrupt or foreign part: what they could read, one error line,
exit 2.

`twin info` prints its report and exits 2 when anything in the file is unreadable or foreign (it
used to exit 0, printing `events: (unreadable) 13`); a corrupt configuration record (`objects = 7`)
is one line naming the field from every reader (it was a TypeError traceback, raised while wording
the error); a camera that cannot look anywhere is refused where the configuration is read (it was a
ZeroDivisionError in `twin view --rrd`). Deep nesting in a file's JSON is one line too, never a
RecursionError.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

import twin
from twin.cli import main
from twin.model.errors import RecordingError
from twin.record.mcap import schemas as S
from twin.record.mcap.info import read_info

READERS = ("info", "recover", "diff", "replay", "check", "view")


def rewrite(
    source: Path,
    out: Path,
    *,
    config=None,
    metadata: dict | None = None,
    edit=None,
    library: str = S.LIBRARY,
) -> Path:
    """A copy of a recording written by mcap's own Writer: config(dict) edits the twin.config record
    in place, metadata replaces records by name (None: leaves it out), edit(topic, data) -> data the
    messages."""
    with open(source, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = [
            (channel.topic, message)
            for _, channel, message in reader.iter_messages(log_time_order=False)
        ]
        records = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    if config is not None:
        value = json.loads(records[S.META_CONFIG]["json"])
        config(value)
        records[S.META_CONFIG] = {"json": json.dumps(value)}
    for name, record in (metadata or {}).items():
        if record is None:
            records.pop(name, None)
        else:
            records[name] = record
    with open(out, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library=library)
        schema_ids = {
            sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()
        }
        channel_ids = {
            cid: w.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id])
            for cid, c in summary.channels.items()
        }
        for name, record in records.items():
            w.add_metadata(name, record)
        for topic, m in messages:
            w.add_message(
                channel_ids[m.channel_id],
                m.log_time,
                edit(topic, m.data) if edit else m.data,
                m.publish_time,
                m.sequence,
            )
        w.finish()
    return out


def _on(topic: str, data: bytes):
    return lambda t, old: data if t == topic else old


def _cli(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _one_line(err: str) -> str:
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("twin: error: "), err
    return lines[0]


@pytest.fixture(scope="module")
def good(pick_place_mcap) -> Path:
    return pick_place_mcap[0]


# -- twin info: what it read, then exit 2 ----------------------------------------------------------

INFO_CASES = {
    # name: (how the file is made from a good one, what the error line says)
    "events_not_json": (
        {"edit": _on(S.EVENTS.topic, b"not json")},
        f"{S.EVENTS.topic} messages are unreadable (the first: a event message is not JSON",
    ),
    "commands_not_objects": (
        {"edit": _on(S.COMMANDS.topic, b"[1]")},
        f"{S.COMMANDS.topic} messages are unreadable",
    ),
    "robot_description_empty_object": (
        {"edit": _on(S.ROBOT_DESCRIPTION.topic, b"{}")},
        f"1 of its 1 {S.ROBOT_DESCRIPTION.topic} message is unreadable",
    ),
    "block_without_frames": (
        {"edit": _on(S.JOINTS.topic, b"")},
        f"{S.JOINTS.topic} messages are unreadable",
    ),
    "config_objects_7": (
        {"config": lambda c: c.update(objects=7)},
        "twin.config field objects = 7 is invalid; expected a list of at most 100 JSON objects",
    ),
    "run_params_a_list": (
        {"metadata": {S.META_RUN: {"source": "task", "task": "pick_place", "params": "[1]"}}},
        "twin.run field params = [1] is invalid",
    ),
    "no_twin_metadata": (
        {"metadata": {S.META_CONFIG: None, S.META_RUN: None}, "library": "someone else"},
        "it has no twin.config metadata: it was not written by twin (written by 'someone else')",
    ),
}


@pytest.mark.parametrize("case", sorted(INFO_CASES))
def test_info_prints_what_it_read_and_exits_2_when_a_part_is_unreadable(
    good, tmp_path, capsys, case
):
    how, said = INFO_CASES[case]
    path = rewrite(good, tmp_path / f"{case}.mcap", **how)
    code, out, err = _cli(capsys, "info", path)
    assert code == 2, (out, err)
    line = _one_line(err)
    assert said in line and str(path) in line, line
    lines = out.splitlines()
    assert (
        lines[0].startswith(f"file: {path} (")
        and "channels:" in lines
        and "finalized: yes (run outcome ok)" in out
    )
    # the report names it too
    assert any(x.startswith("problem: ") and said in x for x in lines), out
    assert any(x.strip().startswith(S.TF.topic) for x in lines)  # and shows what it could read


def test_info_counts_the_readable_events_and_lists_them(good, tmp_path, capsys):
    """One event unreadable: the others are counted and listed (--events); exit 2."""
    n = len(twin.load(good).events)
    seen = [0]

    def second_event_bad(topic: str, data: bytes) -> bytes:
        if topic == S.EVENTS.topic:
            seen[0] += 1
            if seen[0] == 2:
                return b'{"step": "x"}'
        return data

    path = rewrite(good, tmp_path / "one_bad_event.mcap", edit=second_event_bad)
    info = read_info(path)
    assert sum(info.events.values()) == n - 1 and len(info.event_list) == n - 1
    assert info.problems == [
        (
            f"1 of its {n} {S.EVENTS.topic} messages is unreadable (the first: malformed event "
            '{"step": "x"}: step \'x\' is not a whole number 0..10000000000)'
        )
    ]
    code, out, err = _cli(capsys, "info", path, "--events")
    assert code == 2 and f"all events ({n - 1}):" in out and f"1 of its {n}" in _one_line(err)


def test_a_foreign_mcap_is_described_then_exit_2(tmp_path, capsys):
    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="x", library="someone else")
        w.add_message(
            w.register_channel("/x", "json", w.register_schema("s", "jsonschema", b"{}")),
            0,
            b"{}",
            0,
        )
        w.finish()
    code, out, err = _cli(capsys, "info", path)
    assert code == 2
    assert "was not written by twin (written by 'someone else')" in _one_line(err)
    assert "  /x  " in out and "robot: ?" in out


def test_a_good_file_still_has_no_problem(good, capsys):
    assert read_info(good).problems == []
    assert _cli(capsys, "info", good)[0] == 0


# -- a corrupt configuration record: every reader, one line ----------------------------------------

CONFIG_CASES = {
    "objects_7": (lambda c: c.update(objects=7), "objects = 7"),
    "objects_list_of_7": (lambda c: c.update(objects=[7]), "objects[0] = 7"),
    "profile_7": (lambda c: c.update(profile=7), "profile = 7"),
    "profile_missing": (
        lambda c: c.pop("profile"),
        "field profile is missing; expected a JSON object",
    ),
    "engine_a_list": (lambda c: c.update(engine=[1]), "engine = [1]"),
    "cameras_7": (lambda c: c.update(cameras=7), "cameras = 7"),
    "keymap_900_deep": (
        lambda c: c.update(keymap={"a": json.loads("[" * 900 + "]" * 900)}),
        "field keymap = ",
    ),
}


@pytest.mark.parametrize("case", sorted(CONFIG_CASES))
def test_a_corrupt_config_record_is_one_line_from_every_reader(good, tmp_path, capsys, case):
    edit, said = CONFIG_CASES[case]
    path = rewrite(good, tmp_path / f"{case}.mcap", config=edit)
    with pytest.raises(RecordingError, match="its twin configuration is unreadable"):
        twin.load(path)
    for reader in READERS:
        argv = {
            "recover": ["recover", path, "-o", tmp_path / "r.mcap"],
            "diff": ["diff", path, good],
            "view": ["view", path, "--rrd", tmp_path / "v.rrd"],
        }.get(reader, [reader, path])
        code, out, err = _cli(capsys, *argv)
        assert code == 2, (reader, out, err)
        if reader == "check":  # check reports each file in its table, its progress on stderr
            assert "Traceback" not in out + err and said in out, (reader, out, err)
        else:
            assert said in _one_line(err), (reader, err)


# -- a camera that cannot look anywhere ------------------------------------------------------------


@pytest.fixture(scope="module")
def camera_file(tmp_path_factory) -> Path:
    """One pick_place cycle with a small overhead camera (64x48), made by `twin run`."""
    path = tmp_path_factory.mktemp("camera") / "camera.mcap"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "run",
            "pick_place",
            "--cycles",
            "1",
            "--camera",
            "overhead",
            "--camera-size",
            "64x48",
            "--record",
            str(path),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return path


CAMERA_CASES = {
    "eye_on_the_target": (
        {"eye_m": [0.0, 0.075, 0.0]},
        "are 0 m apart; expected a target at least 1e-06 m",
    ),
    "up_zero": ({"up": [0.0, 0.0, 0.0]}, "up [0.0, 0.0, 0.0] is no direction"),
    "up_along_the_view": ({"up": [0.0, 0.0, 2.0]}, "is along the view direction"),
}


@pytest.mark.parametrize("case", sorted(CAMERA_CASES))
def test_a_camera_that_cannot_look_anywhere_is_one_line_exit_2(camera_file, tmp_path, capsys, case):
    change, said = CAMERA_CASES[case]
    path = rewrite(
        camera_file, tmp_path / f"{case}.mcap", config=lambda c: c["cameras"][0].update(change)
    )
    for argv in (["view", path, "--rrd", tmp_path / "v.rrd"], ["info", path], ["replay", path]):
        code, _, err = _cli(capsys, *argv)
        assert code == 2 and "camera 'overhead': " in _one_line(err) and said in err, (argv, err)
    assert not (tmp_path / "v.rrd").exists()
