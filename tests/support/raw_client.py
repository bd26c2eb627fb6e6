"""A bare ZeroMQ REQ client for `twin serve`: sends any bytes, for malformed requests the official
client never sends (protocol and hardening tests)."""

from __future__ import annotations

import uuid

import cbor2
import zmq


class RawClient:
    """A bare REQ socket: sends any bytes, returns the decoded reply map."""

    def __init__(self, port: int) -> None:
        self.context = zmq.Context()
        self.socket = self.context.socket(zmq.REQ)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.RCVTIMEO, 10_000)
        self.socket.connect(f"tcp://127.0.0.1:{port}")
        self.uuid = str(uuid.uuid4())

    def raw(self, data: bytes) -> dict:
        self.socket.send(data)
        return cbor2.loads(self.socket.recv())

    def call(self, func: str, args: list, **extra) -> dict:
        return self.raw(
            cbor2.dumps(
                {"func": func, "args": args, "argsL": len(args), "uuid": self.uuid, **extra}
            )
        )

    def close(self) -> None:
        self.socket.close()
        self.context.term()
