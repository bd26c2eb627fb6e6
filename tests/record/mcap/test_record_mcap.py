"""MCAP recording: round trip, byte-identical files, decoding by the standard reader, the CLI."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from support.runs import collect_pick_place

import twin
from twin.cli import main
from twin.model.columns import FrameColumns
from twin.model.config import TwinConfig
from twin.model.errors import RecordingError
from twin.record.mcap import schemas as S
from twin.record.mcap import wire
from twin.record.mcap.reader import decode_frames, scan
from twin.robot import kinematics
from twin.robot.urdf import urdf_text
from twin.verify.collectors import FrameCollector

RUN = {"source": "task", "task": "pick_place", "params": {"cycles": 1}}


def record(path: Path, *, rate: int = 1, config: TwinConfig | None = None) -> FrameCollector:
    """Record one pick_place cycle to `path`, with an in-memory collector alongside."""
    return collect_pick_place(path, config, rate=rate)


@pytest.fixture(scope="module")
def recorded(pick_place_mcap) -> tuple[Path, FrameCollector]:
    """(path, collector) of one pick_place cycle: the session's shared recording, made by record()'s
    helper."""
    return pick_place_mcap


def test_round_trip_equals_the_in_memory_stream(recorded):
    path, collector = recorded
    rec = twin.load(path)
    assert rec.frames.equals(collector.columns())
    assert len(rec.frames) == len(collector.frames) > 1000
    assert rec.commands == collector.commands and len(rec.commands) > 10
    assert rec.events == collector.events and any(e.kind == "attach" for e in rec.events)
    assert rec.config == TwinConfig()
    assert rec.run == RUN
    assert rec.finalized and rec.meta[S.META_FINALIZED]["outcome"] == "ok"
    assert rec.urdf == urdf_text(TwinConfig().profile)
    assert rec.meta[S.META_VERSIONS]["mcap"] == "1.6.0"


def test_two_recordings_of_the_same_run_are_byte_identical(recorded, tmp_path):
    path, _ = recorded
    again = tmp_path / "again.mcap"
    record(again)
    assert again.read_bytes() == path.read_bytes()


def test_rate_keeps_every_nth_step_and_the_last(tmp_path):
    collector = record(tmp_path / "rate.mcap", rate=7)
    full = collector.columns()
    last = len(full) - 1
    keep = [i for i in range(len(full)) if i % 7 == 0 or i == last]
    expected = FrameColumns.concat([full.slice(i, i + 1) for i in keep])
    rec = twin.load(tmp_path / "rate.mcap")
    assert rec.frames.equals(expected)
    # inputs are never thinned: the run stays re-executable
    assert rec.commands == collector.commands


def _decoded(path: Path) -> dict[str, list]:
    """Every message of every channel, decoded by mcap's reader with the standard protobuf decoder
    (schemas from the file) or json.loads."""
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        for channel in summary.channels.values():
            out[channel.topic] = []
        for _, channel, message in reader.iter_messages(log_time_order=False):
            schema = summary.schemas[channel.schema_id]
            if channel.message_encoding == "json":
                value = json.loads(message.data)
            else:
                value = DecoderFactory().decoder_for(channel.message_encoding, schema)(message.data)
            out[channel.topic].append((message.log_time, value))
    return out


def test_every_channel_decodes_with_the_standard_reader(recorded):
    path, collector = recorded
    cols = collector.columns()
    d = _decoded(path)
    assert set(d) == {s.topic for s in S.CHANNELS}
    joints = [m for _, m in d[S.JOINTS.topic]]
    assert np.array_equal(np.concatenate([m.step for m in joints]), cols.step)
    assert np.array_equal(np.concatenate([m.t_ns for m in joints]), cols.t_ns)
    assert list(joints[0].joint_names) == list(TwinConfig().profile.joint_names)
    for field, column in (
        ("position", cols.joint_q),
        ("velocity", cols.joint_qd),
        ("effort", cols.joint_effort),
        ("target", cols.joint_target),
    ):
        assert (
            np.concatenate([np.array(getattr(m, field)) for m in joints]).tobytes()
            == column.tobytes()
        )
    suction = [m for _, m in d[S.SUCTION.topic]]
    assert np.array_equal(np.concatenate([m.on for m in suction]), cols.suction_on)
    assert np.array_equal(np.concatenate([m.sensed_body for m in suction]), cols.sensed_body)
    assert np.array_equal(np.concatenate([m.held_body for m in suction]), cols.held_body)
    assert (
        np.concatenate([m.hold_force_n for m in suction]).tobytes() == cols.hold_force_n.tobytes()
    )
    assert (
        np.concatenate([m.hold_torque_nm for m in suction]).tobytes()
        == cols.hold_torque_nm.tobytes()
    )
    poses = [m for _, m in d[S.POSES.topic]]
    assert np.concatenate([m.pad_pose for m in poses]).tobytes() == cols.pad_pose.tobytes()
    assert np.concatenate([m.object_poses for m in poses]).tobytes() == cols.object_poses.tobytes()
    logs = [m for _, m in d[S.LOG.topic]]
    assert [(m.name, m.file) for m in logs] == [(e.kind, e.body) for e in collector.events]
    assert [m.timestamp.seconds * 10**9 + m.timestamp.nanos for m in logs] == [
        e.t_ns for e in collector.events
    ]
    assert [m["kind"] for _, m in d[S.EVENTS.topic]] == [e.kind for e in collector.events]
    assert [(c["step"], c["kind"], c["args"]) for _, c in d[S.COMMANDS.topic]] == [
        (c.step, c.kind, c.args) for c in collector.commands
    ]
    assert d[S.ROBOT_DESCRIPTION.topic][0][1]["data"] == urdf_text(TwinConfig().profile)


def test_fast_path_equals_the_protobuf_decoder_on_every_block(recorded):
    path, _ = recorded
    s = scan(path)
    topics = s.by_topic()
    fast = decode_frames(
        topics[S.JOINTS.topic], topics[S.SUCTION.topic], topics[S.POSES.topic], 1, str(path)
    )
    d = _decoded(path)
    slow = np.concatenate([np.array(m.position) for _, m in d[S.JOINTS.topic]]).reshape(-1, 4)
    assert slow.tobytes() == fast.joint_q.tobytes()
    poses = np.concatenate([np.array(m.object_poses) for _, m in d[S.POSES.topic]]).reshape(
        -1, 1, 7
    )
    assert poses.tobytes() == fast.object_poses.tobytes()


def _compose(a, b):
    """(translation, quaternion) a∘b."""
    from twin.model.quat import quat_mul, rotate

    ta, qa = a
    tb, qb = b
    r = rotate(qa, tb)
    return (ta[0] + r[0], ta[1] + r[1], ta[2] + r[2]), quat_mul(qa, qb)


def test_transforms_chain_to_the_pad_and_carry_the_frames_time(recorded):
    path, collector = recorded
    by_step = {f.t_ns: f for f in collector.frames}
    tf = _decoded(path)[S.TF.topic]
    view_every = round(1e9 / (30.0 * TwinConfig().dt_ns))  # ~30 Hz
    assert [t for t, _ in tf] == [f.t_ns for f in collector.frames if f.step % view_every == 0]
    profile = TwinConfig().profile
    for log_time, message in tf[::25]:
        frame = by_step[log_time]
        stamps = {t.timestamp.seconds * 10**9 + t.timestamp.nanos for t in message.transforms}
        assert stamps == {log_time}
        edges = {t.child_frame_id: (t.parent_frame_id, t) for t in message.transforms}
        pose = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
        chain = []
        link = "suctionPad"
        while link != "world":
            parent, t = edges[link]
            chain.append(
                (
                    (t.translation.x, t.translation.y, t.translation.z),
                    (t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w),
                )
            )
            link = parent
        for step in reversed(chain):
            pose = _compose(pose, step)
        pad = kinematics.fk(profile, frame.joint_q)
        assert pose[0][0] == pytest.approx(pad.x_m, abs=1e-12)
        assert pose[0][1] == pytest.approx(pad.y_m, abs=1e-12)
        assert pose[0][2] - profile.pad_length_m == pytest.approx(pad.z_m, abs=1e-12)
        yaw = 2 * math.atan2(pose[1][2], pose[1][3])
        assert math.cos(yaw - pad.heading_rad) == pytest.approx(1.0, abs=1e-12)
        box = edges["box"][1]
        assert (box.translation.x, box.translation.y, box.translation.z) == frame.object_poses[0][
            :3
        ]


def test_the_file_carries_the_urdf_and_metadata_a_replay_needs(recorded):
    path, _ = recorded
    with open(path, "rb") as f:
        reader = make_reader(f)
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert attachments["robot.urdf"].decode() == urdf_text(TwinConfig().profile)
    assert TwinConfig.from_dict(json.loads(metadata[S.META_CONFIG]["json"])) == TwinConfig()
    assert json.loads(metadata[S.META_RUN]["params"]) == {"cycles": 1}
    assert metadata["twin.engine"]["dt_ns"] == str(TwinConfig().dt_ns)
    assert metadata[S.META_FINALIZED]["outcome"] == "ok"


def test_twin_run_records_by_default_and_no_record_disables(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "pick_place", "--cycles", "1"]) == 0
    default = tmp_path / "runs" / "pick_place_mtb.mcap"
    assert twin.load(default).finalized
    assert f"recorded {Path('runs') / 'pick_place_mtb.mcap'}" in capsys.readouterr().out
    default.unlink()
    assert main(["run", "pick_place", "--cycles", "1", "--no-record"]) == 0
    assert not default.exists()


def test_a_raising_task_closes_the_file_with_the_error(tmp_path, capsys):
    task = tmp_path / "boom.py"
    task.write_text(
        "def run(twin):\n    twin.suction(True)\n    twin.wait(1.3)\n    raise "
        "RuntimeError('sensor on fire')\n"
    )
    out = tmp_path / "boom.mcap"
    assert main(["run", str(task), "--record", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["twin: error: task raised RuntimeError: sensor on fire"]
    rec = twin.load(out)
    assert rec.finalized and rec.meta[S.META_FINALIZED]["outcome"] == "error"
    assert "sensor on fire" in rec.meta[S.META_FINALIZED]["error"]
    assert [e.kind for e in rec.events][-1] == "task_error"
    assert rec.frames.step[-1] == round(1.3e9 / rec.config.dt_ns)
    # task_start (said, so an event Command), the signal, then task_error (said too)
    assert [c.kind for c in rec.commands] == ["event", "signal", "event"]
    assert rec.commands[-1].args["kind"] == "task_error"


def test_bad_input_does_not_touch_an_existing_recording(tmp_path, capsys):
    out = tmp_path / "keep.mcap"
    out.write_bytes(b"precious")
    assert main(["run", "no_such_task", "--record", str(out)]) == 2
    assert main(["run", "pick_place", "--robot", "no_such_robot", "--record", str(out)]) == 2
    assert main(["run", "pick_place", "--record", str(tmp_path / "wrong.txt")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("twin: error: ") for line in err)
    assert "'no_such_task'" in err[0] and ".mcap" in err[2]
    assert out.read_bytes() == b"precious"


def test_a_recording_path_that_is_a_directory_is_one_clear_error(tmp_path, capsys):
    folder = tmp_path / "taken.mcap"
    folder.mkdir()
    assert main(["run", "pick_place", "--record", str(folder)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot write recording" in err[0] and str(folder) in err[0]


def test_a_damaged_block_is_a_recording_error(recorded):
    path, _ = recorded
    s = scan(path)
    topics = s.by_topic()
    joints = topics[S.JOINTS.topic]
    with pytest.raises(RecordingError, match="different steps"):
        decode_frames(joints[:-1], topics[S.SUCTION.topic], topics[S.POSES.topic], 1, "x.mcap")
    joints[0] = dataclasses.replace(joints[0], data=joints[0].data[:-3])
    with pytest.raises(RecordingError, match="x.mcap"):
        decode_frames(joints, topics[S.SUCTION.topic], topics[S.POSES.topic], 1, "x.mcap")


@given(st.integers(min_value=0, max_value=2**64 - 1))
def test_varints_round_trip(value):
    encoded = wire.varint(value)
    assert wire.read_varint(encoded, 0) == (value, len(encoded))


@given(
    st.lists(st.floats(allow_nan=False), max_size=20),
    st.lists(st.integers(-(2**63), 2**63 - 1), max_size=20),
)
def test_packed_fields_split_back_exactly(doubles, ints):
    buf = wire.packed(4, np.array(doubles, dtype=np.float64), "<f8") + wire.packed(
        1, np.array(ints, np.int64), "<i8"
    )
    fields = wire.split_fields(buf)
    assert wire.array_of(fields, 4, "<f8").tolist() == doubles
    assert wire.array_of(fields, 1, "<i8").tolist() == ints


def test_the_fast_scanner_reads_what_mcaps_own_stream_reader_reads(recorded):
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    from twin.record.mcap import scan as mcap_scan

    path, _ = recorded
    with open(path, "rb") as f:
        # the scanner skips index, statistics and summary-offset records (it reads every chunk
        # anyway)
        theirs = [
            r for r in StreamReader(f).records if type(r) in {Message, *mcap_scan._PARSED.values()}
        ]
    with open(path, "rb") as f:
        ours = [
            r.as_mcap() if isinstance(r, mcap_scan.Message) else r
            for r in mcap_scan.records(f, path.stat().st_size)
        ]
    assert ours == theirs
    assert sum(isinstance(r, Message) for r in ours) > 250


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_every_chunk_compression_loads_the_same(recorded, tmp_path, compression):
    from twin.record.mcap.writer import McapRecorder

    _, collector = recorded
    config = TwinConfig()
    recorder = McapRecorder(
        tmp_path / "c.mcap", config, RUN, urdf=urdf_text(config.profile), compression=compression
    )
    for frame in collector.frames:
        recorder.on_frame(frame)
    recorder.close()
    assert twin.load(tmp_path / "c.mcap").frames.equals(collector.columns())


@pytest.mark.parametrize("rate", [1, 7])
def test_columns_from_a_reused_buffer_make_the_bytes_frames_make(recorded, tmp_path, rate):
    """The recorder process hands on_frames columns that are views of a buffer it overwrites once
    on_frames returns (a shared-memory ring): the writer copies what it keeps, so the file is the
    one on_frame writes. Runs of 1 to 64 rows, so blocks end inside a run and at its edges; at rate
    7 the last frame is kept only from the last run (the buffer is garbage by then)."""
    from twin.record.mcap.writer import McapRecorder
    from twin.record.rows import FrameRows

    _, collector = recorded
    config = TwinConfig()
    rows = FrameRows(len(config.profile.joint_names), len(config.objects))

    def write(path: Path, by_columns: bool) -> bytes:
        recorder = McapRecorder(path, config, RUN, urdf=urdf_text(config.profile), rate=rate)
        frames, buf, at = collector.frames, bytearray(64 * rows.size), 0
        for size in itertools.cycle((1, 7, 64, 33, 3)):
            batch = frames[at : at + size]
            if not batch:
                break
            at += size
            if not by_columns:
                for frame in batch:
                    recorder.on_frame(frame)
                continue
            for k, frame in enumerate(batch):
                rows.pack_into(buf, k * rows.size, frame)
            recorder.on_frames(rows.columns(memoryview(buf)[: len(batch) * rows.size], copy=False))
            buf[:] = b"\xff" * len(buf)
        for event in collector.events:
            recorder.on_event(event)
        recorder.close()
        return path.read_bytes()

    assert write(tmp_path / "columns.mcap", by_columns=True) == write(
        tmp_path / "frames.mcap", by_columns=False
    )


def test_block_messages_are_each_field_packed_frame_after_frame(recorded):
    """The writer encodes its block messages from columns, contiguous or views of packed rows; field
    by field as wire.packed encodes a numpy array (model.fields' wire types) gives the same bytes,
    whatever the frame count."""
    from twin.model import fields as F
    from twin.record.mcap.blocks import BlockEncoder
    from twin.record.rows import FrameRows

    _, collector = recorded
    rows = FrameRows(4, 1)
    names = {b: wire.str_field(S.NAMES, b) for b in F.BLOCKS}
    encoder = BlockEncoder(names)
    at = 0
    for n in (60, 1, 7, 60, 60, 2):
        block = b"".join(rows.pack(f) for f in collector.frames[at : at + n])
        at += n
        records = rows.records(block)
        expected = [
            b"".join(
                [wire.packed(f.number, records[f.name].reshape(n, -1), f.wire) for f in fields[:2]]
                + [names[b]]
                + [
                    wire.packed(f.number, records[f.name].reshape(n, -1), f.wire)
                    for f in fields[2:]
                ]
            )
            for b, fields in ((b, F.block_fields(b)) for b in F.BLOCKS)
        ]
        assert encoder.messages(rows.columns(block, copy=False)) == expected
        assert encoder.messages(rows.columns(block)) == expected


def test_a_user_urdf_travels_with_its_meshes_and_drives_the_transforms(tmp_path, capsys):
    from support.user_robot import write_user_robot  # the STL-mesh SCARA the URDF tests build

    profile = write_user_robot(tmp_path / "robot")
    out = tmp_path / "user.mcap"
    assert (
        main(["run", "pick_place", "--cycles", "1", "--robot", str(profile), "--record", str(out)])
        == 0
    )
    with open(out, "rb") as f:
        reader = make_reader(f)
        attachments = {a.name: a for a in reader.iter_attachments()}
    stls = sorted((tmp_path / "robot" / "meshes").glob("*.stl"))
    assert sorted(n for n in attachments if n.startswith("meshes/")) == [
        f"meshes/{p.name}" for p in stls
    ]
    for p in stls:
        assert attachments[f"meshes/{p.name}"].data == p.read_bytes()
        assert attachments[f"meshes/{p.name}"].media_type == "model/stl"
    assert attachments["robot.urdf"].data == (tmp_path / "robot" / "stl_scara.urdf").read_bytes()
    tf = _decoded(out)[S.TF.topic][-1][1]
    edges = {(t.parent_frame_id, t.child_frame_id) for t in tf.transforms}
    assert {
        ("world", "base"),
        ("base", "arm1"),
        ("arm1", "arm2"),
        ("arm2", "quill"),
        ("quill", "tool0"),
        ("world", "pad_tip"),
        ("world", "box"),
    } == edges
    rec = twin.load(out)
    assert rec.config.profile.name == "stl_scara" and len(rec.frames) > 1000


@pytest.mark.parametrize(("rate", "steps"), [(1, 2400), (7, 2400), (300, 14400)])
def test_flush_steps_are_the_frames_at_which_the_file_grows(tmp_path, rate, steps):
    """The recorder process is woken just after these frames (twin.record.wakes): they are the
    writer's own flushes, block ends and (at a rate of more than a second) long gaps alike."""
    from twin.record.mcap.writer import McapRecorder, flush_steps
    from twin.sim.twin import Twin

    config = TwinConfig()
    recorder = McapRecorder(
        tmp_path / "f.mcap", config, RUN, urdf=urdf_text(config.profile), rate=rate
    )
    flushed, flush = [], recorder._flush
    recorder._flush = lambda t_ns: (flushed.append(t_ns // config.dt_ns), flush(t_ns))
    twin = Twin(config, sinks=[recorder])
    twin.step(steps)
    recorder._flush = flush  # the close's own flush is not a run's
    twin.close()
    assert len(flushed) > 10
    assert flushed == list(itertools.islice(flush_steps(config.dt_ns, rate), len(flushed)))
