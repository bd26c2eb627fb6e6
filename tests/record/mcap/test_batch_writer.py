"""BatchWriter.add_messages writes what mcap's own add_message writes, byte for byte: the same
records, chunks, indexes and statistics (it reaches into the Writer's state, so a change of the
pinned mcap version shows here first)."""

from __future__ import annotations

import io
import random

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from twin.record.mcap.batch_writer import BatchWriter


def _messages(n: int) -> list[tuple[int, int, bytes, int]]:
    """(channel id, log time, data, sequence): times that repeat and go back now and then, data of
    varied length, channels in no order."""
    rng = random.Random(7)
    out, t = [], 0
    for i in range(n):
        t = max(0, t + rng.choice((-3, 0, 1, 5, 1000)))
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 700)))
        out.append((rng.randrange(1, 5), t, data, i))
    return out


def _file(cls, messages, *, chunk_bytes: int, batch: int, compression) -> bytes:
    out = io.BytesIO()
    writer = cls(out, chunk_size=chunk_bytes, compression=compression)
    writer.start(profile="", library="test")
    schema = writer.register_schema("s", "protobuf", b"")
    for i in range(4):
        writer.register_channel(f"/c{i}", "protobuf", schema)
    for k in range(0, len(messages), batch):
        part = messages[k : k + batch]
        if cls is BatchWriter:
            writer.add_messages(part)
        else:
            for channel, t, data, seq in part:
                writer.add_message(channel, log_time=t, data=data, publish_time=t, sequence=seq)
        if k % (3 * batch) == 0:
            writer.flush()  # the recorder's flushes end chunks
    writer.finish()
    return out.getvalue()


@pytest.mark.parametrize("chunk_bytes", [8 * 1024 * 1024, 3000])  # 3000: chunks end mid-batch
@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.NONE])
def test_add_messages_writes_the_bytes_add_message_writes(chunk_bytes, compression):
    messages = _messages(600)
    ours = _file(BatchWriter, messages, chunk_bytes=chunk_bytes, batch=37, compression=compression)
    theirs = _file(Writer, messages, chunk_bytes=chunk_bytes, batch=37, compression=compression)
    assert ours == theirs
    summary = make_reader(io.BytesIO(ours)).get_summary()
    assert summary.statistics.message_count == 600
    if chunk_bytes == 3000:
        assert summary.statistics.chunk_count > 20  # the size rule ended chunks inside batches


def test_an_empty_batch_adds_nothing():
    """add_messages([]) leaves the file as it was: no message, no chunk, no statistics."""
    out = io.BytesIO()
    writer = BatchWriter(out, chunk_size=1 << 20, compression=CompressionType.ZSTD)
    writer.start(profile="", library="test")
    schema = writer.register_schema("s", "protobuf", b"")
    for i in range(4):
        writer.register_channel(f"/c{i}", "protobuf", schema)
    writer.add_messages([])
    writer.finish()
    assert out.getvalue() == _file(
        Writer, [], chunk_bytes=1 << 20, batch=1, compression=CompressionType.ZSTD
    )
