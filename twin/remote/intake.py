"""How much a connection may make `twin serve` hold before it has sent a whole request: one frame's
worth.

ZMQ hands a message to the server only once every part of it is in, and ZMQ_MAXMSGSIZE bounds each
part (frame) alone. So a peer sending one multipart message of many large parts, or request after
request without waiting for the replies, made ZMQ buffer all of it unseen: 12 parts of 200 MiB held
2.48 GB in the server before it could answer "12 message parts". The server cannot see a second part
arrive, so it measures instead. For each TCP connection it knows the bytes the kernel received
(`tcpi_bytes_received` of TCP_INFO, Linux) and the bytes of the whole messages it took from that
connection (frames and their ZMTP headers); the difference is what the connection has sent and the
server has not taken. When that exceeds MAX_UNREAD_BYTES (one frame at the hard cap MAX_FRAME_BYTES
plus the handshake's few bytes: a request is one frame, and a REQ client sends the next only after
its reply), the server shuts the connection down. ZMQ then reads end of file, drops the unfinished
message and frees it; the peer sees its connection close (there is no reply to give: its message
never ended). The measure is taken each time data arrives on a connection (edge-triggered epoll, in
a thread of its own: the server's loop does not wake for it), so what one connection makes the
server hold stays within about MAX_UNREAD_BYTES.

All connections together are bounded too: the server keeps each connection's last measured unread
bytes, and when their sum exceeds the server-wide limit (`twin serve --max-held-mib`, 256 MiB by
default) it shuts down the connection holding the most, then the next, until the sum is within it.
An ordinary client's requests are taken as they arrive (it holds next to nothing unread), so it is
never the one cut while a flooding connection holds more; any number of connections then cannot
make the server hold more than about that limit (plus what arrives while a measure reacts).

Where TCP_INFO or epoll is missing (not Linux), nothing is measured: each frame is still bounded by
MAX_FRAME_BYTES, a multipart message is not.
"""

from __future__ import annotations

import os
import select
import socket
import struct
import threading
from collections.abc import Iterable
from dataclasses import dataclass

# offset of the u64 tcpi_bytes_received in Linux's struct tcp_info (kernel >= 4.1)
_BYTES_RECEIVED_AT = 128
_TCP_INFO_LEN = _BYTES_RECEIVED_AT + 8


def wire_bytes(frames: Iterable) -> int:
    """Bytes these frames took on the wire: each its body and a ZMTP header (2 bytes up to 255, else
    9)."""
    return sum(len(f) + (2 if len(f) <= 255 else 9) for f in frames)


@dataclass(slots=True)
class _Connection:
    # getpeername(): tells this connection from a later one given the same descriptor number
    peer: tuple
    family: int
    taken: int = 0  # wire bytes of the whole messages the server received from it
    unread: int = 0  # received - taken at its last measure, less what was taken since
    cut: bool = False


class Intake:
    """Unread bytes per connection; over `limit`, the connection is shut down, and while all of
    them together are over `total_limit`, the one holding the most is (see the module docstring).

    The server reports, in order, each connection ZMQ accepted (its descriptor, from the socket
    monitor), each one that closed, and each message it received (the descriptor it came over,
    ZMQ_SRCFD); a thread of ours measures a connection whenever data arrives on it. Its status lines
    wait in `lines()` for the server's loop to print them (one writer: lines never interleave)."""

    def __init__(self, limit: int, total_limit: int | None = None) -> None:
        self.total_limit = limit if total_limit is None else total_limit
        self.limit = min(limit, self.total_limit)
        self._conns: dict[int, _Connection] = {}
        self._lock = threading.Lock()  # _conns: the server's loop reports, the thread measures
        self._lines: list[str] = []
        self._thread: threading.Thread | None = None
        self._epoll = (
            select.epoll() if hasattr(select, "epoll") and hasattr(socket, "TCP_INFO") else None
        )
        self._unmeasurable_said = self._epoll is None
        if self._epoll is None:
            self._lines.append(
                "note: this system offers no TCP_INFO/epoll: a multipart message is bounded per "
                "part only"
            )
            return
        self._wake_r, self._wake_w = os.pipe()  # a byte in it ends the thread
        self._epoll.register(self._wake_r, select.EPOLLIN)

    def start(self) -> None:
        """Measure from now on, in a thread (until close())."""
        if self._epoll is not None and self._thread is None:
            self._thread = threading.Thread(
                target=self._watch, name="twin-serve-intake", daemon=True
            )
            self._thread.start()

    def lines(self) -> list[str]:
        """Status lines to print (connections closed, notes), taken out."""
        if not self._lines:
            return []
        with self._lock:
            out, self._lines = self._lines, []
        return out

    def accepted(self, fd: int) -> None:
        if self._epoll is None:
            return
        with self._lock:
            probe = self._probe(fd, -1)
            if probe is None:
                return  # closed already (its DISCONNECTED follows), or no measure here
            peer, family, _ = probe
            conn = self._conns.get(fd)
            # the same connection (reported twice) keeps its count
            if conn is None or conn.peer != peer:
                self._conns[fd] = _Connection(peer, family)
            try:
                self._epoll.register(fd, select.EPOLLIN | select.EPOLLET)
            except FileExistsError:
                self._epoll.modify(fd, select.EPOLLIN | select.EPOLLET)
            except OSError:
                self._conns.pop(fd, None)
                return
            self._measure(fd)  # what arrived before it was registered

    def disconnected(self, fd: int) -> None:
        with self._lock:
            self._conns.pop(fd, None)  # epoll drops a closed descriptor by itself

    def took(self, fd: int, nbytes: int) -> None:
        """The server received a whole message of `nbytes` wire bytes over connection `fd`."""
        with self._lock:
            conn = self._conns.get(fd)
            if conn is not None:
                conn.taken += nbytes
                conn.unread = max(0, conn.unread - nbytes)

    def close(self) -> None:
        """End the thread, release the epoll and the pipe (once: a second call does nothing)."""
        epoll, self._epoll = self._epoll, None
        if epoll is None:
            return
        if self._thread is not None:
            os.write(self._wake_w, b"x")
            self._thread.join()
            self._thread = None
        epoll.close()
        os.close(self._wake_r)
        os.close(self._wake_w)
        self._conns.clear()

    def _watch(self) -> None:
        epoll = self._epoll
        while True:
            try:
                events = epoll.poll()
            except OSError:
                return  # closed under us
            for fd, _ in events:
                if fd == self._wake_r:
                    return
                try:
                    with self._lock:
                        self._measure(fd)
                except Exception as err:  # noqa: BLE001 - never end the thread: report it, go on measuring
                    with self._lock:
                        self._lines.append(
                            f"internal error measuring a connection: {type(err).__name__}: {err}"
                        )

    def _measure(self, fd: int) -> None:
        """Shut connection `fd` down if it is over the limit (called holding the lock)."""
        conn = self._conns.get(fd)
        if conn is None or conn.cut:
            return
        probe = self._probe(fd, conn.family)
        if probe is None or probe[0] != conn.peer:
            # that connection is gone; the monitor reports it (and any new one on this number)
            return
        received = probe[2]
        # a message counted against the wrong connection gives no credit
        conn.taken = min(conn.taken, received)
        conn.unread = received - conn.taken
        if conn.unread > self.limit:
            self._cut(fd, conn, f"over the limit of {self.limit} for one connection")
            return
        total = sum(c.unread for c in self._conns.values() if not c.cut)
        while total > self.total_limit:
            victim_fd, victim = max(
                ((f, c) for f, c in self._conns.items() if not c.cut), key=lambda fc: fc[1].unread
            )
            self._cut(
                victim_fd,
                victim,
                f"while all connections together held {total} bytes, over the server's limit "
                f"of {self.total_limit} (--max-held-mib)",
            )
            total -= victim.unread
            victim.cut = True  # also when it was gone already: its bytes no longer count

    def _cut(self, fd: int, conn: _Connection, why: str) -> None:
        """Shut connection `fd` down (the peer it was measured with only) and say why."""
        try:
            s = socket.socket(conn.family, socket.SOCK_STREAM, 0, fd)
        except OSError:
            return
        try:
            if s.getpeername() != conn.peer:
                return
            # ZMQ reads end of file, drops the unfinished message, closes
            s.shutdown(socket.SHUT_RDWR)
        except OSError:
            return
        finally:
            s.detach()  # the descriptor stays ZMQ's
        conn.cut = True
        where = ":".join(str(p) for p in conn.peer[:2])
        self._lines.append(
            f"closed the connection from {where}: it sent {conn.unread} bytes without completing "
            f"a message, {why} (a request is one frame; multipart messages and requests sent "
            "before the previous reply are refused once they exceed it)"
        )

    def _probe(self, fd: int, family: int) -> tuple[tuple, int, int] | None:
        """(peer address, address family, bytes received) of TCP socket `fd`, or None."""
        try:  # a family given spares two system calls; -1: find out
            s = (
                socket.socket(family, socket.SOCK_STREAM, 0, fd)
                if family != -1
                else socket.socket(fileno=fd)
            )
        except OSError:
            return None  # closed, or not a socket
        try:
            # (given a family, the type is ours; then TCP_INFO tells)
            if s.type != socket.SOCK_STREAM:
                return None
            peer = s.getpeername()
            info = s.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, _TCP_INFO_LEN)
            family = s.family
        except OSError:
            return None
        finally:
            s.detach()  # the descriptor stays ZMQ's
        if len(info) < _TCP_INFO_LEN:
            if not self._unmeasurable_said:
                self._unmeasurable_said = True
                self._lines.append(
                    "note: this kernel's TCP_INFO has no tcpi_bytes_received: a multipart message "
                    "is bounded per part only"
                )
            return None
        return peer, family, struct.unpack_from("=Q", info, _BYTES_RECEIVED_AT)[0]
