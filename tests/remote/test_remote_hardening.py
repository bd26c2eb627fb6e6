"""`twin serve` against hostile and broken peers: each case of the fault campaign, on the real
server process, with raw sockets (bytes the official client cannot produce) and the official client
(whose calls must keep getting their replies). No request may end the server or cost another client
its reply.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time
import uuid

import cbor2
import psutil
import pytest
import zmq
from support.raw_client import RawClient
from support.server import ServerProcess

from twin.remote.protocol import (
    DEFAULT_MAX_HELD_BYTES,
    MAX_FRAME_BYTES,
    MAX_ITEMS,
    MAX_NAME_CHARS,
    MAX_REQUEST_BYTES,
    MAX_SIGNALS,
    MAX_UNREAD_BYTES,
)
from twin.remote.server import EVICT_IDLE_S, MAX_CLIENTS, MAX_CLIENTS_PER_CONNECTION

pytestmark = pytest.mark.slow  # seconds each: `-m "not slow"` leaves them out

REPLY_TIMEOUT_S = 30.0  # generous: a reply that does not come within it never comes


@pytest.fixture(scope="module")
def server():
    with ServerProcess("--stepped") as s:
        yield s


@pytest.fixture
def raw(server):
    c = RawClient(server.port)
    yield c
    c.close()


def request(raw: RawClient, func, args=(), **extra) -> bytes:
    return cbor2.dumps(
        {"func": func, "args": list(args), "argsL": len(args), "uuid": raw.uuid, **extra}
    )


def assert_serving(server: ServerProcess) -> None:
    """The process is alive and the official client gets its replies."""
    assert server.proc.poll() is None, "the server ended"
    sim = server.client().require("sim")
    assert sim.getSimulationState() == sim.simulation_stopped


def rss_kib(server: ServerProcess) -> int:
    with open(f"/proc/{server.proc.pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))


def test_integers_too_long_to_print_get_an_error_reply(server, raw):
    huge = 10**5000  # 2 KB of CBOR; repr() refuses more than 4300 digits
    for data, expected in [
        (
            cbor2.dumps({"func": huge, "args": [], "uuid": raw.uuid}),
            "'func' must be a non-empty string, got an integer of",
        ),
        (request(raw, "sim.getSimulationState", argsL=huge), "'argsL' an integer of 16610 bits"),
        (
            request(raw, "sim.getSimulationState", ver=huge),
            "protocol version an integer of 16610 bits",
        ),
        (
            request(raw, "sim.getJointPosition", [huge]),
            "argument 1 (handle) is an integer of 16610 bits",
        ),
        (request(raw, "sim.setInt32Signal", ["s", huge]), "expected an integer (64-bit)"),
        (request(raw, "sim.setJointPosition", [11, huge]), "expected a finite number"),
    ]:
        assert expected in raw.raw(data)["err"], expected
    assert_serving(server)


def shared_reference_bomb(depth: int) -> bytes:
    """A request whose argument is [x, x] nested `depth` times through CBOR shared references
    (tags 28/29): 2**depth leaves from a few bytes per level."""
    value = b"\xd8\x1c\x80"  # 28([]): shareable number `depth` (numbered outermost first)
    for level in range(1, depth + 1):
        # 28([inner, 29(inner)])
        value = b"\xd8\x1c\x82" + value + b"\xd8\x1d" + cbor2.dumps(depth - level + 1)
    head = cbor2.dumps({"func": "sim.getJointPosition", "argsL": 1, "uuid": "bomb"})
    return bytes([head[0] + 1]) + head[1:] + cbor2.dumps("args") + b"\x81" + value


def test_shared_references_are_refused_before_they_multiply(server, raw):
    bomb = shared_reference_bomb(26)
    assert len(bomb) < 250
    reply = raw.raw(bomb)  # the old server formatted 2**26 leaves into the error: 23 s, 0.5 GB
    assert "CBOR tag 28 is not accepted" in reply["err"] or "nesting depth (32)" in reply["err"], (
        reply
    )
    assert "CBOR tag 28 is not accepted" in raw.raw(shared_reference_bomb(3))["err"]
    tagged = cbor2.dumps(
        {"func": "sim.addLog", "args": [600, cbor2.CBORTag(1000, "x")], "uuid": raw.uuid}
    )
    assert "CBOR tag 1000 is not accepted" in raw.raw(tagged)["err"]
    assert raw.raw(request(raw, "sim.getObjectAlias", [2**64 + 11]))["err"].endswith(
        "expected an integer (64-bit)"
    )
    assert_serving(server)


def test_what_is_decoded_is_bounded_in_depth_and_items(server, raw):
    assert "nesting depth (32)" in raw.raw(b"\x81" * 40 + b"\x00")["err"]
    many = request(raw, "sim.getJointPosition", [[0] * (MAX_ITEMS + 1)])
    assert len(many) < MAX_REQUEST_BYTES
    assert f"more than {MAX_ITEMS} data items" in raw.raw(many)["err"]
    # under the limit: decoded
    strings = request(raw, "sim.getJointPosition", [["ab"] * (MAX_ITEMS // 2)])
    assert "argument 1 (handle) is an array of 50000 items" in raw.raw(strings)["err"]
    keyed = cbor2.dumps({"func": "sim.getObject", "args": ["/box", {1: True}], "uuid": raw.uuid})
    assert "map key must be a text string or byte string" in raw.raw(keyed)["err"]
    assert_serving(server)


# ZMTP 2.0 greeting (signature, revision 1, socket type DEALER, empty identity), then a message of
# two frames without the empty delimiter a REQ puts first: 21 bytes. Sent by a peer that closes at
# once, it left the old REP socket's envelope state half-written and the next reply to another
# client lost.
ZMTP2_NO_DELIMITER = (
    b"\xff" + b"\x00" * 8 + b"\x7f" + b"\x01\x05\x00\x00" + b"\x01\x01X" + b"\x00\x02YZ"
)
BROKEN_PEERS = {
    "zmtp2 frames without delimiter": ZMTP2_NO_DELIMITER,
    "zmtp1 frames without delimiter": b"\x01\x00" + b"\x02\x01X" + b"\x03\x00YZ",
    "zmtp2 delimiter then nothing": ZMTP2_NO_DELIMITER[:14] + b"\x01\x00",
    "garbage": b"GET / HTTP/1.0\r\n\r\n",
}


def test_a_broken_peer_never_costs_another_client_its_reply(server):
    assert len(ZMTP2_NO_DELIMITER) == 21
    sim = server.client().require("sim")
    h = sim.getObject("/MTB_axis1")
    done = threading.Event()
    errors: list[BaseException] = []

    def calls() -> None:  # the official client: a lost reply would block it forever
        try:
            for _ in range(300):
                sim.getJointPosition(h)
            done.set()
        except BaseException as err:  # noqa: BLE001 - reported by the assertion below
            errors.append(err)

    thread = threading.Thread(target=calls, daemon=True)
    thread.start()
    for _ in range(5):
        for data in BROKEN_PEERS.values():
            with socket.create_connection(("127.0.0.1", server.port)) as peer:
                peer.sendall(data)
    assert done.wait(REPLY_TIMEOUT_S), f"the official client lost a reply (errors: {errors})"
    for name, data in BROKEN_PEERS.items():  # and after each, one call at a time
        with socket.create_connection(("127.0.0.1", server.port)) as peer:
            peer.sendall(data)
        assert sim.getJointPosition(h) == 0.0, name
    assert_serving(server)


def test_a_dealer_peer_is_answered_on_its_own_envelope(server):
    context = zmq.Context()
    dealer = context.socket(zmq.DEALER)
    dealer.setsockopt(zmq.LINGER, 0)
    dealer.setsockopt(zmq.RCVTIMEO, 10_000)
    dealer.connect(f"tcp://127.0.0.1:{server.port}")
    try:
        req = cbor2.dumps({"func": "sim.getSimulationState", "args": [], "uuid": str(uuid.uuid4())})
        dealer.send(req)  # no delimiter: the reply comes the same way
        assert [cbor2.loads(p) for p in dealer.recv_multipart()] == [{"ret": [0]}]
        dealer.send_multipart([b"", req])
        reply = dealer.recv_multipart()
        assert reply[0] == b"" and cbor2.loads(reply[1]) == {"ret": [0]}
        dealer.send_multipart([b"", req, req])
        assert "2 message parts" in cbor2.loads(dealer.recv_multipart()[1])["err"]
    finally:
        dealer.close()
        context.term()


def test_long_signal_names_are_refused_and_not_kept(server):
    sim = server.client().require("sim")
    rss_before = rss_kib(server)
    name = "n" * ((1 << 20) - 256)  # the request stays under 1 MiB
    for _ in range(150):  # the old server kept each: RSS 80 -> 250 MB
        with pytest.raises(
            Exception, match=f"signalName.*expected a string of at most {MAX_NAME_CHARS} characters"
        ):
            sim.setInt32Signal(name, 1)
    assert rss_kib(server) - rss_before < 50_000
    sim.setInt32Signal("n" * MAX_NAME_CHARS, 7)
    assert sim.getInt32Signal("n" * MAX_NAME_CHARS) == 7
    sim.clearInt32Signal("n" * MAX_NAME_CHARS)


def test_the_number_of_signals_is_bounded(server):
    sim = server.client().require("sim")
    try:
        for i in range(MAX_SIGNALS):
            sim.setInt32Signal(f"s{i}", i)
        with pytest.raises(Exception, match=f"already holds {MAX_SIGNALS} signals"):
            sim.setInt32Signal("one_more", 1)
        sim.setInt32Signal("s0", 5)  # an existing one may change
        sim.clearInt32Signal("s1")
        sim.setInt32Signal("one_more", 1)  # a freed slot
    finally:
        for i in range(MAX_SIGNALS):
            sim.clearInt32Signal(f"s{i}")
        sim.clearInt32Signal("one_more")


def test_log_messages_are_bounded_and_printed_on_one_line(server):
    sim = server.client().require("sim")
    with pytest.raises(Exception, match="logMessage.*expected a string of at most 4096 characters"):
        sim.addLog(sim.verbosity_scriptinfos, "x" * 5000)
    forged = "hello\ntwin serve: shutting down\r\x1b[2K\u202eevil"
    sim.addLog(sim.verbosity_scriptinfos, forged)
    line = server.wait_for(r"\[info\] client \d+: hello")
    assert line.endswith(r"hello\ntwin serve: shutting down\r\x1b[2K\u202eevil")
    raw = RawClient(server.port)
    try:
        func = "sim.nothing\ntwin serve: forged"
        assert raw.call(func, [])["err"] == r"No such function: sim.nothing\ntwin serve: forged"
        raw.raw(cbor2.dumps({"func": func, "args": 5, "uuid": raw.uuid}))
        server.wait_for(
            r"refused a request: malformed request to sim\.nothing\\ntwin serve: forged: 'args'"
        )
        other = RawClient(server.port)
        other.call("sim.getSimulationState", [], ver=2, lang="py\nthon", timeout=600)
        server.wait_for(r"connected \(uuid .{8}, py\\nthon\)")
        other.close()
    finally:
        raw.close()
    assert not [
        ln
        for ln in server.lines
        if ln.startswith(("twin serve: forged", "twin serve: shutting down"))
    ]
    assert_serving(server)


def test_the_number_of_clients_is_bounded_per_connection_and_in_all():
    with ServerProcess("--stepped") as server:
        first = server.client().require("sim")
        one = RawClient(server.port)
        many: list[RawClient] = []
        # closed whatever happens: a failed test's unclosed zmq contexts hang the session when
        # collected
        try:
            # each new uuid over one connection would be a client (old: 40,000 of them)
            for i in range(1000):
                reply = one.raw(
                    cbor2.dumps({"func": "sim.getSimulationState", "args": [], "uuid": f"u{i}"})
                )
                if i < MAX_CLIENTS_PER_CONNECTION:
                    assert reply == {"ret": [0]}
                else:
                    assert "too many clients on one connection" in reply["err"]
            # the official client holds one slot
            for _ in range(MAX_CLIENTS - MAX_CLIENTS_PER_CONNECTION - 1):
                many.append(RawClient(server.port))
                assert many[-1].call("sim.getSimulationState", []) == {"ret": [0]}
            # every slot now held by a client seen less than EVICT_IDLE_S ago: none gives its slot
            # up
            assert first.getSimulationState() == 0
            for i in range(MAX_CLIENTS_PER_CONNECTION):
                request = {"func": "sim.getSimulationState", "args": [], "uuid": f"u{i}"}
                assert one.raw(cbor2.dumps(request)) == {"ret": [0]}
            for c in many:
                assert c.call("sim.getSimulationState", []) == {"ret": [0]}
            many.append(RawClient(server.port))
            refused = many[-1].call("sim.getSimulationState", [])["err"]
            assert refused.startswith(f"too many clients: {MAX_CLIENTS} are connected (the limit)")
            assert f"the least recently seen one silent for {EVICT_IDLE_S:g} s or more" in refused
            with pytest.raises(Exception, match="too many clients"):
                server.client().require("sim")
            assert first.getSimulationState() == 0  # a known client goes on
        finally:
            for c in [*many, one]:
                c.close()
        server.wait_for(rf"client {MAX_CLIENTS} disconnected")
        # their slots are free again
        assert server.client().require("sim").getSimulationState() == 0


def test_idle_clients_cannot_lock_the_official_client_out():
    """16 connections x 4 uuids took all 64 slots and held them while open (the official client got
    "too many clients" until they closed). Now, with all slots taken, a new client takes the slot of
    the least recently seen one silent for EVICT_IDLE_S or more."""
    with ServerProcess("--stepped") as server:
        idle = [RawClient(server.port) for _ in range(MAX_CLIENTS // MAX_CLIENTS_PER_CONNECTION)]
        try:
            for i, c in enumerate(idle):
                for j in range(MAX_CLIENTS_PER_CONNECTION):  # a timeout of 115 days: never reaped
                    request = {
                        "func": "sim.getSimulationState",
                        "args": [],
                        "uuid": f"idle-{i}-{j}",
                        "ver": 2,
                        "lang": "python",
                        "timeout": 9_999_999,
                    }
                    assert c.raw(cbor2.dumps(request)) == {"ret": [0]}
            filled = time.monotonic()
            with pytest.raises(Exception, match="too many clients") as refused:  # all seen just now
                server.client().require("sim")
            time.sleep(max(0.0, filled + EVICT_IDLE_S + 0.1 - time.monotonic()))
            t0 = time.monotonic()
            sim = server.client().require("sim")  # two requests, then calls: one slot is enough
            h = sim.getObject("/MTB_axis1")
            sim.setJointPosition(h, 0.25)
            assert sim.getJointPosition(h) == pytest.approx(0.25)
            served_s = time.monotonic() - t0
            server.wait_for(
                rf"client \d+ forgotten: silent for \d+\.\d s while all {MAX_CLIENTS} "
                rf"client slots were taken"
            )
            # the rule is in the refusal's text; the official client got in at once, not after a
            # timeout
            assert (
                f"when all slots are taken, a new client takes the slot of the least "
                f"recently seen one silent "
                f"for {EVICT_IDLE_S:g} s or more"
            ) in str(refused.value)
            assert served_s < 5.0
            # the idle ones, their connections still open, are served again when they call (as new
            # clients, taking idle slots in turn)
            request = {"func": "sim.getSimulationState", "args": [], "uuid": "idle-0-0"}
            assert idle[0].raw(cbor2.dumps(request)) == {"ret": [0]}
            assert sim.getSimulationState() == 0
        finally:
            for c in idle:
                c.close()


class PeakRss:
    """The highest resident set size of a process while in the block, sampled every 2 ms
    (psutil)."""

    def __init__(self, pid: int) -> None:
        self.proc = psutil.Process(pid)
        self.base = self.peak = self.proc.memory_info().rss
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def _sample(self) -> None:
        while not self._done.wait(0.002):
            self.peak = max(self.peak, self.proc.memory_info().rss)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._done.set()
        self._thread.join()

    def growth_mb(self) -> float:
        return (self.peak - self.base) / 1e6


# 1200 MiB in parts each under the per-frame cap: a server that held the whole message is far
# above what a cut-off one holds
FLOOD_PARTS, FLOOD_PART_BYTES = 12, 100 << 20


def keep_calling(sim, stop: threading.Event, errors: list) -> threading.Thread:
    """The official client calling all along (in a thread): its calls must all be answered."""

    def calls() -> None:
        try:
            while not stop.is_set():
                assert sim.getSimulationState() == 0
                time.sleep(0.005)
        except BaseException as err:  # noqa: BLE001 - reported by the test
            errors.append(err)

    thread = threading.Thread(target=calls, daemon=True)
    thread.start()
    return thread


def test_a_multipart_flood_is_cut_off_after_one_frames_worth():
    """ZMQ hands a message over only once all its parts are in (12 x 200 MiB parts: 2.48 GB in the
    old server before its "12 message parts" reply). Now a connection whose unfinished message
    exceeds one frame's worth (MAX_UNREAD_BYTES) is shut down; the server frees it and goes on
    serving."""
    assert FLOOD_PART_BYTES < MAX_FRAME_BYTES < FLOOD_PARTS * FLOOD_PART_BYTES
    with ServerProcess("--stepped") as server:
        sim = server.client().require("sim")
        context = zmq.Context()
        dealer = context.socket(zmq.DEALER)
        dealer.setsockopt(zmq.LINGER, 0)
        dealer.connect(f"tcp://127.0.0.1:{server.port}")
        stop, errors = threading.Event(), []
        part = bytes(FLOOD_PART_BYTES)
        try:
            with PeakRss(server.proc.pid) as rss:
                caller = keep_calling(sim, stop, errors)
                t0 = time.monotonic()
                # a REQ's framing, 6 parts
                dealer.send_multipart([b"", *[part] * FLOOD_PARTS], copy=False)
                # the old server answered once all of it was in; now the connection closes
                while True:
                    if dealer.poll(0):
                        reply = cbor2.loads(dealer.recv_multipart()[-1])
                        break
                    try:
                        reply = server.wait_for(
                            r"closed the connection from 127\.0\.0\.1:\d+: it sent \d+ bytes "
                            r"without completing a message",
                            0.05,
                        )
                        break
                    except AssertionError:
                        assert time.monotonic() - t0 < 20.0, (
                            "neither a reply nor the connection closed"
                        )
                elapsed_s = time.monotonic() - t0
                time.sleep(0.2)
                stop.set()
                caller.join(10)
            print(
                f"multipart flood: peak RSS +{rss.growth_mb():.0f} MB over "
                f"{rss.base / 1e6:.0f} MB, "
                f"{elapsed_s:.2f} s; {reply}"
            )
            # ZMQ takes in a part's bytes as fast as loopback brings them while the server's
            # measure reacts: 267 to 470 MB measured over 20 runs (6 parts; 2 of 6 runs failed a
            # bound of MAX_UNREAD_BYTES + 24 MiB), against the whole 1258 MB message held before
            assert rss.growth_mb() < (MAX_UNREAD_BYTES + 3 * FLOOD_PART_BYTES) / 1e6  # < 583 MB
            assert "closed the connection" in str(reply)
            assert not errors, errors  # the official client was answered all along
            deadline = time.monotonic() + 10.0  # ZMQ freed the unfinished message
            while rss.proc.memory_info().rss - rss.base > 50e6:
                assert time.monotonic() < deadline, "the unfinished message was not freed"
                time.sleep(0.05)
            assert_serving(server)
            assert sim.getSimulationState() == 0
        finally:
            stop.set()
            dealer.close()
            context.term()


FLOODERS, FLOOD_MESSAGE_PARTS, FLOOD_BIG_PART = 8, 6, 200 << 20


def test_many_flooding_connections_stay_under_the_server_wide_cap():
    """8 connections each sending a multipart message of 6 x 200 MiB: per connection each may
    hold one frame's worth, but all of them together stay within the server-wide cap (256 MiB by
    default): the connection holding the most is closed, the official client is served
    throughout, and the server's peak memory stays under 700 MB."""
    assert DEFAULT_MAX_HELD_BYTES == 256 << 20
    with ServerProcess("--stepped") as server:
        sim = server.client().require("sim")
        context = zmq.Context()
        part = bytes(FLOOD_BIG_PART)  # one buffer, sent zero-copy by every dealer
        dealers = []
        stop, errors = threading.Event(), []
        try:
            with PeakRss(server.proc.pid) as rss:
                caller = keep_calling(sim, stop, errors)
                t0 = time.monotonic()
                for _ in range(FLOODERS):
                    dealer = context.socket(zmq.DEALER)
                    dealer.setsockopt(zmq.LINGER, 0)
                    dealer.setsockopt(zmq.RECONNECT_IVL, -1)  # a closed flooder stays closed
                    dealer.connect(f"tcp://127.0.0.1:{server.port}")
                    dealer.send_multipart([b"", *[part] * FLOOD_MESSAGE_PARTS], copy=False)
                    dealers.append(dealer)
                closed = 0
                while closed < FLOODERS:
                    assert time.monotonic() - t0 < 60.0, "\n".join(server.lines[-5:])
                    with contextlib.suppress(AssertionError):  # read the output for 0.2 s
                        server.wait_for(r"(?!)", 0.2)
                    closed = sum("closed the connection from" in line for line in server.lines)
                elapsed_s = time.monotonic() - t0
                time.sleep(0.2)
                stop.set()
                caller.join(10)
            cut_all = [line for line in server.lines if "over the server's limit" in line]
            print(
                f"{FLOODERS} multipart floods: peak RSS {rss.peak / 1e6:.0f} MB (base "
                f"{rss.base / 1e6:.0f} MB, +{rss.growth_mb():.0f} MB), {elapsed_s:.2f} s, "
                f"{len(cut_all)} of {closed} closed by the server-wide cap"
            )
            assert rss.peak < 700e6
            assert cut_all, server.lines[-FLOODERS:]
            assert not errors, errors  # the official client was answered all along
            assert_serving(server)
        finally:
            stop.set()
            for dealer in dealers:
                dealer.close()
            context.term()


# A ZMTP 3.1 REQ peer's greeting and READY, as libzmq 4.3 sends them
ZMTP31_REQ_HANDSHAKE = (
    b"\xff"
    + b"\x00" * 7
    + b"\x01\x7f\x03\x01"
    + b"NULL".ljust(20, b"\x00")
    + b"\x00" * 32
    + b"\x04&\x05READY\x0bSocket-Type\x00\x00\x00\x03REQ\x08Identity\x00\x00\x00\x00"
)


def test_a_raw_peer_ignoring_the_close_cannot_make_the_server_buffer_more():
    """A hostile peer speaking ZMTP itself goes on sending parts after the server closes its side:
    the server reads end of file regardless, drops the message, and the peer's writes fail."""
    with ServerProcess("--stepped") as server:
        with (
            PeakRss(server.proc.pid) as rss,
            socket.create_connection(("127.0.0.1", server.port)) as peer,
        ):
            peer.sendall(ZMTP31_REQ_HANDSHAKE)
            greeting = b""
            while len(greeting) < 64 + 40:  # the server's greeting and READY, before any frame
                greeting += peer.recv(4096)
            peer.sendall(b"\x01\x00")  # the delimiter, then parts of 16 MiB, each with "more"
            chunk, sent = bytes(16 << 20), 0
            header = b"\x03" + struct.pack(">Q", len(chunk))
            t0 = time.monotonic()
            with pytest.raises(OSError):  # EPIPE or ECONNRESET once the server closed
                while sent < FLOOD_PARTS * FLOOD_PART_BYTES:
                    peer.sendall(header + chunk)
                    sent += len(chunk)
            elapsed_s = time.monotonic() - t0
        print(
            f"raw flood: {sent >> 20} MiB sent in {elapsed_s:.2f} s, peak RSS "
            f"+{rss.growth_mb():.0f} MB"
        )
        # what the kernels' buffers took after the close, and what arrived while the server's
        # measure reacted (352 and 386 MB seen with the other flood test running beside it: 4 of
        # 6 runs of this file at 2ab2bed failed a bound of + 32 MiB); without the cut-off all
        # 1258 MB go in
        assert sent < MAX_UNREAD_BYTES + FLOOD_PART_BYTES + (64 << 20)
        # the cap, plus what ZMQ and the allocator hold beside it and what arrives while the
        # measure reacts: +269 to +339 MB measured (a bound of + 48 MiB failed beside the other
        # flood test)
        assert rss.growth_mb() < (MAX_UNREAD_BYTES + FLOOD_PART_BYTES + (64 << 20)) / 1e6
        server.wait_for(
            r"closed the connection from 127\.0\.0\.1:\d+: it sent \d+ bytes without completing"
        )
        assert_serving(server)


def zmtp3_req_with_frame_header(size: int) -> bytes:
    """A ZMTP 3.0 REQ peer's greeting and READY, then a delimiter and the head of a `size`-byte
    frame."""
    greeting = (
        b"\xff"
        + b"\x00" * 8
        + b"\x7f"
        + b"\x03\x00"
        + b"NULL".ljust(20, b"\x00")
        + b"\x00"
        + b"\x00" * 31
    )
    ready = b"\x05READY" + b"\x0bSocket-Type" + struct.pack(">I", 3) + b"REQ"
    return (
        greeting
        + bytes([0x04, len(ready)])
        + ready
        + b"\x01\x00"
        + b"\x02"
        + struct.pack(">Q", size)
    )


def test_requests_over_the_limit_get_an_error_reply_up_to_the_hard_cap(server, raw):
    for size in (MAX_REQUEST_BYTES + 1, 10 << 20, (64 << 20) + 1, 65 << 20):
        reply = raw.raw(b"\x00" * size)
        assert (
            reply["err"]
            == f"request of {size} bytes exceeds the limit of {MAX_REQUEST_BYTES} bytes (1 MiB)"
        )
    assert raw.call("sim.getSimulationState", []) == {"ret": [0]}
    # above the hard cap ZMQ closes the connection when the frame's head announces its size: nothing
    # of it is read or kept, and the server goes on (a REQ client would wait forever: README)
    rss_before = rss_kib(server)
    for size in (MAX_FRAME_BYTES + 1, 1 << 40):
        with socket.create_connection(("127.0.0.1", server.port)) as peer:
            peer.settimeout(REPLY_TIMEOUT_S)
            peer.sendall(zmtp3_req_with_frame_header(size))
            received = b""
            while chunk := _recv_or_reset(peer):
                received += chunk
            assert len(received) < 200  # the server's greeting and READY, no reply: then the close
    assert rss_kib(server) - rss_before < 50_000
    assert_serving(server)


def _recv_or_reset(peer: socket.socket) -> bytes:
    try:
        return peer.recv(4096)
    except ConnectionResetError:
        return b""


def test_step_grace_is_an_option():
    with ServerProcess("--stepped", "--step-grace", "0.5") as server:
        silent = server.client().require("sim")
        silent.setStepping(True)  # then says nothing more
        label = server.wait_for(r"client \d+ connected").split(" connected")[0]
        sim = server.client().require("sim")
        sim.setStepping(True)
        sim.startSimulation()
        sim.step()  # waits for the silent client 0.5 s, not 10
        server.wait_for(
            rf"{label} silent for 0.5 s \(--step-grace\): no longer holds back stepping"
        )
        sim.stopSimulation()


def test_a_cyclic_joint_reads_back_in_minus_pi_to_pi_as_coppeliasim_reports_it():
    """The seeds' CoppeliaSim joints are cyclic: report 000's shoulder goes to +218 deg, read back
    -142."""
    import math

    with ServerProcess("--stepped", "--robot", "seed000") as server:
        sim = server.client().require("sim")
        shoulder = sim.getObject("/joint1")
        sim.startSimulation()
        sim.setJointPosition(shoulder, math.radians(218.0))
        sim.setStepping(True)
        sim.step()
        assert sim.getJointPosition(shoulder) == pytest.approx(
            math.radians(218.0 - 360.0), abs=1e-6
        )
        sim.stopSimulation()


def test_a_stopped_simulation_holds_a_bounded_number_of_commands_then_refuses_with_a_reply(
    tmp_path,
):
    from twin.record.mcap.reader import load
    from twin.remote.session import MAX_PENDING_COMMANDS

    record = tmp_path / "held.mcap"
    with ServerProcess("--stepped", "--record", str(record)) as server:
        sim = server.client().require("sim")
        shoulder = sim.getObject("/MTB_axis1")
        for i in range(MAX_PENDING_COMMANDS):  # while stopped: each is held for the next run
            sim.setJointTargetPosition(shoulder, 0.001 * (i % 100))
        with pytest.raises(Exception, match="already holds 10000 commands for its next run"):
            sim.setJointTargetPosition(shoulder, 0.5)
        sim.startSimulation()  # the held commands go into the run; new ones are taken again
        sim.setJointTargetPosition(shoulder, 0.5)
        sim.setStepping(True)
        sim.step()
        sim.stopSimulation()
        server.wait_for(r"recorded .*held\.mcap")
    commands = [c for c in load(record).commands if c.kind == "joint_target"]
    assert len(commands) == MAX_PENDING_COMMANDS + 1 and commands[-1].args["q"] == 0.5


def test_the_eviction_rule_in_detail():
    """In process, at chosen times: only when all slots are taken, only a client silent for
    EVICT_IDLE_S, least recently seen first, a stepping one only after --step-grace, the
    per-connection cap first."""
    from twin.model.config import TwinConfig
    from twin.remote.server import Server
    from twin.remote.session import Scene

    lines: list[str] = []
    scene = Scene(TwinConfig(), mode="stepped", log=lines.append)
    server = Server(scene, port=0, mode="stepped", step_grace_s=10.0, log=lines.append)

    def call(
        uuid: str, now: float, peer: bytes, func: str = "sim.getSimulationState", args=()
    ) -> dict:
        return cbor2.loads(
            server.handle(cbor2.dumps({"func": func, "args": list(args), "uuid": uuid}), now, peer)
        )

    try:
        for i in range(MAX_CLIENTS):  # client c<i> seen at i ms, 4 per connection
            assert call(f"c{i}", i / 1000, f"p{i // MAX_CLIENTS_PER_CONNECTION}".encode()) == {
                "ret": [0]
            }
        # c0 steps, seen at 0.5 s
        assert call("c0", 0.5, b"p0", "sim.setStepping", [True]) == {"ret": [0]}
        # nobody idle 2 s yet
        assert "none silent long enough" in call("n1", EVICT_IDLE_S - 0.1, b"q")["err"]
        # c1 (2.0005 s idle) gives way, c2 not yet
        assert call("n1", EVICT_IDLE_S + 0.0015, b"q") == {"ret": [0]}
        assert "c1" not in server.clients and "c2" in server.clients
        assert lines[-2].endswith(
            f"client 2 forgotten: silent for 2.0 s while all {MAX_CLIENTS} client slots "
            "were taken (a new client takes its slot)"
        )
        assert call("n2", EVICT_IDLE_S + 0.0025, b"q") == {"ret": [0]}  # then c2
        # c3, c4
        assert call("n3", 3.0, b"q") == {"ret": [0]} and call("n4", 3.0, b"q") == {"ret": [0]}
        assert not {"c1", "c2", "c3", "c4"} & set(server.clients) and "c5" in server.clients
        # the per-connection cap comes first: no one is evicted for a fifth uuid over one connection
        assert "too many clients on one connection" in call("n5", 100.0, b"q")["err"]
        assert len(server.clients) == MAX_CLIENTS and "c5" in server.clients
        # at 5 s: the plain clients seen at 0.005..0.063 s go, oldest first
        for i in range(5, MAX_CLIENTS):
            assert call(f"late{i}", 5.0, f"r{i}".encode()) == {"ret": [0]}
            assert f"c{i}" not in server.clients and "n1" in server.clients
        # c0 is now the least recently seen (0.5 s), but in stepping mode it keeps its slot for
        # --step-grace
        assert call("x1", 10.4, b"s") == {"ret": [0]}
        assert "c0" in server.clients and "n1" not in server.clients
        assert call("x2", 10.6, b"s") == {"ret": [0]}
        assert "c0" not in server.clients  # silent 10.1 s: it gave way
        # a known client is served as ever, nobody evicted
        assert call("n2", 10.7, b"q") == {"ret": [0]}
        # back: a new client, not stepping
        assert call("c0", 10.8, b"p0", "sim.setStepping", [False]) == {"ret": [0]}
        assert len(server.clients) == MAX_CLIENTS
    finally:
        server.close()
