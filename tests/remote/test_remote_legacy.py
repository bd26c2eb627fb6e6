"""twin.remote.legacy: the old simx* calls, their return codes and the 19997 port mapping."""

from __future__ import annotations

import math
import time

import pytest
from support.cli import free_port
from support.server import ServerProcess

from twin.remote import legacy as vrep

DT_S = 4_166_667e-9
WAIT = vrep.simx_opmode_oneshot_wait


@pytest.fixture(scope="module")
def server():
    with ServerProcess("--stepped", "--robot", "seed001") as s:
        yield s


@pytest.fixture
def cid(server, monkeypatch):
    monkeypatch.setenv("TWIN_REMOTE_PORT", str(server.port))
    monkeypatch.delenv("TWIN_REMOTE_HOST", raising=False)
    vrep.simxFinish(-1)
    client_id = vrep.simxStart("127.0.0.1", 19997, True, True, 5000, 5)
    assert client_id >= 0
    yield client_id
    vrep.simxStopSimulation(client_id, WAIT)
    vrep.simxFinish(-1)


_free_port = free_port


def test_simx_start_gives_minus_one_when_no_server_answers_within_its_timeout():
    t0 = time.monotonic()
    assert vrep.simxStart("127.0.0.1", _free_port(), True, True, 300, 5) == -1
    assert time.monotonic() - t0 < 5.0


def test_the_legacy_calls_and_return_codes(cid, server):
    assert vrep.simxGetConnectionId(cid) == cid
    assert (
        vrep.simxAddStatusbarMessage(cid, "legacy hello", vrep.simx_opmode_oneshot)
        == vrep.simx_return_ok
    )
    server.wait_for(r"\[info\] client \d+: legacy hello")
    rc, shoulder = vrep.simxGetObjectHandle(cid, "Revolute_joint", WAIT)
    assert rc == vrep.simx_return_ok and shoulder == 11
    rc, elbow = vrep.simxGetObjectHandle(cid, "Revolute_joint1", WAIT)
    assert rc == vrep.simx_return_ok and elbow == 12
    assert vrep.simxGetObjectHandle(cid, "no_such_joint", WAIT) == (
        vrep.simx_return_remote_error_flag,
        0,
    )
    assert vrep.simxGetIntegerSignal(cid, "pad_switch", vrep.simx_opmode_streaming) == (
        vrep.simx_return_novalue_flag,
        0,
    )
    assert vrep.simxSetIntegerSignal(cid, "pad_switch", 1, WAIT) == vrep.simx_return_ok
    assert vrep.simxGetIntegerSignal(cid, "pad_switch", vrep.simx_opmode_buffer) == (
        vrep.simx_return_ok,
        1,
    )
    assert vrep.simxSetJointPosition(cid, elbow, 0.25, WAIT) == vrep.simx_return_ok
    assert vrep.simxGetJointPosition(cid, elbow, WAIT) == (
        vrep.simx_return_ok,
        pytest.approx(0.25, abs=1e-12),
    )
    rc, pad = vrep.simxGetObjectHandle(cid, "suctionPad", WAIT)
    rc, xyz = vrep.simxGetObjectPosition(cid, pad, -1, WAIT)
    assert rc == vrep.simx_return_ok and len(xyz) == 3
    rc, euler = vrep.simxGetObjectOrientation(cid, pad, -1, WAIT)
    # seed001's scene: link 1 along +y at zero, joints turning clockwise seen from above
    assert euler == pytest.approx([0.0, 0.0, math.pi / 2 - 0.25], abs=1e-9)
    assert (
        vrep.simxSetJointTargetPosition(cid, shoulder, "far", WAIT)
        == vrep.simx_return_remote_error_flag
    )
    assert (
        vrep.simxSetJointTargetPosition(cid, shoulder, 0.1, 0x090000)
        == vrep.simx_return_illegal_opmode_flag
    )
    rc, ping_ms = vrep.simxGetPingTime(cid)
    assert rc == vrep.simx_return_ok and ping_ms >= 0
    assert (
        vrep.simxSetJointTargetPosition(99, shoulder, 0.1, WAIT)
        == vrep.simx_return_initialize_error_flag
    )


def test_synchronous_mode_triggers_one_step_at_a_time(cid):
    assert vrep.simxSynchronous(cid, True) == vrep.simx_return_ok
    assert vrep.simxStartSimulation(cid, WAIT) == vrep.simx_return_ok
    for _ in range(3):
        assert vrep.simxSynchronousTrigger(cid) == vrep.simx_return_ok
    assert vrep.simxGetLastCmdTime(cid) == int(3 * DT_S * 1000)
    assert vrep.simxStopSimulation(cid, WAIT) == vrep.simx_return_ok
    assert vrep.simxGetLastCmdTime(cid) == 0


def test_simx_finish_closes_the_connection(cid, server):
    uuid = vrep._connections[cid].client.uuid
    label = server.wait_for(rf"client \d+ connected \(uuid {uuid[:8]}").split(" connected")[0]
    vrep.simxFinish(cid)
    assert vrep.simxGetConnectionId(cid) == -1
    server.wait_for(rf"{label} disconnected$")
