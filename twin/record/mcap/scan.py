"""One fast pass over an MCAP file's records, in file order, stopping cleanly at a damaged end.

Record bodies are parsed by mcap's own record classes, except the two that dominate a recording:
Message records inside chunks (a fixed 22-byte header, then the payload) are sliced directly, and
MessageIndex records are skipped (the pass reads every chunk anyway). Chunk CRCs are checked.

A damaged or hostile file must cost bounded memory and time, so sizes are capped by what twin's own
writer produces: a chunk decompresses to at most MAX_CHUNK_BYTES (the writer closes chunks at 8 MiB
and every flush), a message holds at most MAX_MESSAGE_BYTES, and a file decompresses to at most
MAX_EXPANSION times its size (recordings measured here expand 2.6-6.6 times) or MAX_CHUNK_BYTES,
whichever is larger. Decompression stops at the declared size, whatever the compressed stream says.

Per record, the cost is bounded too. A chunk holds only schema, channel and message records (the
MCAP specification's rule); a message names a channel registered before it. The records inside
chunks number at most RECORD_ALLOWANCE plus one per MIN_BYTES_PER_RECORD (8) bytes of the file:
twin's writer puts a 16-byte message index entry in the file for every message, beside its
compressed record (17.6 bytes a message in all, measured on a task that says one event 100,000 times
in one step; 60-600 bytes in ordinary runs). So a file of tiny or empty messages that decompresses
32 times cannot make the pass walk hundreds of millions of them (a 45 MB file of 44 million empty
messages stops after 5.7 million). A caller that names the channels it wants (`keep`) gets Message
objects for those only; every message is counted by channel (`counts`), which is all a message the
caller does not interpret costs: memory does not grow with the number of messages.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Container, Iterator
from dataclasses import asdict, dataclass
from io import BytesIO
from typing import BinaryIO

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    Channel,
    Chunk,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Metadata,
    Schema,
)
from mcap.records import (
    Message as McapMessage,
)

from twin.record.mcap.schemas import MAX_MESSAGE_BYTES

MAGIC = b"\x89MCAP0\r\n"
MAX_CHUNK_BYTES = 32 * 1024 * 1024  # the writer's 8 MiB chunks plus one largest message, rounded up
MAX_EXPANSION = 32  # decompressed bytes per file byte, over the whole file
RECORD_ALLOWANCE = 100_000  # records inside chunks that any file may hold, ...
MIN_BYTES_PER_RECORD = 8  # ... plus one per this many bytes of the file
_IN_CHUNK = (int(Opcode.SCHEMA), int(Opcode.CHANNEL))
_MESSAGE = int(Opcode.MESSAGE)
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
# a record's opcode and length, and a message's channel id
_RECORD_HEAD_AND_ID = struct.Struct("<BQH")
_PARSED = {
    Opcode.HEADER: Header,
    Opcode.FOOTER: Footer,
    Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel,
    Opcode.METADATA: Metadata,
    Opcode.ATTACHMENT: Attachment,
    Opcode.DATA_END: DataEnd,
    Opcode.CHUNK: Chunk,
}


class Truncated(Exception):
    """The file ends inside a record (or before its footer)."""


class Damaged(Exception):
    """A record's bytes do not parse or fail their CRC."""


@dataclass(slots=True)  # not frozen: a frozen dataclass's __init__ costs 3x more, per message
class Message:
    """A message record: the fields of mcap's Message, in a fifth of its memory (a file may hold
    millions)."""

    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: bytes

    def as_mcap(self) -> McapMessage:
        """The same record as mcap's own Message class."""
        return McapMessage(**asdict(self))


def _parse(opcode: int, body: bytes) -> McapRecord | None:
    kind = _PARSED.get(opcode)
    if kind is None:
        return None
    try:
        return kind.read(ReadDataStream(BytesIO(body)))
    except Exception as err:
        raise Damaged(
            f"{Opcode(opcode).name.lower()} record does not parse ({type(err).__name__}: {err})"
        ) from err


def _decompress(chunk: Chunk, budget: list[int]) -> bytes:
    """A chunk's records, decompressed to exactly its declared size (refused over the caps) and
    CRC-checked."""
    size = chunk.uncompressed_size
    if size > MAX_CHUNK_BYTES:
        raise Damaged(
            f"a chunk declares {size:,} bytes decompressed; twin writes at most {MAX_CHUNK_BYTES:,}"
        )
    if size > budget[0]:
        raise Damaged(
            f"the chunks decompress to more than {MAX_EXPANSION} times the file's size; "
            f"twin's do not"
        )
    budget[0] -= size
    try:
        if chunk.compression == "zstd":
            reader = zstandard.ZstdDecompressor().stream_reader(chunk.data, read_across_frames=True)
            data = reader.read(size + 1)
            while len(data) <= size:  # read() may return less than asked before the end
                more = reader.read(size + 1 - len(data))
                if not more:
                    break
                data += more
        elif chunk.compression == "lz4":
            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=size + 1)
        elif chunk.compression == "":
            data = chunk.data
        else:
            raise Damaged(
                f"chunk compression {chunk.compression[:40]!r} is unknown; expected "
                f"zstd, lz4 or none"
            )
    except (zstandard.ZstdError, RuntimeError, ValueError) as err:
        raise Damaged(f"chunk does not decompress ({type(err).__name__}: {err})") from err
    if len(data) != size:
        raise Damaged(
            f"a chunk decompresses to "
            f"{'more than ' if len(data) > size else ''}{len(data):,} bytes; "
            f"it declares {size:,}"
        )
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise Damaged("a chunk fails its CRC")
    return data


class _Pass:
    """What one pass over a file has left to spend, and the messages it counted by channel."""

    __slots__ = ("budget", "counts", "keep", "records_left", "records_limit")

    def __init__(
        self, size_bytes: int, counts: dict[int, int], keep: Container[int] | None
    ) -> None:
        # decompressed bytes still allowed
        self.budget = max(MAX_CHUNK_BYTES, MAX_EXPANSION * size_bytes)
        self.records_limit = self.records_left = (
            RECORD_ALLOWANCE + size_bytes // MIN_BYTES_PER_RECORD
        )
        self.counts = counts
        self.keep = keep

    def channel(self, record: McapRecord | None) -> None:
        if isinstance(record, Channel):
            self.counts.setdefault(record.id, 0)


def _chunk_records(chunk: Chunk, state: _Pass) -> Iterator[McapRecord | Message]:
    budget = [state.budget]
    data = _decompress(chunk, budget)
    state.budget = budget[0]
    pos, end = 0, len(data)
    head, message_head = _RECORD_HEAD_AND_ID.unpack_from, _MESSAGE_HEAD.unpack_from
    counts, keep, left = state.counts, state.keep, state.records_left
    same = -1  # the last message's length
    try:  # the loop runs once per message: a 44 MB file may hold millions
        while pos < end:
            if pos + 11 > end:  # every record a chunk may hold starts with an id of 2 bytes
                raise Damaged("chunk ends inside a record header")
            opcode, length, channel_id = head(data, pos)
            start, stop = pos + 9, pos + 9 + length
            if stop > end:
                raise Damaged("a record runs past the end of its chunk")
            left -= 1
            if left < 0:
                raise Damaged(
                    f"the chunks hold more than {state.records_limit:,} records "
                    f"({RECORD_ALLOWANCE:,} and "
                    f"one per {MIN_BYTES_PER_RECORD} bytes of the file); twin's hold far fewer"
                )
            if opcode == _MESSAGE:
                if length < 22:
                    raise Damaged("a message record is shorter than its header")
                if length - 22 > MAX_MESSAGE_BYTES:
                    raise Damaged(
                        f"a message holds {length - 22:,} bytes; twin writes at most "
                        f"{MAX_MESSAGE_BYTES:,}"
                    )
                try:
                    counts[channel_id] += 1
                except KeyError:
                    raise Damaged(
                        f"a message on channel {channel_id}, which no channel record before it "
                        "registers"
                    ) from None
                if keep is None or channel_id in keep:
                    channel_id, sequence, log_time, publish_time = message_head(data, start)
                    yield Message(
                        channel_id, sequence, log_time, publish_time, data[start + 22 : stop]
                    )
                elif length == same and not (left & 255):
                    # now and then in a run of same-size messages: count it at once
                    skipped = _count_run(
                        data=data,
                        pos=stop,
                        end=end,
                        length=length,
                        counts=counts,
                        keep=keep,
                        left=left,
                    )
                    left -= skipped
                    stop += skipped * (9 + length)
                same = length
            elif opcode in _IN_CHUNK:
                record = _parse(opcode, data[start:stop])
                state.channel(record)
                yield record
            else:
                try:
                    name = Opcode(opcode).name.lower()
                except ValueError:
                    name = f"opcode {opcode:#x}"
                raise Damaged(
                    f"a chunk holds a {name} record; chunks hold only schema, channel "
                    f"and message records"
                )
            pos = stop
    finally:
        state.records_left = left


def _count_run(
    data: bytes,
    pos: int,
    end: int,
    length: int,
    counts: dict[int, int],
    keep: Container[int] | None,
    left: int,
) -> int:
    """How many message records of `length` bytes follow one another from `pos`, none on a channel
    kept or unknown, counted by channel in one numpy pass (at most `left`); 0 if fewer than 64.
    Floods of empty or equal messages cost no Python work per message."""
    stride = 9 + length
    rows = min((end - pos) // stride, left, 1 << 20)
    if rows < 64:
        return 0
    head = np.frombuffer(data, np.uint8, count=rows * stride, offset=pos).reshape(rows, stride)[
        :, :11
    ]
    same = (head[:, 0] == _MESSAGE) & (
        head[:, 1:9] == np.frombuffer(struct.pack("<Q", length), np.uint8)
    ).all(1)
    run = rows if same.all() else int(np.argmin(same))
    if run < 64:
        return 0
    ids, n = np.unique(head[:run, 9:11].copy().view("<u2").ravel(), return_counts=True)
    if any(int(i) not in counts or (keep is not None and int(i) in keep) for i in ids):
        return 0
    for i, k in zip(ids.tolist(), n.tolist(), strict=True):
        counts[i] += k
    return run


def records(
    f: BinaryIO,
    size_bytes: int,
    *,
    keep: Container[int] | None = None,
    counts: dict[int, int] | None = None,
) -> Iterator[McapRecord | Message]:
    """Every record of the file (chunks opened), in order. Raises Truncated or Damaged where the
    file stops making sense; everything yielded before that is sound.

    keep: the channel ids whose messages are yielded (None: every message); the caller may add to it
    as it sees channel records. counts: filled with the number of messages on each channel id."""
    if f.read(len(MAGIC)) != MAGIC:
        raise Damaged("the file does not start with the MCAP magic bytes")
    pos = len(MAGIC)
    state = _Pass(size_bytes, {} if counts is None else counts, keep)
    while True:
        head = f.read(9)
        if len(head) < 9:
            raise Truncated("the file ends before its MCAP footer (cut short)")
        opcode, length = _RECORD_HEAD.unpack(head)
        if opcode == 0:  # no MCAP record has opcode 0: zeros (a preallocated or overwritten tail)
            raise Damaged(
                f"zero bytes where a record should start (byte {pos:,}), not an MCAP record"
            )
        if pos + 9 + length > size_bytes:
            raise Truncated("the file ends inside a record (cut short)")
        pos += 9 + length
        if opcode == Opcode.MESSAGE_INDEX or opcode not in _PARSED:
            f.seek(length, 1)
            continue
        body = f.read(length)
        if len(body) < length:
            raise Truncated("the file ends inside a record (cut short)")
        record = _parse(opcode, body)
        if isinstance(record, Chunk):
            yield from _chunk_records(record, state)
            continue
        state.channel(record)
        yield record
        if isinstance(record, Footer):
            if f.read(len(MAGIC)) != MAGIC:
                raise Truncated("the file ends without its closing MCAP magic bytes")
            if pos + len(MAGIC) != size_bytes:
                raise Damaged(
                    f"{size_bytes - pos - len(MAGIC):,} bytes follow the MCAP file's "
                    f"closing magic bytes"
                )
            return


ROS2_PROFILE = "ros2"  # a ROS 2 bag's MCAP file (rosbag2's MCAP storage)
BAG_METADATA = "metadata.yaml"  # what makes a folder a ROS 2 bag


def is_bag_folder(path: str | os.PathLike) -> bool:
    """A ROS 2 bag's folder: a folder holding metadata.yaml."""
    return os.path.isdir(path) and os.path.isfile(os.path.join(path, BAG_METADATA))


def is_bag(path: str | os.PathLike) -> bool:
    """A ROS 2 bag: a folder holding metadata.yaml, or an MCAP file whose profile is `ros2` (told
    without importing rosbags, which costs a command about 0.2 s to start)."""
    return is_bag_folder(path) or (os.path.isfile(path) and profile(path) == ROS2_PROFILE)


def profile(path: str | os.PathLike) -> str | None:
    """The profile of an MCAP file's header ("ros2" for a ROS 2 bag's file, "" for a twin
    recording), or None for anything that is no readable MCAP file with a header."""
    try:
        with open(path, "rb") as f:
            if f.read(len(MAGIC)) != MAGIC:
                return None
            head = f.read(9)
            if len(head) < 9:
                return None
            opcode, length = _RECORD_HEAD.unpack(head)
            body = f.read(min(length, 1 << 16))
    except (OSError, ValueError):
        return None
    if opcode != Opcode.HEADER or len(body) < min(length, 4):
        return None
    try:
        header = _parse(opcode, body)
    except Damaged:
        return None
    return header.profile if isinstance(header, Header) else None
