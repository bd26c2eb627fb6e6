"""mcap's Writer with one more way in: add_messages, many messages in one call.

The library's add_message builds a record object and writes it field by field (about 8.5 us a
message on our machines); the twin's MCAP writer adds a few thousand a simulated minute, in
batches. add_messages writes the same bytes and keeps the same indexes and statistics, in one pass.
It reaches into the Writer's own state, so it holds only for the mcap version pyproject.toml pins;
tests/record/mcap/test_batch_writer.py holds it to add_message, byte for byte.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import Writer

# a Message record's head: opcode, record length, channel id, sequence, log time, publish time
_HEAD = struct.Struct("<BQHIQQ")
_FIELDS_BYTES = _HEAD.size - 9  # the record's length counts what follows opcode and length


class BatchWriter(Writer):
    """An mcap Writer (chunked) that also takes messages in batches."""

    def add_messages(self, messages: Iterable[tuple[int, int, bytes, int]]) -> None:
        """Add messages given as (channel id, log time, data, sequence), each published at its log
        time, in order: the file, its indexes and statistics are what add_message would make of
        them one by one."""
        stats = self._Writer__statistics
        chunk = self._Writer__chunk_builder
        counts, indices = stats.channel_message_counts, chunk.message_indices
        buffer, limit = chunk.record_writer._buffer, self._Writer__chunk_size
        opcode = Opcode.MESSAGE
        for channel_id, t, data, sequence in messages:
            first_t = stats.message_start_time if stats.message_count else t
            stats.message_start_time = min(t, first_t)
            stats.message_end_time = max(t, stats.message_end_time)
            counts[channel_id] += 1
            stats.message_count += 1
            first_t = chunk.message_start_time if chunk.num_messages else t
            chunk.message_start_time = min(t, first_t)
            chunk.message_end_time = max(t, chunk.message_end_time)
            index = indices.get(channel_id)
            if index is None:
                index = indices[channel_id] = MessageIndex(channel_id=channel_id, records=[])
            index.records.append((t, buffer.tell()))
            chunk.num_messages += 1
            buffer.write(_HEAD.pack(opcode, _FIELDS_BYTES + len(data), channel_id, sequence, t, t))
            buffer.write(data)
            if buffer.tell() > limit:  # a chunk this large ends here, as add_message ends it
                self._Writer__maybe_finalize_chunk()
                buffer = chunk.record_writer._buffer
