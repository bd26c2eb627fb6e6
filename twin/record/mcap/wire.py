"""The protobuf wire format, by hand: encoding the few shapes the recorder writes, and splitting a
message into its fields for the reader's fast path.

Packed repeated double / sfixed64 / sfixed32 fields are little-endian arrays, so numpy writes and
reads them directly; any protobuf library decodes the same bytes from the schema in the file.
"""

from __future__ import annotations

import numpy as np

from twin.model.errors import RecordingError

VARINT, I64, LEN, I32 = 0, 1, 2, 5
# Fields one message may hold: twin writes each block field once (packed), so a handful; other
# writers' unpacked arrays are accepted up to this many values. A damaged message costs bounded
# time.
MAX_FIELDS = 65_536
_VARINT_CACHE = [bytes([i]) for i in range(128)]


def varint(value: int) -> bytes:
    """Base-128 varint of a non-negative integer (negative int64 as its 64-bit two's complement)."""
    if value < 0:
        value += 1 << 64
    if value < 128:
        return _VARINT_CACHE[value]
    out = bytearray()
    while value >= 128:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def tag(field_number: int, wire_type: int) -> bytes:
    return varint((field_number << 3) | wire_type)


def len_field(field_number: int, payload: bytes) -> bytes:
    """A length-delimited field: packed array, string, bytes or sub-message."""
    return tag(field_number, LEN) + varint(len(payload)) + payload


def str_field(field_number: int, text: str) -> bytes:
    return len_field(field_number, text.encode())


def packed(field_number: int, array: np.ndarray, dtype: str) -> bytes:
    """A packed repeated field from a numpy array ('<f8' double, '<i8' sfixed64, '<i4' sfixed32,
    '|u1' bool)."""
    return len_field(field_number, np.ascontiguousarray(array, dtype=dtype).tobytes())


def read_varint(buf: bytes | memoryview, pos: int) -> tuple[int, int]:
    result = 0
    shift = 0
    while True:
        if pos >= len(buf):
            raise RecordingError("protobuf message ends inside a varint")
        b = buf[pos]
        pos += 1
        result |= (b & 0x7F) << shift
        if b < 128:
            return result, pos
        shift += 7
        if shift > 63:
            raise RecordingError("protobuf varint longer than 10 bytes")


def split_fields(buf: bytes) -> dict[int, list[tuple[int, bytes | int]]]:
    """Every field of a message, by number, in order: (wire_type, value) with value the raw bytes
    of a length-delimited or fixed-width field, or the integer of a varint."""
    out: dict[int, list[tuple[int, bytes | int]]] = {}
    pos, end, count = 0, len(buf), 0
    while pos < end:
        key = buf[pos]  # one-byte keys and lengths are the common case: skip the general varint
        if key < 128:
            pos += 1
        else:
            key, pos = read_varint(buf, pos)
        number, wire_type = key >> 3, key & 7
        if number == 0:
            raise RecordingError("protobuf field number 0 (zero bytes or garbage), not a field")
        count += 1
        if count > MAX_FIELDS:
            raise RecordingError(
                f"protobuf message holds more than {MAX_FIELDS:,} fields; expected packed arrays"
            )
        if wire_type == LEN:
            if pos < end and buf[pos] < 128:
                size, pos = buf[pos], pos + 1
            else:
                size, pos = read_varint(buf, pos)
            value, pos = buf[pos : pos + size], pos + size
        elif wire_type == VARINT:
            value, pos = read_varint(buf, pos)
        elif wire_type in (I64, I32):
            width = 8 if wire_type == I64 else 4
            value, pos = buf[pos : pos + width], pos + width
        else:
            raise RecordingError(
                f"protobuf wire type {wire_type} (field {number}) is not supported"
            )
        if pos > end:
            raise RecordingError(f"protobuf field {number} runs past the end of its message")
        out.setdefault(number, []).append((wire_type, value))
    return out


def raw_of(fields: dict, number: int, dtype: str) -> bytes:
    """A repeated numeric field's little-endian bytes, packed or not."""
    parts = fields.get(number)
    if not parts:
        return b""
    if len(parts) == 1 and parts[0][0] == LEN:
        return parts[0][1]
    return array_of(fields, number, dtype).tobytes()


def array_of(fields: dict, number: int, dtype: str) -> np.ndarray:
    """A repeated numeric field as a numpy array, packed or not (a decoder must accept both)."""
    parts = fields.get(number)
    if not parts:
        return np.zeros(0, dtype=dtype)
    if len(parts) == 1 and parts[0][0] == LEN:
        return np.frombuffer(parts[0][1], dtype=dtype)
    chunks = []
    for wire_type, value in parts:
        if wire_type == VARINT:  # unpacked bool
            chunks.append(np.array([value], dtype=dtype).tobytes())
        else:
            chunks.append(bytes(value))
    return np.frombuffer(b"".join(chunks), dtype=dtype)
