"""Damaged files through every reader: one error line, exit 2, no traceback, bounded memory and
time.

A corpus of damaged variants of a real recording made here (truncations, bit flips, a zstd bomb,
trailing and overwriting zeros, corrupted metadata and messages, a FIFO, a folder, an empty and a
foreign file) goes through `twin info/recover/diff/replay/check/view --rrd`, each in a process of
its own: the CLI's own main() in a child forked from this (already imported) interpreter, so ~180
runs take seconds; the worst cases also run through the installed `twin` executable. os.wait4 gives
each child's peak RSS. Variants are written with mcap's own Writer, independently of twin's writer.
"""

from __future__ import annotations

import io
import json
import math
import os
import random
import resource
import signal
import struct
import sys
import time
import traceback
import zlib
from pathlib import Path

import pytest
import zstandard
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

import twin
import twin.record.mcap.info
import twin.record.mcap.recover
import twin.record.rerun.viewer  # the CLI imports these lazily: imported here, forks have them
import twin.verify.check
from twin.cli import main
from twin.model.errors import RecordingError
from twin.record.mcap import schemas as S

pytestmark = pytest.mark.slow  # seconds each: `-m "not slow"` leaves them out

# a reader in a forked child: its peak above pytest at the fork; a fresh twin: its whole peak
MAX_RSS_MB = 400
TIMEOUT_S = 30.0  # a hang guard; every run here takes well under a second or two
# address-space cap of each child: a regression fails instead of swamping the machine
AS_LIMIT = 6 << 30
KEYS = "d*3 k g i wait"


# -- running a reader in its own process -----------------------------------------------------------


class Run:
    def __init__(self, code: int, out: str, err: str, rss_mb: float, seconds: float) -> None:
        self.code, self.out, self.err, self.rss_mb, self.seconds = code, out, err, rss_mb, seconds

    def __repr__(self) -> str:
        return (
            f"exit {self.code}, {self.rss_mb:.0f} MB, {self.seconds:.2f} s, stderr "
            f"{self.err[-600:]!r}"
        )


def _wait(pid: int, timeout_s: float) -> tuple[int, resource.struct_rusage]:
    deadline = time.monotonic() + timeout_s
    while True:
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status), usage
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            _, status, usage = os.wait4(pid, 0)
            return -999, usage
        time.sleep(0.005)


def run_forked(argv: list[str], cwd: Path, timeout_s: float = TIMEOUT_S) -> Run:
    """`twin ARGV` as twin.cli.main in a forked child with its own stdout/stderr; its exit code,
    output, peak RSS (MB) above what it started with (pytest's own, whose size depends on the tests
    run before) and wall time."""
    out_path, err_path = cwd / ".out", cwd / ".err"
    base_mb = _rss_mb()
    t0 = time.monotonic()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        code = 99
        try:
            resource.setrlimit(resource.RLIMIT_AS, (AS_LIMIT, AS_LIMIT))
            for fd, path in ((1, out_path), (2, err_path)):
                target = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
                os.dup2(target, fd)
            sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), line_buffering=True)
            sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), line_buffering=True)
            os.chdir(cwd)
            code = main(argv)
        except BaseException:  # noqa: BLE001 - reported as a traceback, which the tests refuse
            traceback.print_exc()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code if isinstance(code, int) else 98)
    code, usage = _wait(pid, timeout_s)
    return Run(
        code,
        out_path.read_text(errors="replace"),
        err_path.read_text(errors="replace"),
        usage.ru_maxrss / 1024 - base_mb,
        time.monotonic() - t0,
    )


def _rss_mb() -> float:
    """This process's resident set now (MB)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / (1 << 20)


# Peak RSS survives exec, so a child forked from pytest would report pytest's size: a small launcher
# process starts the executable and reports that child's own peak.
_LAUNCHER = """
import os, resource, sys
resource.setrlimit(resource.RLIMIT_AS, (int(sys.argv[2]), int(sys.argv[2])))
pid = os.posix_spawn(sys.argv[3], sys.argv[3:], os.environ)
_, status, usage = os.wait4(pid, 0)
open(sys.argv[1], "w").write(str(usage.ru_maxrss))
sys.exit(os.waitstatus_to_exitcode(status))
"""


def run_binary(argv: list[str], cwd: Path, timeout_s: float = TIMEOUT_S) -> Run:
    """The installed `twin` executable (a fresh interpreter), measured the same way."""
    import subprocess

    exe = Path(sys.executable).parent / "twin"
    assert exe.is_file(), exe
    t0 = time.monotonic()
    with open(cwd / ".out", "w") as out, open(cwd / ".err", "w") as err:
        proc = subprocess.run(
            [sys.executable, "-c", _LAUNCHER, str(cwd / ".rss"), str(AS_LIMIT), str(exe), *argv],
            cwd=cwd,
            stdout=out,
            stderr=err,
            stdin=subprocess.DEVNULL,
            timeout=timeout_s,
            check=False,
        )
    return Run(
        proc.returncode,
        (cwd / ".out").read_text(errors="replace"),
        (cwd / ".err").read_text(errors="replace"),
        int((cwd / ".rss").read_text()) / 1024,
        time.monotonic() - t0,
    )


def reader_argv(reader: str, path: Path, good: Path, out_dir: Path) -> list[str]:
    return {
        "info": ["info", str(path)],
        "recover": ["recover", str(path), "-o", str(out_dir / "recovered.mcap")],
        "diff": ["diff", str(path), str(good)],
        "replay": ["replay", str(path)],
        "check": ["check", str(path)],
        "view": ["view", str(path), "--rrd", str(out_dir / "view.rrd")],
    }[reader]


READERS = ("info", "recover", "diff", "replay", "check", "view")


# -- the corpus ------------------------------------------------------------------------------------


def _read(path: Path) -> dict:
    """Everything in an MCAP file, through mcap's own reader."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = [
            (channel.topic, message)
            for _, channel, message in reader.iter_messages(log_time_order=False)
        ]
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return {
        "schemas": summary.schemas,
        "channels": summary.channels,
        "messages": messages,
        "metadata": metadata,
    }


def rewrite(
    content: dict, out: Path, *, metadata: dict | None = None, edit=None, raw_chunk: bytes = b""
) -> Path:
    """A copy of a recording with its metadata replaced and messages edited (edit(topic, data) ->
    data) by mcap's Writer; raw_chunk is written as is before the messages."""
    with open(out, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library=S.LIBRARY)
        schema_ids = {
            sid: w.register_schema(s.name, s.encoding, s.data)
            for sid, s in content["schemas"].items()
        }
        channel_ids = {
            cid: w.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id])
            for cid, c in content["channels"].items()
        }
        for name, record in (metadata if metadata is not None else content["metadata"]).items():
            w.add_metadata(name, record)
        f.write(raw_chunk)
        for topic, m in content["messages"]:
            data = edit(topic, m.data) if edit else m.data
            w.add_message(channel_ids[m.channel_id], m.log_time, data, m.publish_time, m.sequence)
        w.finish()
    return out


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def chunk_record(
    records: bytes | None, *, compression: str, declared: int, compressed: bytes | None = None
) -> bytes:
    """An MCAP chunk record holding `records` (or an already compressed stream) with a declared
    size."""
    data = compressed if compressed is not None else records
    crc = 0 if compressed is not None else zlib.crc32(records)
    name = compression.encode()
    body = (
        struct.pack("<QQQI", 0, 0, declared, crc)
        + struct.pack("<I", len(name))
        + name
        + struct.pack("<Q", len(data))
        + data
    )
    return _record(0x06, body)


def zstd_of_zeros(n_bytes: int, prefix: bytes = b"") -> bytes:
    """A zstd stream of prefix + n_bytes zeros, compressed piecewise (never n_bytes in memory)."""
    c = zstandard.ZstdCompressor(level=3).compressobj()
    parts = [c.compress(prefix)]
    block = bytes(1 << 20)
    left = n_bytes
    while left:
        parts.append(c.compress(block[: min(left, len(block))]))
        left -= min(left, len(block))
    return b"".join(parts) + c.flush()


def _message_record(channel_id: int, data_len: int, seq: int = 0) -> bytes:
    return struct.pack("<BQHIQQ", 0x05, 22 + data_len, channel_id, seq, seq, seq)


def config_leaves(value, path: tuple = ()):
    """Every leaf of a JSON value, as a path of keys and indexes."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from config_leaves(v, (*path, k))
    elif (
        isinstance(value, list)
        and value
        and not all(isinstance(v, (int, float, str)) for v in value)
    ):
        for i, v in enumerate(value):
            yield from config_leaves(v, (*path, i))
    else:
        yield path


def with_leaf(value, path: tuple, new):
    value = json.loads(json.dumps(value))
    target = value
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = new
    return value


def wrong_value(old):
    """A value of the wrong type for a leaf (a string for a number, a number for a string, ...)."""
    if isinstance(old, bool):
        return 2
    if isinstance(old, (int, float)):
        return "x"
    if isinstance(old, str):
        return 5
    if isinstance(old, list):
        return [1] if old and isinstance(old[0], str) else ["x"] * max(1, len(old))
    return [1]


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    """A short real teleop recording (3.5 s simulated, key commands): re-run cheaply by replay and
    check."""
    folder = tmp_path_factory.mktemp("good")
    path = folder / "good.mcap"
    run = run_forked(["teleop", "--keys", KEYS, "--record", str(path)], folder)
    assert run.code == 0 and path.is_file(), run
    return path


@pytest.fixture(scope="module")
def corpus(good, tmp_path_factory) -> dict[str, tuple[Path, str]]:
    """name -> (path, kind). kind "bad": every reader exits 2; "damaged": recover may restore it
    (0); "messages": a part that info reads too is bad or foreign (it prints the rest, then exits
    2); "any": a bit flip may hit bytes nobody reads (0), or a value replay then sees differ (1)."""
    d = tmp_path_factory.mktemp("corpus")
    raw = good.read_bytes()
    content = _read(good)
    config = json.loads(content["metadata"][S.META_CONFIG]["json"])
    out: dict[str, tuple[Path, str]] = {}

    def add(name: str, data: bytes, kind: str) -> None:
        (d / f"{name}.mcap").write_bytes(data)
        out[name] = (d / f"{name}.mcap", kind)

    add("empty", b"", "bad")
    add("text", b"this is not a recording\n" * 10, "bad")
    add("png", b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4, "bad")
    add("magic_only", raw[:10], "bad")
    (d / "folder.mcap").mkdir()
    out["folder"] = (d / "folder.mcap", "bad")
    os.mkfifo(d / "fifo.mcap")
    out["fifo"] = (d / "fifo.mcap", "bad")
    for frac in (0.25, 0.5, 0.75):
        add(f"cut_{int(frac * 100)}", raw[: int(len(raw) * frac)], "damaged")
    add("cut_last_byte", raw[:-1], "damaged")
    rng = random.Random(7)
    for i in range(4):
        flipped = bytearray(raw)
        pos = rng.randrange(8, len(raw) - 8)
        flipped[pos] ^= 1 << rng.randrange(8)
        add(f"bitflip_{i}_at_{pos}", bytes(flipped), "any")
    # trailing zeros after a complete file, and zeros where its end should be (sparse: instant to
    # make)
    for name, keep in (
        ("trailing_zeros_200MB", len(raw)),
        ("zeros_over_the_end_200MB", int(len(raw) * 0.6)),
    ):
        path = d / f"{name}.mcap"
        with open(path, "wb") as f:
            f.write(raw[:keep])
            f.truncate(keep + 200 * 1024 * 1024)
        out[name] = (path, "damaged")
    # a 33 KB file holding one 1 GiB zstd-compressed zero message on /twin/joints (declared, or lied
    # about)
    gib = 1 << 30
    joints_id = next(cid for cid, c in content["channels"].items() if c.topic == S.JOINTS.topic)
    bomb = zstd_of_zeros(gib, _message_record(joints_id, gib))
    no_messages = {**content, "messages": []}
    rewrite(
        no_messages,
        d / "zstd_bomb_1GiB.mcap",
        raw_chunk=chunk_record(None, compression="zstd", declared=gib + 31, compressed=bomb),
    )
    rewrite(
        no_messages,
        d / "zstd_bomb_declared_small.mcap",
        raw_chunk=chunk_record(None, compression="zstd", declared=4096, compressed=bomb),
    )
    # 28 MiB of one-byte messages in a chunk (under the chunk cap): ~900k records from a few KB
    tiny = b"".join(_message_record(joints_id, 1, i) + b"\x00" for i in range(4096))
    rewrite(
        no_messages,
        d / "tiny_messages_flood.mcap",
        raw_chunk=chunk_record(
            None,
            compression="zstd",
            declared=len(tiny) * 224,
            compressed=zstandard.ZstdCompressor().compress(tiny * 224),
        ),
    )
    for name in ("zstd_bomb_1GiB", "zstd_bomb_declared_small", "tiny_messages_flood"):
        out[name] = (d / f"{name}.mcap", "damaged")
    # corrupted metadata values (the cases the fault campaign hit, and whole records)
    meta = content["metadata"]

    def config_case(name: str, text: str) -> None:
        rewrite(content, d / f"{name}.mcap", metadata={**meta, S.META_CONFIG: {"json": text}})
        out[name] = (d / f"{name}.mcap", "bad")

    config_case("config_dt_ns_infinity", json.dumps(with_leaf(config, ("dt_ns",), math.inf)))
    config_case("config_objects_1", json.dumps(with_leaf(config, ("objects",), [1])))
    config_case("config_link1_x", json.dumps(with_leaf(config, ("profile", "link1_m"), "x")))
    config_case(
        "config_mass_nan", json.dumps(with_leaf(config, ("objects", 0, "mass_kg"), math.nan))
    )
    config_case(
        "config_gravity_huge",
        json.dumps(with_leaf(config, ("engine", "gravity_m_s2"), [0, 0, 1e300])),
    )
    config_case("config_not_json", "{not json")
    config_case("config_deep", "[" * 100_000 + "]" * 100_000)
    config_case("config_profile_empty", json.dumps(with_leaf(config, ("profile",), {})))
    config_case(
        "config_keymap_bad",
        json.dumps(with_leaf(config, ("keymap",), {"a": [["jog", "elbow", math.nan]]})),
    )
    rewrite(
        content,
        d / "run_params_nan.mcap",
        metadata={**meta, S.META_RUN: {**meta[S.META_RUN], "params": "NaN"}},
    )
    rewrite(
        content,
        d / "run_source_bad.mcap",
        metadata={**meta, S.META_RUN: {**meta[S.META_RUN], "source": "x"}},
    )
    out["run_params_nan"] = (d / "run_params_nan.mcap", "bad")
    out["run_source_bad"] = (d / "run_source_bad.mcap", "bad")

    # corrupted messages
    def message_case(name: str, topic: str, new: bytes) -> None:
        rewrite(content, d / f"{name}.mcap", edit=lambda t, data: new if t == topic else data)
        out[name] = (d / f"{name}.mcap", "messages")

    message_case("robot_description_empty", S.ROBOT_DESCRIPTION.topic, b"{}")
    message_case(
        "command_step_1e30",
        S.COMMANDS.topic,
        b'{"args":{"key":"d"},"kind":"key","step":1' + b"0" * 30 + b"}",
    )
    message_case(
        "command_nan",
        S.COMMANDS.topic,
        b'{"args":{"joint":"MTB_axis1","q":NaN},"kind":"joint_target","step":0}',
    )
    message_case("command_not_object", S.COMMANDS.topic, b"[1]")
    rewrite(
        content,
        d / "block_zero_bytes.mcap",
        edit=lambda t, data: bytes(len(data)) if t == S.JOINTS.topic else data,
    )
    out["block_zero_bytes"] = (d / "block_zero_bytes.mcap", "bad")
    # a valid MCAP file that twin did not write
    with open(d / "foreign.mcap", "wb") as f:
        w = Writer(f)
        w.start(profile="x", library="someone else")
        w.add_message(
            w.register_channel("/x", "json", w.register_schema("s", "jsonschema", b"{}")),
            0,
            b"{}",
            0,
        )
        w.finish()
    out["foreign_mcap"] = (d / "foreign.mcap", "messages")
    return out


def _expected_codes(kind: str, reader: str) -> set[int]:
    if kind == "any":
        return {0, 1, 2}
    if kind == "damaged" and reader == "recover":
        return {0, 2}
    return {2}  # "messages" too: info prints what it read of such a file, then exits 2


def _assert_clean(run: Run, expected: set[int], what: str) -> None:
    assert run.code in expected, f"{what}: {run!r}"
    assert "Traceback" not in run.err + run.out, f"{what}: {run!r}"
    assert run.rss_mb < MAX_RSS_MB, f"{what}: {run!r}"
    if run.code == 2:
        lines = run.err.splitlines()
        assert len(lines) == 1, f"{what}: {run!r}"
        # check reports each golden in its table, progress on stderr
        if not lines[0].startswith("twin: error: "):
            assert what.startswith("check ") and ": error" in lines[0] and "error" in run.out, (
                f"{what}: {run!r}"
            )


@pytest.mark.parametrize("reader", READERS)
def test_every_reader_gives_one_line_and_exit_2_on_the_corpus(corpus, good, tmp_path, reader):
    worst = Run(0, "", "", 0.0, 0.0)
    for name, (path, kind) in corpus.items():
        run = run_forked(reader_argv(reader, path, good, tmp_path), tmp_path)
        _assert_clean(run, _expected_codes(kind, reader), f"{reader} {name}")
        worst = max(worst, run, key=lambda r: r.rss_mb)
        print(f"{reader} {name}: {run.code} {run.rss_mb:.0f} MB {run.seconds:.2f} s")
    print(f"{reader}: worst peak growth {worst.rss_mb:.0f} MB")


def test_the_worst_cases_through_the_twin_executable(corpus, good, tmp_path):
    """A fresh `twin` process each: peak memory and time of the bomb, the zeros, a FIFO, a bad
    config."""
    for name in (
        "zstd_bomb_1GiB",
        "zstd_bomb_declared_small",
        "tiny_messages_flood",
        "trailing_zeros_200MB",
        "zeros_over_the_end_200MB",
        "fifo",
        "config_dt_ns_infinity",
    ):
        path, kind = corpus[name]
        for reader in ("info", "replay"):
            run = run_binary(reader_argv(reader, path, good, tmp_path), tmp_path)
            _assert_clean(run, _expected_codes(kind, reader), f"{reader} {name} (executable)")
            size = path.stat().st_size if path.is_file() else 0
            print(
                f"twin {reader} {name} ({size:,} bytes): {run.rss_mb:.0f} MB peak, "
                f"{run.seconds:.2f} s"
            )


def test_load_names_every_corrupted_config_field(good, tmp_path):
    """twin.load on a config with each field in turn given a wrong type, NaN, or infinity: a
    RecordingError naming that field (the schema checks every field a file holds)."""
    content = _read(good)
    config = json.loads(content["metadata"][S.META_CONFIG]["json"])
    leaves = list(config_leaves(config))
    assert len(leaves) > 40
    cases = 0
    for path in leaves:
        if path == ("keymap",):
            continue  # an empty key map: checked by test_corrupted_config_in_keymap
        old = _get(config, path)
        bads = [wrong_value(old)]
        if isinstance(old, (int, float)) and not isinstance(old, bool):
            bads += [math.nan, math.inf, -math.inf, 10**30]
        if isinstance(old, list) and old and isinstance(old[0], (int, float)):
            bads += [[math.nan] * len(old), old[:-1]]
        for bad in bads:
            text = json.dumps(with_leaf(config, path, bad))
            target = rewrite(
                content,
                tmp_path / "c.mcap",
                metadata={**content["metadata"], S.META_CONFIG: {"json": text}},
            )
            with pytest.raises(RecordingError) as err:
                twin.load(target)
            message = str(err.value)
            assert "\n" not in message and str(path[-1]) in message, (path, bad, message)
            cases += 1
    assert cases > 150


def _get(value, path):
    for key in path:
        value = value[key]
    return value


def test_nan_in_event_data_is_written_as_null(tmp_path):
    """The JSON channels never hold NaN or Infinity: event data from a diverged simulation is
    null."""
    from twin.model.config import TwinConfig
    from twin.record import open_recorders
    from twin.sim.twin import Twin

    path = tmp_path / "nan.mcap"
    with open_recorders(
        TwinConfig(), {"source": "task", "task": "x", "params": {}}, mcap_path=path
    ) as sinks:
        t = Twin(TwinConfig(), sinks=sinks)
        t.event("probe", error_m=math.nan, pose=[1.0, math.inf], ok=1.5)
        t.step(1)
        t.close()
    content = _read(path)
    (event,) = [
        json.loads(m.data, parse_constant=pytest.fail)
        for topic, m in content["messages"]
        if topic == S.EVENTS.topic and b"probe" in m.data
    ]
    assert event["data"] == {"error_m": None, "ok": 1.5, "pose": [1.0, None]}
    assert twin.load(path).events[-1].data == {"error_m": None, "ok": 1.5, "pose": [1.0, None]}


# pictures and export
# -- camera pictures through the readers that decode them (diff, replay, check) --------------------
# A short camera run (teleop, 1 s simulated, overhead and wrist cameras, 320x240 at 15 Hz: 16
# pictures each) with its third overhead picture (step 32) replaced. Was: an UnidentifiedImageError
# or DecompressionBombError traceback (exit 1) from each, and 1.14-1.17 GB for the 9000x9000 PNG
# (decoded in full: 243 MB of pixels in a 430 KB file). `twin export` on these and more:
# tests/export/test_export_bad_inputs.py. Short, not conftest's pick_place camera_run: replay, check
# and diff each re-run the recording with its cameras (diff and check twice, for the noise floor)
# before they judge the pictures, 3-4 s of CPU a test on pick_place, and the picture at step 32 is
# reached the same way in either.


def _black_png(width: int, height: int, *, pixels: bool = True) -> bytes:
    """An 8-bit RGB PNG of black pixels, compressed row by row; pixels=False: the header and one row
    only."""
    c = zlib.compressobj(1)
    row = bytes(1 + 3 * width)
    idat = b"".join([c.compress(row) for _ in range(height if pixels else 1)] + [c.flush()])

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


@pytest.fixture(scope="module")
def short_camera_run(tmp_path_factory) -> Path:
    """A real teleop recording with both cameras, 1 s simulated (two key presses)."""
    folder = tmp_path_factory.mktemp("short_camera_run")
    path = folder / "camera.mcap"
    argv = ["teleop", "--keys", "d*2", "--camera", "overhead", "--camera", "wrist"]
    run = run_forked([*argv, "--record", str(path)], folder)
    assert run.code == 0 and path.is_file(), run
    return path


@pytest.fixture(scope="module")
def bad_picture_runs(short_camera_run, tmp_path_factory) -> dict[str, Path]:
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    folder = tmp_path_factory.mktemp("bad_pictures")
    content = _read(short_camera_run)
    topic = S.image_channel("overhead").topic

    def third_picture(payload: bytes):
        seen = [0]

        def edit(t: str, data: bytes) -> bytes:
            if t != topic:
                return data
            seen[0] += 1
            if seen[0] != 3:
                return data
            picture = CompressedImage()
            picture.ParseFromString(data)
            picture.data = payload
            return picture.SerializeToString()

        return edit

    payloads = {
        "garbage": b"not a picture " * 20,
        "png_20000x20000": _black_png(20000, 20000, pixels=False),
        "png_9000x9000": _black_png(9000, 9000),
    }
    return {
        name: rewrite(content, folder / f"{name}.mcap", edit=third_picture(payload))
        for name, payload in payloads.items()
    }


@pytest.mark.parametrize("name", ["garbage", "png_20000x20000", "png_9000x9000"])
@pytest.mark.parametrize("reader", ["diff", "replay", "check"])
def test_a_bad_camera_picture_is_one_line_exit_2(
    bad_picture_runs, short_camera_run, tmp_path, reader, name
):
    path = bad_picture_runs[name]
    argv = {
        "diff": ["diff", str(path), str(short_camera_run)],
        "replay": ["replay", str(path)],
        "check": ["check", str(path)],
    }[reader]
    run = run_forked(argv, tmp_path)
    _assert_clean(run, {2}, f"{reader} {name}")
    said = run.err + run.out
    assert (
        "camera 'overhead' picture at step 32 " in said
        and "expected a PNG picture of 320x240 px" in said
    ), run
    print(f"{reader} {name}: {run.code} {run.rss_mb:.0f} MB {run.seconds:.2f} s")


# readers and metadata
# -- floods of empty messages: memory must not grow with the number of messages --------------------
# The issue: a 44 MB file of empty messages cost `twin info` 2.34 GB and 14 s, `twin check` 1.22 GB.
# Measured here on the files below before the fix (each `twin` process's whole peak, as run_binary
# measures it):
# empty_44M_tf (45 MB, 44 million empty /tf messages): info 5.6 GB, 143 s; check 5.6 GB, 141 s; both
# exit 0
# empty_44M_foreign (the same on a channel twin does not know): info 5.6 GB, 232 s; check 5.6 GB,
# 214 s
#   empty_44M_events (on /twin/events): info 5.6 GB, over 300 s (stopped)
# empty_3M_tf_timed (50 MB, 3 million empty /tf messages at distinct times): info 723 MB, 10.5 s;
# check
#   761 MB, 9.9 s; both exit 0
# After: 80-125 MB and 1-2 s each, exit 2: the chunks hold more records than one per 8 bytes of the
# file (twin's writer spends 16 bytes of message index per message); empty_3M_tf_timed, inside that
# bound, is read (exit 0) in 117 and 154 MB, 1.2 and 1.5 s. The rule checked: the peak RSS of the
# whole `twin` process under MAX_RSS_MB (400 MB) and the time under 10 s, whatever the number of
# messages.

FLOOD_TIMEOUT_S = 10.0
_FLOOD_RECORD = [
    ("op", "u1"),
    ("length", "<u8"),
    ("channel", "<u2"),
    ("sequence", "<u4"),
    ("log_time", "<u8"),
    ("publish_time", "<u8"),
]  # a message record with no data: 31 bytes


def _channel_record(channel_id: int, schema_id: int, topic: str, encoding: str) -> bytes:
    def text(s: str) -> bytes:
        return struct.pack("<I", len(s.encode())) + s.encode()

    return _record(
        0x04,
        struct.pack("<HH", channel_id, schema_id)
        + text(topic)
        + text(encoding)
        + struct.pack("<I", 0),
    )


def _flood_chunk(channel: bytes, channel_id: int, n: int, *, timed: bool, first: int = 0) -> bytes:
    """A zstd chunk: a channel record, then n empty messages on it (sequence first..; log and
    publish time 0, or, timed, one step apart and scattered: then the chunk compresses about 2.5
    times only)."""
    import numpy as np

    records = np.zeros(n, dtype=_FLOOD_RECORD)
    records["op"], records["length"], records["channel"] = 0x05, 22, channel_id
    records["sequence"] = np.arange(first, first + n)
    if timed:
        records["log_time"] = np.arange(first, first + n) * 4_166_667
        records["publish_time"] = np.random.default_rng(first).integers(0, 2**62, n)
    raw = channel + records.tobytes()
    return chunk_record(
        None,
        compression="zstd",
        declared=len(raw),
        compressed=zstandard.ZstdCompressor(level=1).compress(raw),
    )


@pytest.fixture(scope="module")
def floods(good, tmp_path_factory) -> dict[str, tuple[Path, int]]:
    """name -> (path, the exit code every reader gives): the `good` recording with a flood of empty
    messages written before its own (rewrite's Writer numbers schemas and channels 1, 2, ... in
    order)."""
    folder = tmp_path_factory.mktemp("floods")
    content = _read(good)
    ids = {
        c.topic: (i, list(content["schemas"]).index(c.schema_id) + 1)
        for i, c in enumerate(content["channels"].values(), 1)
    }
    out = {}
    for name, topic, encoding, chunks, per_chunk, timed, code in (
        ("empty_44M_tf", S.TF.topic, "protobuf", 44, 1 << 20, False, 2),
        ("empty_44M_events", S.EVENTS.topic, "json", 44, 1 << 20, False, 2),
        ("empty_44M_foreign", "/x", "json", 44, 1 << 20, False, 2),
        ("empty_3M_tf_timed", S.TF.topic, "protobuf", 3, 1 << 20, True, 0),
    ):
        channel_id, schema_id = ids.get(topic, (len(ids) + 1, 0))  # /x: a new channel, no schema
        channel = _channel_record(channel_id, schema_id, topic, encoding)
        flood = (
            b"".join(
                _flood_chunk(channel, channel_id, per_chunk, timed=True, first=i * per_chunk)
                for i in range(chunks)
            )
            if timed
            # the same chunk again
            else _flood_chunk(channel, channel_id, per_chunk, timed=False) * chunks
        )
        path = rewrite(content, folder / f"{name}.mcap", raw_chunk=flood)
        out[name] = (path, code)
    return out


@pytest.mark.parametrize(
    "name", ["empty_44M_tf", "empty_44M_events", "empty_44M_foreign", "empty_3M_tf_timed"]
)
@pytest.mark.parametrize("reader", ["info", "check"])
def test_a_flood_of_empty_messages_costs_bounded_memory_and_time(
    floods, good, tmp_path, reader, name
):
    path, code = floods[name]
    run = run_binary(reader_argv(reader, path, good, tmp_path), tmp_path, timeout_s=60)
    _assert_clean(run, {code}, f"{reader} {name} (executable)")
    assert run.seconds < FLOOD_TIMEOUT_S, run
    print(
        f"twin {reader} {name} ({path.stat().st_size:,} bytes): exit {run.code}, "
        f"{run.rss_mb:.0f} MB peak, "
        f"{run.seconds:.2f} s"
    )


def test_a_message_on_a_channel_never_registered_is_refused_at_once(good, tmp_path):
    """MCAP registers a channel before its messages: 44 million messages on channel 999 stop at the
    first."""
    content = _read(good)
    chunk = _flood_chunk(b"", 999, 1 << 20, timed=False)
    path = rewrite(content, tmp_path / "unregistered.mcap", raw_chunk=chunk * 44)
    for reader in ("info", "check"):
        run = run_forked(reader_argv(reader, path, good, tmp_path), tmp_path)
        _assert_clean(run, {2}, f"{reader} unregistered")
        assert (
            "a message on channel 999, which no channel record before it registers"
            in run.err + run.out
        ), run
        assert run.seconds < FLOOD_TIMEOUT_S, run
