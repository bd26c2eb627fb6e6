"""The wire format of CoppeliaSim's ZeroMQ remote API, protocol version 2.

One ZMQ frame carries one CBOR map. A request holds `func`, `args`, `argsL` and `uuid` (and `ver`,
`lang`, `timeout` in a client's first message); a reply holds exactly one of `ret` (a list of
values), `err` (a message) or `func` (a control message such as `_*wait*_`). Everything here
turns bad input into a RequestError whose message names the problem, never a crash.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cbor2

from twin.model.errors import exception_text
from twin.model.json_values import finite_number

PROTOCOL_VERSION = 2
# Limits on what a client may send (README, "Remote control"); over each, the client gets an error
# reply.
MAX_REQUEST_BYTES = 1 << 20  # a real request is a few hundred bytes; 1 MiB is generous
MAX_FRAME_BYTES = 256 << 20  # hard cap: ZMQ closes a connection announcing a bigger frame, unread
# per connection: sent, not yet a whole message the server
MAX_UNREAD_BYTES = MAX_FRAME_BYTES + (64 << 10)
# took (one frame at the hard cap, its framing and the handshake); above, the connection is closed
# (intake.py)
# all connections together (twin serve --max-held-mib): any number of flooding connections cannot
# make the server hold more than about this (intake.py)
DEFAULT_MAX_HELD_BYTES = 256 << 20
MAX_DEPTH = 32  # nested arrays/maps (a request map holding args is 2 deep)
MAX_ITEMS = 100_000  # CBOR data items in one request (a request of n bytes holds at most n)
MAX_ARGS = 64
MAX_NAME_CHARS = 256  # signal names: a name is kept in the scene for the whole run
MAX_SIGNALS = 1024  # signals set at once in a scene
MAX_TEXT_CHARS = 4096  # log messages: printed and recorded
# integer arguments (handles, levels, signal values) are at most 64-bit
INT64 = (-(1 << 63), (1 << 63) - 1)
BRIEF_CHARS = 60  # how much of a client's string an error message quotes

WAIT_REPLY = cbor2.dumps({"func": "_*wait*_", "args": []})
EMPTY_REPLY = cbor2.dumps({"ret": []})


class RequestError(Exception):
    """A request the server cannot serve; the message goes back to the client as `err`."""


@dataclass(slots=True)
class Request:
    func: str
    args: list
    uuid: str
    first: dict | None  # ver/lang/timeout when the message carried them


def decode(raw: bytes) -> Request:
    """Parse one raw request; raises RequestError naming what is wrong with it.

    Error messages show a client's values in brief (brief_value()), never format them whole: a value
    can be an integer of a million digits, which repr() refuses.
    """
    if len(raw) > MAX_REQUEST_BYTES:
        raise RequestError(
            f"request of {len(raw)} bytes exceeds the limit of {MAX_REQUEST_BYTES} bytes (1 MiB)"
        )
    if len(raw) > MAX_ITEMS:  # only then can it hold more than MAX_ITEMS items
        _check_item_count(raw)
    try:
        msg = cbor2.loads(
            raw,
            max_depth=MAX_DEPTH,
            semantic_decoders=_REFUSED_TAGS,
            tag_hook=_refuse_tag,
            strict_hashable_types=True,
        )
    except Exception as err:  # noqa: BLE001 - cbor2 raises CBORDecodeError, ValueError, MemoryError, ...
        refused = _refused_tag(err)
        if refused is not None:
            raise RequestError(f"malformed request: {refused}") from None
        raise RequestError(
            f"malformed request: not valid CBOR ({type(err).__name__}: {safe_str(err)})"
        ) from None
    if not isinstance(msg, dict):
        raise RequestError(f"malformed request: expected a CBOR map, got {type(msg).__name__}")
    uuid = msg.get("uuid")
    if not isinstance(uuid, str) or not uuid:
        raise VersionMismatch(
            f"client version does not match: request without a 'uuid' (protocol version 1?); "
            f"this server speaks ZeroMQ remote API protocol version {PROTOCOL_VERSION}"
        )
    func = msg.get("func")
    if not isinstance(func, str) or not func:
        raise RequestError(
            f"malformed request: 'func' must be a non-empty string, got {brief_value(func)}"
        )
    args = msg.get("args", [])
    if args is None:
        args = []
    if not isinstance(args, list):
        raise RequestError(
            f"malformed request to {brief(func)}: 'args' must be an array, got "
            f"{type(args).__name__}"
        )
    n = msg.get("argsL", len(args))
    if isinstance(n, bool) or not isinstance(n, int) or not len(args) <= n <= MAX_ARGS:
        raise RequestError(
            f"malformed request to {brief(func)}: 'argsL' {brief_value(n)} must be an integer "
            f"{len(args)}..{MAX_ARGS}"
        )
    if n > len(args):
        args = args + [None] * (n - len(args))  # trailing nulls the encoder dropped
    first = None
    if "ver" in msg:
        ver = msg["ver"]
        if isinstance(ver, bool) or ver != PROTOCOL_VERSION:
            raise VersionMismatch(
                f"client version does not match: protocol version {brief_value(ver)}; "
                f"this server speaks version "
                f"{PROTOCOL_VERSION}"
            )
        first = {"lang": msg.get("lang"), "timeout": msg.get("timeout")}
    return Request(func, args, uuid, first)


def _refuse_tag(*args: Any) -> Any:
    """cbor2's hook for tags it does not know (called with the CBORTag; the order differs by
    version)."""
    number = next((a.tag for a in args if isinstance(a, cbor2.CBORTag)), "")
    raise RequestError(f"CBOR tag {number} is not accepted (only 2 and 3, big integers)")


def _refuse_semantic_tag(number: int) -> Callable[..., Any]:
    def refuse(*_: Any) -> Any:
        raise RequestError(f"CBOR tag {number} is not accepted (only 2 and 3, big integers)")

    return refuse


# cbor2's own tags (dates, decimals, shared references 28/29 whose values repeat without end, string
# references, regular expressions, sets, ...) are refused; 2 and 3 (big integers) stay.
_REFUSED_TAGS = {
    t: _refuse_semantic_tag(t)
    for t in (0, 1, 4, 5, 25, 28, 29, 30, 35, 36, 37, 100, 256, 258, 260, 261, 1004, 55799)
}


def _refused_tag(err: BaseException) -> RequestError | None:
    """The RequestError of a refused tag, which cbor2 wraps once per enclosing container."""
    for _ in range(MAX_DEPTH + 2):
        if err is None or isinstance(err, RequestError):
            return err
        err = err.__cause__
    return None


def _check_item_count(raw: bytes) -> None:
    """Refuse a request of more than MAX_ITEMS data items before decoding it (decoded, each costs
    ~50 bytes or more). Walks the item heads only: a container's items follow its head, so every
    head is one item, except tags and the break byte; strings are skipped by their length."""
    end, i, items = len(raw), 0, 0
    while i < end:
        head = raw[i]
        major, info = head >> 5, head & 0x1F
        i += 1
        length = info
        if 24 <= info <= 27:
            width = 1 << (info - 24)
            length = int.from_bytes(raw[i : i + width], "big")
            i += width
        if major in (2, 3) and info != 31:
            i += length  # a string's bytes
        if major == 6 or head == 0xFF:
            continue  # a tag (its item follows) or the end of an indefinite container
        items += 1
        if items > MAX_ITEMS:
            raise RequestError(f"request holds more than {MAX_ITEMS} data items (the limit)")


def safe_str(err: BaseException, limit: int = 200) -> str:
    """An exception's message, escaped and cut to `limit` characters; never raises."""
    return printable(exception_text(err), limit)


def printable(text: str, limit: int = MAX_TEXT_CHARS) -> str:
    """`text` for a status line: control and other non-printable characters escaped (a client cannot
    start a line of its own or move the cursor), cut to `limit` characters."""
    suffix = ""
    if len(text) > limit:
        suffix = f"... ({len(text)} characters)"
        text = text[:limit]
    if not text.isprintable():
        text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text + suffix


def brief(text: str) -> str:
    """A client's string for a message: its first BRIEF_CHARS characters, escaped."""
    return printable(text, BRIEF_CHARS)


def brief_value(value: Any) -> str:
    """A short description of a client's value for an error message, in constant time."""
    if isinstance(value, str):
        more = f"... ({len(value)} characters)" if len(value) > BRIEF_CHARS else ""
        return repr(value[:BRIEF_CHARS]) + more
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 64:
        return f"an integer of {value.bit_length()} bits"
    if value is None or isinstance(value, (bool, int, float)):
        return repr(value)
    if isinstance(value, (bytes, bytearray)):
        return f"a byte string of {len(value)} bytes"
    if isinstance(value, list):
        return f"an array of {len(value)} items"
    if isinstance(value, dict):
        return f"a map of {len(value)} entries"
    return f"a value of type {type(value).__name__}"


class VersionMismatch(RequestError):
    """An old (v1) or unknown client: answered in both the v1 and the v2 error shapes."""


def encode_ret(values: list) -> bytes:
    return cbor2.dumps({"ret": values})


def encode_err(message: str) -> bytes:
    return cbor2.dumps({"err": message})


def encode_version_mismatch(message: str) -> bytes:
    return cbor2.dumps({"success": False, "error": message, "err": message})


# -- argument checking ------------------------------------------------------------------------
REQUIRED = object()


def _int(v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not INT64[0] <= v <= INT64[1]:
        raise TypeError("an integer (64-bit)")
    return v


def _float(v: Any) -> float:
    number = finite_number(v)
    if number is None:
        raise TypeError("a finite number")
    return number


def _str(v: Any) -> str:
    if not isinstance(v, str):
        raise TypeError("a string")
    if v.endswith("@func"):  # how the official client sends a Python function
        raise TypeError("a string, not a Python function (callbacks are not supported)")
    return v


def _bool(v: Any) -> bool:
    if isinstance(v, bool):
        return v
    if isinstance(v, int) and v in (0, 1):
        return bool(v)
    raise TypeError("a boolean")


def _name(v: Any) -> str:
    if len(_str(v)) > MAX_NAME_CHARS:
        raise TypeError(f"a string of at most {MAX_NAME_CHARS} characters")
    return v


def _text(v: Any) -> str:
    if len(_str(v)) > MAX_TEXT_CHARS:
        raise TypeError(f"a string of at most {MAX_TEXT_CHARS} characters")
    return v


def _any(v: Any) -> Any:
    return v


def _map_or_none(v: Any) -> dict:
    if v is None:
        return {}
    if not isinstance(v, dict):
        raise TypeError("a map")
    return v


def _list_or_none(v: Any) -> list:
    if v is None:
        return []
    if not isinstance(v, list):
        raise TypeError("an array")
    return v


KINDS = {
    "int": _int,
    "float": _float,
    "str": _str,
    "name": _name,
    "text": _text,
    "bool": _bool,
    "any": _any,
    "map?": _map_or_none,
    "list?": _list_or_none,
}


@dataclass(frozen=True, slots=True)
class Param:
    name: str
    kind: str
    default: Any = REQUIRED


class Signature:
    """A function's parameters, with the count of required ones computed once."""

    __slots__ = ("n_required", "params")

    def __init__(self, *params: Param) -> None:
        self.params = params
        self.n_required = sum(1 for p in params if p.default is REQUIRED)


def check_args(signature: Signature, args: list) -> list:
    """Convert `args` by `signature`; raises RequestError naming the parameter and the value."""
    params, n_req = signature.params, signature.n_required
    if not n_req <= len(args) <= len(params):
        want = f"{n_req}" if n_req == len(params) else f"{n_req}..{len(params)}"
        sig = ", ".join(f"{p.name}: {p.kind}" for p in params)
        raise RequestError(f"expected {want} argument(s) ({sig}), got {len(args)}")
    out = []
    for i, p in enumerate(params):
        if i >= len(args) or (args[i] is None and p.default is not REQUIRED):
            out.append(p.default)
            continue
        try:
            out.append(KINDS[p.kind](args[i]))
        except TypeError as err:
            raise RequestError(
                f"argument {i + 1} ({p.name}) is {brief_value(args[i])}; expected {err}"
            ) from None
    return out
