"""CoppeliaSim's legacy remote API (`import sim as vrep`, CoppeliaSim <= 4.2), in pure Python.

Same call signatures, return conventions and simx_* constants as the old module, implemented over
the ZeroMQ remote API (protocol v2) with the official client, so an old program runs against `twin
serve` after changing only its import line:

    from twin.remote import legacy as vrep      # or: import twin.remote.legacy as sim

Connection: simxStart(address, port, ...) connects to tcp://address:port, except that the legacy
default port 19997 means "the twin server": $TWIN_REMOTE_PORT, else 23000. $TWIN_REMOTE_HOST, when
set, replaces the address (a program written for another machine's IP). simxStart returns -1 when no
server answers within timeOutInMs; that timeout also bounds every blocking call (return code
simx_return_timeout_flag). Every operation mode performs the call at once: streaming and buffer
reads return the current value with simx_return_ok.
"""

from __future__ import annotations

import math
import os
import time
from typing import Any

import zmq

try:
    from coppeliasim_zmqremoteapi_client import RemoteAPIClient
except ImportError as _err:  # the official client is what speaks the protocol underneath
    raise ImportError(
        "twin.remote.legacy needs the official client: pip install "
        "coppeliasim-zmqremoteapi-client==2.0.4"
    ) from _err

LEGACY_PORT = 19997
DEFAULT_PORT = 23000

# return codes (bit flags)
simx_return_ok = 0x000000
simx_return_novalue_flag = 0x000001
simx_return_timeout_flag = 0x000002
simx_return_illegal_opmode_flag = 0x000004
simx_return_remote_error_flag = 0x000008
simx_return_split_progress_flag = 0x000010
simx_return_local_error_flag = 0x000020
simx_return_initialize_error_flag = 0x000040

# operation modes
simx_opmode_oneshot = 0x000000
simx_opmode_blocking = 0x010000
simx_opmode_oneshot_wait = 0x010000
simx_opmode_streaming = 0x020000
simx_opmode_oneshot_split = 0x030000
simx_opmode_streaming_split = 0x040000
simx_opmode_discontinue = 0x050000
simx_opmode_buffer = 0x060000
simx_opmode_remove = 0x070000

# a few sim_* constants old programs use
sim_handle_parent = -11
sim_handle_all = -2
sim_simulation_stopped = 0x00
sim_simulation_paused = 0x08
sim_simulation_advancing = 0x10
sim_simulation_advancing_running = 0x11

_VERBOSITY_MSGS = 600  # sim.verbosity_msgs: what the status bar shows


class _Connection:
    def __init__(self, client: RemoteAPIClient, timeout_ms: int) -> None:
        self.client = client
        self.timeout_ms = timeout_ms
        self.synchronous = False

    def call(self, func: str, *args: Any) -> tuple[int, Any]:
        """(return code, value) of one remote call; never raises for a remote or timeout error."""
        try:
            return simx_return_ok, self.client.call(func, list(args))
        except zmq.Again:
            self._reopen()
            return simx_return_timeout_flag, None
        except zmq.ZMQError:
            return simx_return_local_error_flag, None
        except Exception:  # noqa: BLE001 - the client raises a plain Exception carrying the server's message
            return simx_return_remote_error_flag, None

    def _reopen(self) -> None:
        """A REQ socket whose reply timed out cannot send again: give the client a fresh socket."""
        c = self.client
        endpoint = c.socket.getsockopt_string(zmq.LAST_ENDPOINT)
        c.socket.close(linger=0)
        c.socket = c.context.socket(zmq.REQ)
        _configure(c.socket, self.timeout_ms)
        c.socket.connect(endpoint)

    def close(self) -> None:
        if self.synchronous:
            self.call("sim.setStepping", False)
        self.client.socket.close(linger=0)


_connections: dict[int, _Connection] = {}
_next_id = 0


def _configure(socket: zmq.Socket, timeout_ms: int) -> None:
    socket.setsockopt(zmq.LINGER, 0)
    if timeout_ms > 0:
        socket.setsockopt(zmq.RCVTIMEO, timeout_ms)
        socket.setsockopt(zmq.SNDTIMEO, timeout_ms)


def _endpoint(address: str, port: int) -> tuple[str, int]:
    host = os.environ.get("TWIN_REMOTE_HOST") or address
    if port == LEGACY_PORT:
        text = os.environ.get("TWIN_REMOTE_PORT", str(DEFAULT_PORT))
        try:
            port = int(text)
        except ValueError:
            raise ValueError(f"TWIN_REMOTE_PORT {text!r} is not a port number") from None
    return host, port


def simxStart(
    connectionAddress: str,
    connectionPort: int,
    waitUntilConnected: bool,
    doNotReconnectOnceDisconnected: bool,
    timeOutInMs: int,
    commThreadCycleInMs: int,
) -> int:
    """Connect; the client id (>= 0), or -1 when no server answers within timeOutInMs (5000 if <=
    0)."""
    global _next_id
    host, port = _endpoint(connectionAddress, int(connectionPort))
    timeout_ms = int(timeOutInMs) if timeOutInMs and timeOutInMs > 0 else 5000
    client = RemoteAPIClient(host, port)
    _configure(client.socket, timeout_ms)
    try:
        client.call("zmqRemoteApi.require", ["sim"])
    except Exception:  # noqa: BLE001 - zmq.Again (no answer), or a plain Exception from a server not ours
        client.socket.close(linger=0)
        return -1
    cid = _next_id
    _next_id += 1
    _connections[cid] = _Connection(client, timeout_ms)
    return cid


def simxFinish(clientID: int) -> None:
    """Close one connection, or all with -1."""
    ids = list(_connections) if clientID == -1 else [clientID]
    for cid in ids:
        conn = _connections.pop(cid, None)
        if conn is not None:
            conn.close()


def simxGetConnectionId(clientID: int) -> int:
    return clientID if clientID in _connections else -1


def _do(clientID: int, func: str, *args: Any) -> tuple[int, Any]:
    conn = _connections.get(clientID)
    if conn is None:
        return simx_return_initialize_error_flag, None
    return conn.call(func, *args)


def _mode_ok(operationMode: int) -> bool:
    return isinstance(operationMode, int) and (operationMode & 0xFF0000) <= simx_opmode_remove


def simxGetObjectHandle(clientID: int, objectName: str, operationMode: int) -> tuple[int, int]:
    rc, handle = _do(clientID, "sim.getObject", "/" + objectName.lstrip("/"))
    return (rc, handle) if rc == simx_return_ok else (rc, 0)


def _set(clientID: int, func: str, operationMode: int, *args: Any) -> int:
    if not _mode_ok(operationMode):
        return simx_return_illegal_opmode_flag
    if operationMode & 0xFF0000 in (simx_opmode_remove, simx_opmode_discontinue):
        return simx_return_ok
    return _do(clientID, func, *args)[0]


def _get(clientID: int, func: str, operationMode: int, *args: Any) -> tuple[int, Any]:
    if not _mode_ok(operationMode):
        return simx_return_illegal_opmode_flag, None
    return _do(clientID, func, *args)


def simxSetJointTargetPosition(
    clientID: int, jointHandle: int, targetPosition: float, operationMode: int
) -> int:
    return _set(clientID, "sim.setJointTargetPosition", operationMode, jointHandle, targetPosition)


def simxSetJointPosition(
    clientID: int, jointHandle: int, position: float, operationMode: int
) -> int:
    return _set(clientID, "sim.setJointPosition", operationMode, jointHandle, position)


def simxGetJointPosition(clientID: int, jointHandle: int, operationMode: int) -> tuple[int, float]:
    rc, q = _get(clientID, "sim.getJointPosition", operationMode, jointHandle)
    return rc, (q if rc == simx_return_ok else 0.0)


def simxSetIntegerSignal(
    clientID: int, signalName: str, signalValue: int, operationMode: int
) -> int:
    return _set(clientID, "sim.setInt32Signal", operationMode, signalName, signalValue)


def simxGetIntegerSignal(clientID: int, signalName: str, operationMode: int) -> tuple[int, int]:
    rc, value = _get(clientID, "sim.getInt32Signal", operationMode, signalName)
    if rc == simx_return_ok and value is None:
        return simx_return_novalue_flag, 0
    return rc, (value if rc == simx_return_ok else 0)


def simxClearIntegerSignal(clientID: int, signalName: str, operationMode: int) -> int:
    return _set(clientID, "sim.clearInt32Signal", operationMode, signalName)


def simxAddStatusbarMessage(clientID: int, message: str, operationMode: int) -> int:
    return _set(clientID, "sim.addLog", operationMode, _VERBOSITY_MSGS, str(message))


def simxStartSimulation(clientID: int, operationMode: int) -> int:
    return _set(clientID, "sim.startSimulation", operationMode)


def simxStopSimulation(clientID: int, operationMode: int) -> int:
    return _set(clientID, "sim.stopSimulation", operationMode)


def simxPauseSimulation(clientID: int, operationMode: int) -> int:
    return _set(clientID, "sim.pauseSimulation", operationMode)


def simxSynchronous(clientID: int, enable: bool) -> int:
    rc, _ = _do(clientID, "sim.setStepping", bool(enable))
    if rc == simx_return_ok:
        _connections[clientID].synchronous = bool(enable)
    return rc


def simxSynchronousTrigger(clientID: int) -> int:
    return _do(clientID, "sim.step")[0]


def simxGetObjectPosition(
    clientID: int, objectHandle: int, relativeToObjectHandle: int, operationMode: int
) -> tuple[int, list[float]]:
    rc, pos = _get(
        clientID, "sim.getObjectPosition", operationMode, objectHandle, relativeToObjectHandle
    )
    return rc, (pos if rc == simx_return_ok else [0.0, 0.0, 0.0])


def simxGetObjectOrientation(
    clientID: int, objectHandle: int, relativeToObjectHandle: int, operationMode: int
) -> tuple[int, list[float]]:
    rc, euler = _get(
        clientID, "sim.getObjectOrientation", operationMode, objectHandle, relativeToObjectHandle
    )
    return rc, (euler if rc == simx_return_ok else [0.0, 0.0, 0.0])


def simxGetPingTime(clientID: int) -> tuple[int, int]:
    """Round-trip time of one call, in whole milliseconds."""
    t0 = time.perf_counter()
    rc, _ = _do(clientID, "sim.getSimulationState")
    return rc, math.ceil((time.perf_counter() - t0) * 1000)


def simxGetLastCmdTime(clientID: int) -> int:
    """Simulation time of the last command, in milliseconds (0 when unknown)."""
    rc, t_s = _do(clientID, "sim.getSimulationTime")
    return int(t_s * 1000) if rc == simx_return_ok else 0


__all__ = [name for name in dir() if name.startswith(("simx", "sim_"))]
