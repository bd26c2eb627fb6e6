"""`twin export` on damaged or hostile input: one error line, exit 2, bounded memory and time, no
traceback, nothing written and nothing already there lost.

Each damaged recording is a copy of a real run (the session's camera_run and pick_place_mcap) with
one thing changed: a camera picture (garbage, a 20000x20000 or 9000x9000 PNG, a JPEG, a cut one, a
smaller one), a command's arguments, a joint position (NaN, or too large for float32), a frame's
time. The exports that could cost memory run as a real `twin` process of their own, whose own peak
RSS os.wait4 reports.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from support.cli import TWIN, twin

import twin as twin_pkg
from twin.export import episodes as episodes_module
from twin.pictures import png_bytes, track_rgb
from twin.record.mcap import schemas as S
from twin.verify.replay import save

# a whole `twin export` process (about 45 MB when it refuses; 1.2 GB for the 9000x9000 PNG before)
MAX_RSS_MB = 400
PICTURE_INDEX = 2  # the overhead camera's third picture: step 32 (15 Hz at 240 Hz: every 16 steps)


class Run:
    def __init__(self, code: int, out: str, err: str, rss_mb: float, seconds: float) -> None:
        self.code, self.out, self.err, self.rss_mb, self.seconds = code, out, err, rss_mb, seconds

    def __repr__(self) -> str:
        return (
            f"exit {self.code}, {self.rss_mb:.0f} MB, {self.seconds:.2f} s, stderr "
            f"{self.err[-600:]!r}"
        )


# Peak RSS survives fork and exec: a child of pytest would report at least pytest's size. A small
# launcher process starts the command and reports that child's own peak (as
# tests/record/mcap/test_bad_files.py).
_LAUNCHER = """
import os, sys
pid = os.posix_spawn(sys.argv[2], sys.argv[2:], os.environ)
_, status, usage = os.wait4(pid, 0)
open(sys.argv[1], "w").write(str(usage.ru_maxrss))
sys.exit(os.waitstatus_to_exitcode(status))
"""


def run_measured(argv: list, cwd: Path, timeout_s: float = 60.0) -> Run:
    """`twin ARGV` as a process of its own: exit code, output, its own peak RSS (MB) and wall
    time."""
    t0 = time.monotonic()
    with open(cwd / ".out", "w") as out, open(cwd / ".err", "w") as err:
        proc = subprocess.run(
            [sys.executable, "-c", _LAUNCHER, str(cwd / ".rss"), *TWIN, *map(str, argv)],
            cwd=cwd,
            stdout=out,
            stderr=err,
            stdin=subprocess.DEVNULL,
            timeout=timeout_s,
            check=False,
        )
    rss_mb = int((cwd / ".rss").read_text()) / 1024
    (cwd / ".rss").unlink()
    return Run(
        proc.returncode,
        (cwd / ".out").read_text(errors="replace"),
        (cwd / ".err").read_text(errors="replace"),
        rss_mb,
        time.monotonic() - t0,
    )


def assert_one_line_exit_2(run: Run, *expected: str) -> str:
    assert run.code == 2, run
    assert "Traceback" not in run.err + run.out, run
    lines = run.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("twin: error: "), run
    for text in expected:
        assert text in lines[0], (text, run)
    return lines[0]


def assert_nothing_written(folder: Path, *kept: str) -> None:
    """Only the inputs (and run_measured's .out/.err) are in folder: no dataset, no .partial
    folder."""
    assert sorted(p.name for p in folder.iterdir() if p.name not in (".out", ".err")) == sorted(
        kept
    )


# -- damaged copies --------------------------------------------------------------------------------


def copy_with(src: Path, dst: Path, edit) -> Path:
    """A copy of an MCAP file with every message through edit(topic, data) -> data (mcap's own
    reader and writer, independent of twin's)."""
    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
        messages = [(c.topic, m) for _, c, m in reader.iter_messages(log_time_order=False)]
    with open(dst, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library=S.LIBRARY)
        schema_ids = {
            sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()
        }
        channel_ids = {
            cid: w.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id])
            for cid, c in summary.channels.items()
        }
        for name, record in metadata:
            w.add_metadata(name, record)
        for topic, m in messages:
            w.add_message(
                channel_ids[m.channel_id],
                m.log_time,
                edit(topic, m.data),
                m.publish_time,
                m.sequence,
            )
        w.finish()
    return dst


def with_picture(
    src: Path, dst: Path, payload: bytes, camera: str = "overhead", index: int = PICTURE_INDEX
) -> Path:
    """A copy of src whose camera picture number `index` holds payload instead."""
    seen = [0]

    def edit(topic: str, data: bytes) -> bytes:
        if topic != S.image_channel(camera).topic:
            return data
        seen[0] += 1
        if seen[0] - 1 != index:
            return data
        picture = CompressedImage()
        picture.ParseFromString(data)
        picture.data = payload
        return picture.SerializeToString()

    copy_with(src, dst, edit)
    assert seen[0] > index
    return dst


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def black_png(width: int, height: int, *, pixels: bool = True) -> bytes:
    """An 8-bit RGB PNG of width x height black pixels, compressed row by row (never the whole image
    in memory); pixels=False: the header only (with one row of data), what Pillow's open reads."""
    c = zlib.compressobj(1)
    row = bytes(1 + 3 * width)
    idat = b"".join([c.compress(row) for _ in range(height if pixels else 1)] + [c.flush()])
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")
    )


def jpeg_320x240() -> bytes:
    from PIL import Image

    out = io.BytesIO()
    Image.new("RGB", (320, 240), (90, 120, 30)).save(out, format="JPEG")
    return out.getvalue()


@pytest.fixture(scope="module")
def bad_pictures(camera_run, tmp_path_factory) -> dict[str, tuple[Path, str]]:
    """name -> (copy of the camera run with one bad overhead picture, what the error says about
    it)."""
    folder = tmp_path_factory.mktemp("bad_pictures")
    good = twin_pkg.load(camera_run["mcap"]).cameras["overhead"].data[PICTURE_INDEX]
    cases = {
        "garbage": (b"not a picture " * 20, "is not a PNG picture (280 bytes"),
        "png_20000x20000": (black_png(20000, 20000, pixels=False), "is 20000x20000 px"),
        # 243 MB of pixels in a 1 MB picture
        "png_9000x9000": (black_png(9000, 9000), "is 9000x9000 px"),
        "jpeg": (jpeg_320x240(), "is not a PNG picture"),
        "png_160x120": (png_bytes(np.zeros((120, 160, 3), dtype=np.uint8)), "is 160x120 px"),
        # its header is right: found when decoded
        "png_cut": (good[: len(good) // 2], "does not decode"),
    }
    return {
        name: (with_picture(camera_run["mcap"], folder / f"{name}.mcap", payload), why)
        for name, (payload, why) in cases.items()
    }


# -- 1. camera pictures ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name", ["garbage", "png_20000x20000", "png_9000x9000", "jpeg", "png_160x120", "png_cut"]
)
def test_a_bad_picture_is_one_line_exit_2_in_bounded_memory(bad_pictures, tmp_path, name):
    """Was: UnidentifiedImageError or DecompressionBombError tracebacks (exit 1), and 1229 MB, 3.4 s
    for the 9000x9000 PNG (decoded, then refused for its shape). Now the header is checked against
    the camera's configured size before anything is decoded."""
    path, why = bad_pictures[name]
    run = run_measured(
        ["export", path, "--format", "lerobot", "--fps", "15", "-o", tmp_path / "ds"], tmp_path
    )
    assert_one_line_exit_2(
        run,
        f"recording '{path}': camera 'overhead' picture at step 32 {why}",
        "expected a PNG picture of 320x240 px (the camera's configured format and size)",
    )
    assert run.rss_mb < MAX_RSS_MB, run
    assert run.seconds < 10, run
    assert_nothing_written(tmp_path)
    print(f"export {name}: {run.rss_mb:.0f} MB, {run.seconds:.2f} s")


def test_every_picture_is_checked_before_any_work(bad_pictures, tmp_path, capsys):
    """A bad picture no dataset frame shows (at 1 fps, picture 2 is skipped) is refused all the
    same, before --verify's replay (which would call the file 'not replayable', exit 1)."""
    path, _ = bad_pictures["png_9000x9000"]
    code, out, err = twin(
        capsys,
        "export",
        path,
        "--format",
        "lerobot",
        "--fps",
        "1",
        "--verify",
        "-o",
        tmp_path / "ds",
    )
    assert code == 2 and err.count("\n") == 1 and "is 9000x9000 px" in err and out == "", err
    assert_nothing_written(tmp_path)


def test_track_rgb_checks_the_header_first(bad_pictures):
    """pictures.track_rgb (what diff, replay and check decode with): a RecordingError, never
    Pillow's."""
    from twin.model.errors import RecordingError

    for path, why in bad_pictures.values():
        track = twin_pkg.load(path).cameras["overhead"]
        track.source = str(path)
        with pytest.raises(RecordingError) as err:
            track_rgb(track, PICTURE_INDEX)
        assert f"camera 'overhead' picture at step 32 {why}" in str(err.value) and "\n" not in str(
            err.value
        )
        assert track_rgb(track, PICTURE_INDEX + 1).shape == (240, 320, 3)  # the others decode


# -- 2. --fps --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "fps, expected",
    [
        ("241", "--fps 241 is above the physics rate of recording"),
        ("2000000", "--fps 2000000 is above 10000"),
        ("100000000000", "--fps 100000000000 is above 10000"),
        (str(10**18), f"--fps {10**18} is above 10000"),
        (str(10**20), "is not a whole number 1..2**63-1"),
    ],
)
def test_fps_is_at_most_the_physics_rate(pick_place_mcap, tmp_path, fps, expected):
    """Was: --fps 2000000 on a 5.9 s recording wrote 11.8M frames in 47 s and 2.35 GB; 1e11 and 1e18
    raised numpy's MemoryError and ValueError (tracebacks)."""
    run = run_measured(
        ["export", pick_place_mcap[0], "--format", "lerobot", "--fps", fps, "-o", tmp_path / "ds"],
        tmp_path,
    )
    assert_one_line_exit_2(run, expected)
    assert run.rss_mb < MAX_RSS_MB and run.seconds < 20, run  # was 47 s
    assert_nothing_written(tmp_path)


def test_fps_at_the_physics_rate_is_one_frame_per_step(pick_place_mcap, tmp_path, capsys):
    rec = twin_pkg.load(pick_place_mcap[0])
    assert (
        twin(
            capsys,
            "export",
            pick_place_mcap[0],
            "--format",
            "lerobot",
            "--fps",
            "240",
            "-o",
            tmp_path / "ds",
        )[0]
        == 0
    )
    info = json.loads((tmp_path / "ds/meta/info.json").read_text())
    assert info["total_frames"] == len(rec.frames)  # every recorded step once


def test_frame_times_that_are_not_their_steps_are_refused(pick_place_mcap, tmp_path, capsys):
    """Resampling goes by time: a frame whose time is not step x dt (here 2**61 ns) would ask for
    billions of dataset frames."""
    rec = twin_pkg.load(pick_place_mcap[0])
    rec.frames.t_ns[-1] = 2**61
    save(rec, tmp_path / "late.mcap")
    code, _, err = twin(
        capsys,
        "export",
        tmp_path / "late.mcap",
        "--format",
        "lerobot",
        "--fps",
        "30",
        "-o",
        tmp_path / "ds",
    )
    assert (
        code == 2
        and err.count("\n") == 1
        and f"has time {2**61} ns; expected step x 4166667 ns" in err
    ), err
    assert_nothing_written(tmp_path, "late.mcap")


def test_a_dataset_is_at_most_max_dataset_frames(pick_place_mcap, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(episodes_module, "MAX_DATASET_FRAMES", 100)
    code, _, err = twin(
        capsys,
        "export",
        pick_place_mcap[0],
        "--format",
        "lerobot",
        "--fps",
        "30",
        "-o",
        tmp_path / "ds",
    )
    assert code == 2 and err.count("\n") == 1 and "would hold more than 100 frames" in err, err
    assert_nothing_written(tmp_path)


# -- 3. malformed commands, NaN --------------------------------------------------------------------


def _with_signal_args(src: Path, dst: Path, args: dict) -> Path:
    rec = twin_pkg.load(src)
    i = next(i for i, c in enumerate(rec.commands) if c.kind == "signal")
    rec.commands[i] = dataclasses.replace(rec.commands[i], args=args)
    save(rec, dst)
    return dst


@pytest.mark.parametrize(
    "args, expected",
    [
        (
            {"nom": "pad_switch", "value": 1},
            "signal command at step 0 has arguments {'nom': 'pad_switch', 'value': 1}",
        ),
        ({"name": ["pad_switch"], "value": 1}, "signal command at step 0 is malformed: "),
        ({"name": "pad_switch", "value": "on"}, "signal command at step 0 is malformed: "),
    ],
)
def test_a_malformed_command_is_exit_2_in_every_format_as_in_replay(
    pick_place_mcap, tmp_path, capsys, args, expected
):
    """Was: KeyError: 'name' (a traceback) from csv, parquet and lerobot export; replay said exit
    2."""
    bad = _with_signal_args(pick_place_mcap[0], tmp_path / "bad.mcap", args)
    code, _, err = twin(capsys, "replay", bad)
    assert code == 2 and err.count("\n") == 1 and expected in err, err
    for fmt, out in (("csv", "t.csv"), ("parquet", "t.parquet"), ("lerobot", "ds")):
        fps = ["--fps", "10"] if fmt == "lerobot" else []
        code, _, err = twin(capsys, "export", bad, "--format", fmt, *fps, "-o", tmp_path / out)
        assert code == 2 and err.startswith(f"twin: error: recording '{bad}': "), (fmt, err)
        assert err.count("\n") == 1 and expected in err, (fmt, err)
    assert_nothing_written(tmp_path, "bad.mcap")


@pytest.mark.parametrize("value, shown", [(math.nan, "is nan"), (1e300, "is 1e+300")])
def test_a_nan_joint_position_is_refused_for_a_dataset(
    pick_place_mcap, tmp_path, capsys, value, shown
):
    """Was: ValueError 'Out of range float values are not JSON compliant' (a traceback) writing
    stats.json. LeRobot reads stats.json with Python's json (NaN would load), but normalizes by its
    mean and std, which one NaN makes NaN: refused, naming the value. The csv table keeps the
    recorded value."""
    rec = twin_pkg.load(pick_place_mcap[0])
    rec.frames.joint_q[100, 0] = value
    save(rec, tmp_path / "nan.mcap")
    code, _, err = twin(
        capsys,
        "export",
        tmp_path / "nan.mcap",
        "--format",
        "lerobot",
        "--fps",
        "240",
        "-o",
        tmp_path / "ds",
    )
    assert code == 2 and err.count("\n") == 1, err
    assert (
        f"joint.shoulder.position_rad {shown} at step 100; expected finite float32 values" in err
    ), err
    assert_nothing_written(tmp_path, "nan.mcap")
    assert (
        twin(capsys, "export", tmp_path / "nan.mcap", "--format", "csv", "-o", tmp_path / "t.csv")[
            0
        ]
        == 0
    )
    # not at a dataset frame (10 fps takes every 24th step): exported
    assert (
        twin(
            capsys,
            "export",
            tmp_path / "nan.mcap",
            "--format",
            "lerobot",
            "--fps",
            "10",
            "-o",
            tmp_path / "ds",
        )[0]
        == 0
    )


# -- 4. what killed exports leave ------------------------------------------------------------------


def test_a_killed_exports_partial_folder_is_removed_by_the_next(camera_run, tmp_path, capsys):
    """A killed export leaves .ds.partial-PID; the next export of ds removes it (its process is
    gone), keeps a running export's, and removes one whose id a later process reuses."""
    out = tmp_path / "ds"
    proc = subprocess.Popen(
        [
            *TWIN,
            "export",
            str(camera_run["mcap"]),
            "--format",
            "lerobot",
            "--fps",
            "30",
            "-o",
            str(out),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    partial = tmp_path / f".ds.partial-{proc.pid}"
    deadline = time.monotonic() + 30
    while not partial.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.001)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert partial.is_dir() and not out.exists()  # killed while writing

    running = [subprocess.Popen(["sleep", "60"]) for _ in range(2)]
    try:
        # a running export's, as far as we can tell
        live = tmp_path / f".ds.partial-{running[0].pid}"
        (live / "meta").mkdir(parents=True)
        # last changed an hour before its process started:
        reused = tmp_path / f".ds.partial-{running[1].pid}"
        # a dead export's folder, whose id a later process reuses
        (reused / "data").mkdir(parents=True)
        os.utime(reused, (time.time() - 3600,) * 2)
        # another dataset's: not this export's to remove
        other = tmp_path / f".other.partial-{proc.pid}"
        other.mkdir()
        assert (
            twin(
                capsys,
                "export",
                camera_run["mcap"],
                "--format",
                "lerobot",
                "--fps",
                "10",
                "-o",
                out,
            )[0]
            == 0
        )
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["ds", live.name, other.name])
    finally:
        for sleeper in running:
            sleeper.kill()
            sleeper.wait()


def test_an_old_dataset_left_by_a_killed_overwrite_is_removed_once_ds_is_whole(
    pick_place_mcap, tmp_path, capsys
):
    """--overwrite renames the old dataset to .ds.old-PID-*; a kill before it is removed leaves
    it."""
    out = tmp_path / "ds"
    assert (
        twin(capsys, "export", pick_place_mcap[0], "--format", "lerobot", "--fps", "10", "-o", out)[
            0
        ]
        == 0
    )
    dead = subprocess.Popen(["true"])
    dead.wait()
    old = tmp_path / f".ds.old-{dead.pid}-abc123"
    (old / "ds" / "meta").mkdir(parents=True)
    assert (
        twin(
            capsys,
            "export",
            pick_place_mcap[0],
            "--format",
            "lerobot",
            "--fps",
            "20",
            "--overwrite",
            "-o",
            out,
        )[0]
        == 0
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
