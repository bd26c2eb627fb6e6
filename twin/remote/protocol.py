"""The wire format of CoppeliaSim's ZeroMQ remote API, protocol version 2.

One ZMQ frame carries one CBOR map. A request holds `func`, `args`, `argsL` and `uuid` (and `ver`,
`lang`, `timeout` in a client's first message); a reply holds exactly one of `ret` (a list of
values), `err` (a message) or `func` (a control message such as `_*wait*_`). Everything here
turns bad input into a RequestError whose message names the problem, never a crash.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cbor2

PROTOCOL_VERSION = 2
MAX_REQUEST_BYTES = 1 << 20  # a real request is a few hundred bytes; 1 MiB is generous
MAX_ARGS = 64

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
    """Parse one raw request; raises RequestError naming what is wrong with it."""
    if len(raw) > MAX_REQUEST_BYTES:
        raise RequestError(f"request of {len(raw)} bytes exceeds the limit of {MAX_REQUEST_BYTES} bytes")
    try:
        msg = cbor2.loads(raw)
    except Exception as err:  # noqa: BLE001 - cbor2 raises CBORDecodeError, ValueError, RecursionError, ...
        raise RequestError(f"malformed request: not valid CBOR ({type(err).__name__}: {err})") from None
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
        raise RequestError(f"malformed request: 'func' must be a non-empty string, got {func!r:.80}")
    args = msg.get("args", [])
    if args is None:
        args = []
    if not isinstance(args, list):
        raise RequestError(f"malformed request to {func}: 'args' must be an array, got {type(args).__name__}")
    n = msg.get("argsL", len(args))
    if isinstance(n, bool) or not isinstance(n, int) or not len(args) <= n <= MAX_ARGS:
        raise RequestError(f"malformed request to {func}: 'argsL' {n!r:.40} must be an integer {len(args)}..{MAX_ARGS}")
    if n > len(args):
        args = args + [None] * (n - len(args))  # trailing nulls the encoder dropped
    first = None
    if "ver" in msg:
        ver = msg["ver"]
        if ver != PROTOCOL_VERSION:
            raise VersionMismatch(
                f"client version does not match: protocol version {ver!r:.40}; this server speaks version "
                f"{PROTOCOL_VERSION}"
            )
        first = {"lang": msg.get("lang"), "timeout": msg.get("timeout")}
    return Request(func, args, uuid, first)


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
    if isinstance(v, bool) or not isinstance(v, int):
        raise TypeError("an integer")
    return v


def _float(v: Any) -> float:
    try:
        ok = not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
    except OverflowError:  # an int too large for a float
        ok = False
    if not ok:
        raise TypeError("a finite number")
    return float(v)


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


KINDS = {"int": _int, "float": _float, "str": _str, "bool": _bool, "any": _any, "map?": _map_or_none,
         "list?": _list_or_none}


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
            raise RequestError(f"argument {i + 1} ({p.name}) is {args[i]!r:.60}; expected {err}") from None
    return out

