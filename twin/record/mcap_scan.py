"""One fast pass over an MCAP file's records, in file order, stopping cleanly at a damaged end.

Record bodies are parsed by mcap's own record classes, except the two that dominate a recording:
Message records inside chunks (a fixed 22-byte header, then the payload) are sliced directly, and
MessageIndex records are skipped (the pass reads every chunk anyway). Chunk CRCs are checked.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from io import BytesIO
from typing import BinaryIO

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
    Message,
    Metadata,
    Schema,
)
from mcap.stream_reader import get_chunk_data_stream

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
_PARSED = {Opcode.HEADER: Header, Opcode.FOOTER: Footer, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
           Opcode.METADATA: Metadata, Opcode.ATTACHMENT: Attachment, Opcode.DATA_END: DataEnd, Opcode.CHUNK: Chunk}


class Truncated(Exception):
    """The file ends inside a record (or before its footer)."""


class Damaged(Exception):
    """A record's bytes do not parse or fail their CRC."""


def _parse(opcode: int, body: bytes) -> McapRecord | None:
    kind = _PARSED.get(opcode)
    if kind is None:
        return None
    try:
        return kind.read(ReadDataStream(BytesIO(body)))
    except Exception as err:
        raise Damaged(f"{Opcode(opcode).name.lower()} record does not parse ({type(err).__name__}: {err})") from err


def _chunk_records(chunk: Chunk) -> Iterator[McapRecord]:
    try:
        stream, size = get_chunk_data_stream(chunk, validate_crc=True)
        data = stream.read(size)
    except Exception as err:
        raise Damaged(f"chunk does not decompress or fails its CRC ({type(err).__name__}: {err})") from err
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
            channel_id, sequence, log_time, publish_time = message_head(data, start)
            yield Message(channel_id=channel_id, sequence=sequence, log_time=log_time, publish_time=publish_time,
                          data=data[start + 22:stop])
        else:
            record = _parse(opcode, data[start:stop])
            if record is not None:
                yield record
        pos = stop


def records(f: BinaryIO, size_bytes: int) -> Iterator[McapRecord]:
    """Every record of the file (chunks opened), in order. Raises Truncated or Damaged where the
    file stops making sense; everything yielded before that is sound."""
    if f.read(len(MAGIC)) != MAGIC:
        raise Damaged("the file does not start with the MCAP magic bytes")
    pos = len(MAGIC)
    while True:
        head = f.read(9)
        if len(head) < 9:
            raise Truncated("the file ends before its MCAP footer (cut short)")
        opcode, length = _RECORD_HEAD.unpack(head)
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
            yield from _chunk_records(record)
            continue
        yield record
        if isinstance(record, Footer):
            if f.read(len(MAGIC)) != MAGIC:
                raise Truncated("the file ends without its closing MCAP magic bytes")
            return
