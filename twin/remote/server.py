"""`twin serve`: a ZeroMQ server speaking CoppeliaSim's remote API (protocol v2) over a Scene.

Socket: ROUTER, not REP. The official client's REQ socket puts an empty delimiter frame before its
request; ROUTER hands us each message with its connection's routing id, and we answer on that
envelope. A REP socket keeps one envelope state for all peers, so a peer sending broken framing (a
frame without the delimiter, then closing) made it drop the next reply to another client.

Time: in realtime mode the twin follows the wall clock (times `speed`): before each request and on
idle poll timeouts it steps up to floor(elapsed_wall * speed / dt). While any client is in stepping
mode (sim.setStepping(True)), and always in stepped mode, the twin advances only on sim.step(),
once every stepping client has asked for its next step. Wall-clock time never enters the twin:
every call that changes it is a Command stamped with the step it took effect at.

Bounds on what peers can make the server hold:
- Bytes: each frame is at most MAX_FRAME_BYTES (ZMQ closes a connection announcing a bigger one),
  and each connection may have sent at most MAX_UNREAD_BYTES that the server has not yet taken as
  whole messages (one frame's worth). Over that, the server shuts the connection down (intake.py):
  ZMQ hands a multipart message over only once all its parts are in, so this is what stops a peer
  from making it buffer an endless multipart message (or requests sent without waiting for the
  replies). All connections together may hold at most max_held_bytes (DEFAULT_MAX_HELD_BYTES, 256
  MiB): over it, the connection holding the most is shut down, and the others are served.
- Clients: at most MAX_CLIENTS uuids at once, MAX_CLIENTS_PER_CONNECTION per connection. A client is
  forgotten when its connection closes or after its own timeout; and when all MAX_CLIENTS slots are
  taken, a new uuid takes the slot of the least recently seen client that has been silent for at
  least EVICT_IDLE_S (a client in stepping mode: --step-grace), so idle connections cannot lock
  others out. A forgotten client that calls again is served as a new one (stepping off).
"""

from __future__ import annotations

import math
import signal
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass

import zmq
from zmq.utils.monitor import parse_monitor_message

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError, TwinError
from twin.remote import DEFAULT_STEP_GRACE_S, STEP_GRACE_RANGE_S
from twin.remote.intake import Intake, wire_bytes
from twin.remote.protocol import (
    DEFAULT_MAX_HELD_BYTES,
    EMPTY_REPLY,
    MAX_FRAME_BYTES,
    MAX_REQUEST_BYTES,
    MAX_UNREAD_BYTES,
    WAIT_REPLY,
    Param,
    RequestError,
    Signature,
    VersionMismatch,
    brief_value,
    check_args,
    decode,
    encode_err,
    encode_ret,
    encode_version_mismatch,
    printable,
    safe_str,
)
from twin.remote.session import Scene
from twin.remote.sim_api import SimApi

MODES = ("realtime", "stepped")
IDLE_POLL_S = 0.1
# simulated seconds owed beyond which the twin stops catching up (slow machine): time slips
MAX_LAG_S = 0.25
DEFAULT_CLIENT_TIMEOUT_S = 600.0
WAIT_BACKOFF_S = 0.0002  # before repeating _*wait*_ to a client whose step has not come yet
# uuids served at once; a client is forgotten when its connection closes or it times out
MAX_CLIENTS = 64
MAX_CLIENTS_PER_CONNECTION = 4  # the official client sends one uuid per connection
# all slots taken: a new client takes the slot of the least recently seen one silent this long
EVICT_IDLE_S = 2.0
# requests queued per connection (a REQ client has one at a time): bounds what a peer can park
RCVHWM = 4


@dataclass(slots=True)
class _Client:
    label: str
    last_seen_s: float
    timeout_s: float
    stepping: bool = False
    wants_step: bool = False
    wait_until_step: int = -1  # the step its pending sim.step() waits for; -1: none
    peer: bytes = b""  # the routing id of the connection its last request came over


class Server:
    """One ROUTER socket, one Scene; serves requests until stop() is called.

    What a peer can make it hold is bounded (module docstring): MAX_FRAME_BYTES per frame and
    MAX_UNREAD_BYTES per connection (a connection over it is shut down); MAX_CLIENTS clients,
    MAX_CLIENTS_PER_CONNECTION per connection, and when all slots are taken a new client takes the
    slot of the least recently seen one silent for EVICT_IDLE_S or more (step_grace_s if it is
    stepping).
    """

    def __init__(
        self,
        scene: Scene,
        *,
        host: str = "127.0.0.1",
        port: int = 23000,
        mode: str = "realtime",
        speed: float = 1.0,
        step_grace_s: float = DEFAULT_STEP_GRACE_S,
        log: Callable[[str], None] = print,
        max_held_bytes: int = DEFAULT_MAX_HELD_BYTES,
    ) -> None:
        if mode not in MODES:
            raise ConfigError(
                f"server mode {mode!r} is unknown; expected one of {', '.join(MODES)}"
            )
        if not (math.isfinite(speed) and 0.01 <= speed <= 1000.0):
            raise ConfigError(f"speed {speed} is out of range; expected 0.01..1000 (1 = real time)")
        low, high = STEP_GRACE_RANGE_S
        if not (math.isfinite(step_grace_s) and low <= step_grace_s <= high):
            raise ConfigError(
                f"step grace {step_grace_s} s is out of range; expected {low:g}..{high:g} seconds"
            )
        self.scene = scene
        self.mode = mode
        self.speed = speed
        self.step_grace_s = step_grace_s
        self.log = log
        self.api = SimApi(scene)
        self.clients: dict[str, _Client] = {}
        # connections seen: routing id -> file descriptor (ZMQ_SRCFD)
        self._peer_fds: dict[bytes, int] = {}
        self._n_clients = 0
        # (wall s, step) where realtime pacing started
        self._anchor: tuple[float, int] | None = None
        self._slipping = False  # said once: the machine cannot step at --speed
        self._stop = False
        self._next_reap_s = 0.0
        self._info_reply = encode_ret([self.api.info()])
        self.context = zmq.Context()
        self.socket = self.context.socket(zmq.ROUTER)
        self.socket.setsockopt(zmq.LINGER, 0)
        # above: ZMQ closes the connection, unread
        self.socket.setsockopt(zmq.MAXMSGSIZE, MAX_FRAME_BYTES)
        self.socket.setsockopt(zmq.RCVHWM, RCVHWM)
        # what a connection sent beyond one frame: shut down
        self._intake = Intake(MAX_UNREAD_BYTES, max_held_bytes)
        try:
            if port == 0:
                port = self.socket.bind_to_random_port(f"tcp://{host}")
            else:
                self.socket.bind(f"tcp://{host}:{port}")
        except zmq.ZMQError as err:
            self.socket.close()
            self.context.term()
            self._intake.close()
            raise ConfigError(f"cannot listen on tcp://{host}:{port}: {err}") from err
        self.host, self.port = host, port
        self._monitor = self.socket.get_monitor_socket(zmq.EVENT_ACCEPTED | zmq.EVENT_DISCONNECTED)

    # -- loop --------------------------------------------------------------------------------
    def serve_forever(self) -> None:
        sock, monitor, intake = self.socket, self._monitor, self._intake
        poller = zmq.Poller()
        poller.register(sock, zmq.POLLIN)
        poller.register(monitor, zmq.POLLIN)
        intake.start()  # its thread shuts down a connection over MAX_UNREAD_BYTES
        while not self._stop:
            for line in intake.lines():
                self.log(line)
            try:
                parts = sock.recv_multipart(zmq.NOBLOCK, copy=False)
            except zmq.Again:
                ready = dict(poller.poll(self._poll_timeout_ms()))
                if monitor in ready:
                    self._drain_monitor()
                if sock in ready:
                    continue
                now = time.monotonic()
                self._pace(now)
                if now >= self._next_reap_s:
                    self._reap(now)
                continue
            # the connections accepted and closed before it, in order: then count it
            self._drain_monitor()
            # parts[0], the routing id, is ZMQ's
            intake.took(_source_fd(parts[-1]), wire_bytes(parts[1:]))
            now = time.monotonic()
            self._pace(now)
            if now >= self._next_reap_s:
                self._reap(now)
            sock.send_multipart(self.answer(parts, now))
            self._pace(time.monotonic())

    def answer(self, parts: list, now: float) -> list:
        """The reply message for one received message: its envelope (routing id and the frames up to
        the empty delimiter a REQ client adds), then one CBOR frame. Never raises."""
        peer = parts[0].bytes
        if len(parts) == 3 and not parts[1].bytes:  # a REQ client: [id, b"", request]
            envelope, body = [peer, b""], parts[2:]
        else:
            cut = next((i for i in range(1, len(parts)) if not parts[i].bytes), 0)
            envelope, body = [p.bytes for p in parts[: cut + 1]], parts[cut + 1 :]
        if peer not in self._peer_fds:
            self._drain_monitor()  # first: a closed connection's fd may be this new one's
            self._peer_fds[peer] = _source_fd(parts[-1])
        if len(body) != 1:
            reply = encode_err(
                f"malformed request: {len(body)} message parts; expected one CBOR map in one part"
            )
        else:
            frame = body[0]  # an oversized one is only measured, not copied
            try:
                reply = self.handle(
                    frame.buffer if len(frame) > MAX_REQUEST_BYTES else frame.bytes, now, peer
                )
            except Exception as err:  # noqa: BLE001 - a bug of ours: no request may end the server
                self.log(
                    f"internal error: {type(err).__name__}: {safe_str(err)}\n"
                    f"{traceback.format_exc()}"
                )
                reply = encode_err(f"internal error: {type(err).__name__}")
        return [*envelope, reply]

    def stop(self) -> None:
        """Ask the loop to end (signal-safe); it returns within one idle poll."""
        self._stop = True

    def close(self) -> None:
        try:
            self.scene.close()
        finally:
            self.socket.disable_monitor()
            self._monitor.close(linger=0)
            self.socket.close()
            self.context.term()
            self._intake.close()

    def _poll_timeout_ms(self) -> int:
        if self._anchor is not None:
            return max(
                1, min(int(IDLE_POLL_S * 1000), int(self.scene.config.dt_s / self.speed * 1000))
            )
        return int(IDLE_POLL_S * 1000)

    def _pace(self, now: float) -> None:
        """Realtime mode: step the twin up to the wall clock, unless a client is stepping."""
        scene = self.scene
        if (
            self.mode != "realtime"
            or not scene.running
            or any(c.stepping for c in self.clients.values())
        ):
            self._anchor = None
            return
        if self._anchor is None:
            self._anchor = (now, scene.twin.step_index)
            return
        wall0, step0 = self._anchor
        due = (
            step0
            + int((now - wall0) * self.speed * 1e9 / scene.config.dt_ns)
            - scene.twin.step_index
        )
        max_due = max(1, round(MAX_LAG_S * 1e9 / scene.config.dt_ns))
        # the machine cannot step that fast: let simulated time slip, keep serving
        if due > max_due:
            if not self._slipping:
                self.log(
                    f"the twin cannot keep up with {self.speed:g}x real time here; "
                    f"simulated time slips"
                )
                self._slipping = True
            self._anchor = (now, scene.twin.step_index + max_due)
            due = max_due
        if due > 0:  # all of it: a request must see the simulated time its wall-clock moment is due
            try:
                scene.advance(due)
            except Exception as err:  # noqa: BLE001 - e.g. a recorder failing: end the run, keep serving
                self.log(
                    f"error while stepping the twin: {type(err).__name__}: {err}; "
                    f"stopping the simulation"
                )
                self._anchor = None
                try:
                    scene.stop()
                except Exception as stop_err:  # noqa: BLE001
                    self.log(
                        f"error while stopping the simulation: "
                        f"{type(stop_err).__name__}: {stop_err}"
                    )

    def _drain_monitor(self) -> None:
        """Connections ZMQ accepted (measured from now on) and closed (a client's program ended or
        closed its socket: forget its clients), in the order they happened."""
        while self._monitor.get(zmq.EVENTS) & zmq.POLLIN:
            event = parse_monitor_message(self._monitor.recv_multipart())
            fd = int(event["value"])
            if event["event"] == zmq.EVENT_ACCEPTED:
                self._intake.accepted(fd)
                continue
            if event["event"] != zmq.EVENT_DISCONNECTED:
                continue
            self._intake.disconnected(fd)
            gone = {peer for peer, peer_fd in self._peer_fds.items() if peer_fd == fd}
            for peer in gone:
                del self._peer_fds[peer]
            for uuid, c in list(self.clients.items()):
                if c.peer in gone:
                    del self.clients[uuid]
                    self.log(f"{c.label} disconnected")

    def _reap(self, now: float) -> None:
        self._next_reap_s = now + 1.0
        for uuid, c in list(self.clients.items()):
            if now - c.last_seen_s > c.timeout_s:
                del self.clients[uuid]
                self.log(f"{c.label} disconnected (silent for more than {c.timeout_s:g} s)")

    # -- requests ----------------------------------------------------------------------------
    def handle(self, raw: bytes, now: float, peer: bytes = b"") -> bytes:
        """One request in, one reply out; never raises for a client's bad input."""
        try:
            req = decode(raw)
        except VersionMismatch as err:
            self.log(f"refused a request: {printable(str(err), 200)}")
            return encode_version_mismatch(str(err))
        except RequestError as err:
            self.log(f"refused a request: {printable(str(err), 200)}")
            return encode_err(str(err))
        client = self.clients.get(req.uuid)
        if client is None:
            refusal = self._make_room(peer, now)
            if refusal:
                return encode_err(refusal)
            client = self._connect(req.uuid, req.first, now)
        client.last_seen_s = now
        client.peer = peer
        func = req.func
        try:
            entry = self.api.functions.get(func)
            if entry is not None:
                params, fn = entry
                self.api.client = client.label
                result = fn(*check_args(params, req.args))
                if func == "sim.stopSimulation":
                    self._reset_stepping()
                return EMPTY_REPLY if result is None else encode_ret([result])
            if func == "sim.step":
                return self._step(client, req.args)
            if func == "_*executed*_":
                return self._executed(client)
            if func == "sim.setStepping":
                (enable,) = check_args(_STEPPING_PARAMS, req.args)
                return encode_ret([self._set_stepping(client, enable)])
            if func == "zmqRemoteApi.require":
                (name,) = check_args(_MODULE_PARAMS, req.args)
                _check_module(name)
                return EMPTY_REPLY
            if func == "zmqRemoteApi.info":
                (name,) = check_args(_MODULE_PARAMS, req.args)
                _check_module(name)
                return self._info_reply
            return encode_err(f"No such function: {printable(func, 120)}")
        except (RequestError, TwinError) as err:
            return encode_err(f"{func}: {err}")
        except Exception as err:  # noqa: BLE001 - a bug of ours: report it, keep serving
            message = f"{type(err).__name__}: {safe_str(err)}"
            self.log(f"internal error in {func}: {message}\n{traceback.format_exc()}")
            return encode_err(f"{func}: internal error: {message}")

    def _make_room(self, peer: bytes, now: float) -> str:
        """Why a new uuid cannot be served now, or '' if it can (having forgotten an idle client if
        need be).

        At most MAX_CLIENTS_PER_CONNECTION uuids per connection and MAX_CLIENTS in all. When all
        slots are taken, the least recently seen client silent for EVICT_IDLE_S or more
        (step_grace_s if it is in stepping mode, which would hold the others' sim.step() back that
        long anyway) is forgotten: its slot goes to the new one. If it calls again it is served as a
        new client."""
        if (
            peer
            and sum(1 for c in self.clients.values() if c.peer == peer)
            >= MAX_CLIENTS_PER_CONNECTION
        ):
            return (
                f"too many clients on one connection: {MAX_CLIENTS_PER_CONNECTION} uuids "
                f"already came over it "
                "(the limit)"
            )
        if len(self.clients) < MAX_CLIENTS:
            return ""
        idle = [
            (c.last_seen_s, uuid)
            for uuid, c in self.clients.items()
            if now - c.last_seen_s >= (self.step_grace_s if c.stepping else EVICT_IDLE_S)
        ]
        if not idle:
            return (
                f"too many clients: {MAX_CLIENTS} are connected (the limit), none silent "
                f"long enough to give "
                f"up its slot; when all slots are taken, a new client takes the slot of "
                f"the least recently seen "
                f"one silent for {EVICT_IDLE_S:g} s or more ({self.step_grace_s:g} s, "
                f"--step-grace, if it is in "
                "stepping mode): try again then. A client is also forgotten when its "
                "connection closes or "
                "after its timeout"
            )
        _, uuid = min(idle)
        c = self.clients.pop(uuid)
        self.log(
            f"{c.label} forgotten: silent for {now - c.last_seen_s:.1f} s while all "
            f"{MAX_CLIENTS} client "
            "slots were taken (a new client takes its slot)"
        )
        return ""

    def _connect(self, uuid: str, first: dict | None, now: float) -> _Client:
        self._n_clients += 1
        timeout = (first or {}).get("timeout")
        if (
            isinstance(timeout, bool)
            or not isinstance(timeout, (int, float))
            or not 0 < timeout < 1e7
        ):
            timeout = DEFAULT_CLIENT_TIMEOUT_S
        c = _Client(label=f"client {self._n_clients}", last_seen_s=now, timeout_s=float(timeout))
        self.clients[uuid] = c
        lang = (first or {}).get("lang")
        lang = printable(lang, 20) if isinstance(lang, str) else "unknown language"
        self.log(f"{c.label} connected (uuid {printable(uuid[:8])}, {lang})")
        return c

    # -- stepping ----------------------------------------------------------------------------
    def _set_stepping(self, client: _Client, enable: bool) -> int:
        previous = int(client.stepping)
        client.stepping = enable
        if not enable:
            client.wants_step = False
            self._try_advance()
        return previous

    def _reset_stepping(self) -> None:
        for c in self.clients.values():
            c.stepping = c.wants_step = False
            c.wait_until_step = -1

    def _step(self, client: _Client, args: list) -> bytes:
        check_args(_STEP_PARAMS, args)
        if not self.scene.running:
            state = "paused" if self.scene.state else "stopped"
            raise RequestError(f"the simulation is {state}; call sim.startSimulation() first")
        client.wants_step = True
        client.wait_until_step = self.scene.twin.step_index + 1
        self._try_advance()
        return self._wait_reply(client)

    def _executed(self, client: _Client) -> bytes:
        if client.wait_until_step < 0:
            raise RequestError("no call of this client is waiting (callbacks are not supported)")
        self._try_advance()
        reply = self._wait_reply(client)
        if reply is WAIT_REPLY:
            time.sleep(WAIT_BACKOFF_S)
        return reply

    def _try_advance(self) -> None:
        """One step once every stepping client (and every client in sim.step) has asked for it."""
        now = time.monotonic()
        asked = False
        for c in self.clients.values():
            if c.wants_step:
                asked = True
            elif c.stepping:
                if now - c.last_seen_s < self.step_grace_s:
                    return
                c.stepping = False
                self.log(
                    f"{c.label} silent for {self.step_grace_s:g} s (--step-grace): no "
                    f"longer holds back stepping"
                )
        if asked and self.scene.running:
            self.scene.advance(1)
            for c in self.clients.values():
                c.wants_step = False

    def _wait_reply(self, client: _Client) -> bytes:
        if client.wait_until_step <= self.scene.twin.step_index or not self.scene.running:
            client.wait_until_step = -1
            client.wants_step = False
            return EMPTY_REPLY
        return WAIT_REPLY


def _source_fd(frame: zmq.Frame) -> int:
    try:
        return int(frame.get(zmq.SRCFD))
    except (zmq.ZMQError, AttributeError, TypeError):
        return -1


def _check_module(name: str) -> None:
    if name != "sim":
        raise RequestError(f"no such module {brief_value(name)}; this twin offers 'sim'")


_STEPPING_PARAMS = Signature(Param("enable", "bool"))
_STEP_PARAMS = Signature(Param("wait", "bool", True))
_MODULE_PARAMS = Signature(Param("name", "str"))


def serve(
    config: TwinConfig,
    *,
    host: str = "127.0.0.1",
    port: int = 23000,
    mode: str = "realtime",
    speed: float = 1.0,
    step_grace_s: float = DEFAULT_STEP_GRACE_S,
    mcap_path: str | None = None,
    rrd_path: str | None = None,
    rate: int = 1,
    start: bool = False,
    log: Callable[[str], None] = print,
    max_held_bytes: int = DEFAULT_MAX_HELD_BYTES,
) -> int:
    """Run the server until SIGINT/SIGTERM; each start..stop run is recorded to its own file."""
    scene = Scene(config, mcap_path=mcap_path, rrd_path=rrd_path, rate=rate, mode=mode, log=log)
    try:
        server = Server(
            scene,
            host=host,
            port=port,
            mode=mode,
            speed=speed,
            step_grace_s=step_grace_s,
            log=log,
            max_held_bytes=max_held_bytes,
        )
    except BaseException:
        scene.twin.close()
        raise
    previous = {
        s: signal.signal(s, lambda *_: server.stop()) for s in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        pace = f"{mode}, speed {speed:g}x" if mode == "realtime" else mode
        if host not in ("127.0.0.1", "localhost", "::1"):
            log(f"warning: listening on {host}, reachable from other machines")
        log(
            f"twin serve: listening on tcp://{server.host}:{server.port} (robot "
            f"{config.profile.name}, {pace})"
        )
        if start:
            scene.start()
        server.serve_forever()
        log("twin serve: shutting down")
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        server.close()
    return 0
