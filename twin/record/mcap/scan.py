"""One fast pass over an MCAP file's records, in file order, stopping cleanly at a damaged end.

Record bodies are parsed by mcap's own record classes, except the two that dominate a recording:
Message records inside chunks (a fixed 22-byte header, then the payload) are sliced directly, and
MessageIndex records are skipped (the pass reads every chunk anyway). Chunk CRCs are checked.

A damaged or hostile file must cost bounded memory and time, so sizes are capped by what twin's own
writer produces: a chunk decompresses to at most MAX_CHUNK_BYTES (the writer closes chunks at 8 MiB
and every flush), a message holds at most MAX_MESSAGE_BYTES, and a file decompresses to at most
MAX_EXPANSION times its size (recordings measured here expand 2.6-6.6 times) or MAX_CHUNK_BYTES,
whichever is larger. Decompression stops at the declared size, whatever the compressed stream says.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from io import BytesIO
from typing import BinaryIO

import lz4.frame
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
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
_PARSED = {Opcode.HEADER: Header, Opcode.FOOTER: Footer, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
           Opcode.METADATA: Metadata, Opcode.ATTACHMENT: Attachment, Opcode.DATA_END: DataEnd, Opcode.CHUNK: Chunk}


class Truncated(Exception):
    """The file ends inside a record (or before its footer)."""


class Damaged(Exception):
    """A record's bytes do not parse or fail their CRC."""


@dataclass(slots=True)  # not frozen: a frozen dataclass's __init__ costs 3x more, per message
class Message:
    """A message record: the fields of mcap's Message, in a fifth of its memory (a file may hold millions)."""

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
        raise Damaged(f"{Opcode(opcode).name.lower()} record does not parse ({type(err).__name__}: {err})") from err


def _decompress(chunk: Chunk, budget: list[int]) -> bytes:
    """A chunk's records, decompressed to exactly its declared size (refused over the caps) and CRC-checked."""
    size = chunk.uncompressed_size
    if size > MAX_CHUNK_BYTES:
        raise Damaged(f"a chunk declares {size:,} bytes decompressed; twin writes at most {MAX_CHUNK_BYTES:,}")
    if size > budget[0]:
        raise Damaged(f"the chunks decompress to more than {MAX_EXPANSION} times the file's size; twin's do not")
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
            raise Damaged(f"chunk compression {chunk.compression[:40]!r} is unknown; expected zstd, lz4 or none")
    except (zstandard.ZstdError, RuntimeError, ValueError) as err:
        raise Damaged(f"chunk does not decompress ({type(err).__name__}: {err})") from err
    if len(data) != size:
        raise Damaged(f"a chunk decompresses to {'more than ' if len(data) > size else ''}{len(data):,} bytes; "
                      f"it declares {size:,}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise Damaged("a chunk fails its CRC")
    return data


def _chunk_records(chunk: Chunk, budget: list[int]) -> Iterator[McapRecord | Message]:
    data = _decompress(chunk, budget)
    pos, end = 0, len(data)
    head, message_head = _RECORD_HEAD.unpack_from, _MESSAGE_HEAD.unpack_from
    while pos < end:
        if pos + 9 > end:
            raise Damaged("chunk ends inside a record header")
        opcode, length = head(data, pos)
        start, stop = pos + 9, pos + 9 + length
        if stop > end:
            raise Damaged("a record runs past the end of its chunk")
        if opcode == Opcode.MESSAGE:
            if length < 22:
                raise Damaged("a message record is shorter than its header")
            if length - 22 > MAX_MESSAGE_BYTES:
                raise Damaged(f"a message holds {length - 22:,} bytes; twin writes at most {MAX_MESSAGE_BYTES:,}")
            channel_id, sequence, log_time, publish_time = message_head(data, start)
            yield Message(channel_id, sequence, log_time, publish_time, data[start + 22:stop])
        else:
            record = _parse(opcode, data[start:stop])
            if record is not None:
                yield record
        pos = stop


def records(f: BinaryIO, size_bytes: int) -> Iterator[McapRecord | Message]:
    """Every record of the file (chunks opened), in order. Raises Truncated or Damaged where the
    file stops making sense; everything yielded before that is sound."""
    if f.read(len(MAGIC)) != MAGIC:
        raise Damaged("the file does not start with the MCAP magic bytes")
    pos = len(MAGIC)
    budget = [max(MAX_CHUNK_BYTES, MAX_EXPANSION * size_bytes)]  # decompressed bytes still allowed
    while True:
        head = f.read(9)
        if len(head) < 9:
            raise Truncated("the file ends before its MCAP footer (cut short)")
        opcode, length = _RECORD_HEAD.unpack(head)
        if opcode == 0:  # no MCAP record has opcode 0: zeros (a preallocated or overwritten tail)
            raise Damaged(f"zero bytes where a record should start (byte {pos:,}), not an MCAP record")
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
            yield from _chunk_records(record, budget)
            continue
        yield record
        if isinstance(record, Footer):
            if f.read(len(MAGIC)) != MAGIC:
                raise Truncated("the file ends without its closing MCAP magic bytes")
            if pos + len(MAGIC) != size_bytes:
                raise Damaged(f"{size_bytes - pos - len(MAGIC):,} bytes follow the MCAP file's closing magic bytes")
            return
