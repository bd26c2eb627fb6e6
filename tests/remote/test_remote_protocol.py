"""The ZeroMQ remote API (protocol v2) as the official client sees it, and bad input that must not
stop the server (sent with a raw REQ socket where the official client cannot produce it)."""

from __future__ import annotations

import math
import threading
import time

import cbor2
import pytest
from support.raw_client import RawClient
from support.server import ServerProcess

from twin.model.config import TwinConfig
from twin.model.errors import UnknownName
from twin.model.profiles import JOINT_ALIASES, PAD_ALIASES, PROFILES, ROLES
from twin.remote.session import Scene
from twin.remote.sim_api import SimApi

DT_S = 4_166_667e-9


@pytest.fixture(scope="module")
def server():
    with ServerProcess("--stepped") as s:
        yield s


@pytest.fixture
def sim(server):
    sim = server.client().require("sim")
    yield sim
    sim.setStepping(False)
    sim.stopSimulation()



@pytest.fixture
def raw(server):
    c = RawClient(server.port)
    yield c
    c.close()


def test_require_gives_functions_and_the_constants(sim):
    assert sim.handle_world == -1
    assert sim.simulation_stopped == 0
    assert sim.simulation_advancing_running == 17
    assert sim.getSimulationState() == sim.simulation_stopped
    for name in (
        "getObject",
        "getObjectHandle",
        "setJointTargetPosition",
        "setJointPosition",
        "getJointPosition",
        "setInt32Signal",
        "getInt32Signal",
        "clearInt32Signal",
        "startSimulation",
        "stopSimulation",
        "pauseSimulation",
        "getSimulationTime",
        "setStepping",
        "step",
        "getObjectPosition",
        "getObjectOrientation",
        "addLog",
    ):
        assert callable(getattr(sim, name)), name


def test_objects_joints_signals_and_poses(sim):
    h1 = sim.getObject("/MTB_axis1")
    assert h1 == sim.getObjectHandle("MTB_axis1") == sim.getObject("/MTB_Robot/MTB_axis1")
    assert (
        len(
            {
                h1,
                sim.getObject("/MTB_axis2"),
                sim.getObject("/MTB_axis3"),
                sim.getObject("/MTB_axis4"),
            }
        )
        == 4
    )
    box = sim.getObject("/box")
    assert box == sim.getObject("/Cuboid")
    assert sim.getObjectPosition(box, sim.handle_world) == pytest.approx(
        [0.2, 0.7, 0.025], abs=1e-3
    )
    sim.setJointPosition(sim.getObject("/MTB_axis2"), 0.5)
    assert sim.getJointPosition(sim.getObject("/MTB_axis2")) == pytest.approx(0.5, abs=1e-12)
    pad = sim.getObject("/suctionPad")
    x, y, _ = sim.getObjectPosition(pad, -1)
    assert (x, y) == pytest.approx(
        (0.467 + 0.4005 * math.cos(0.5), 0.4005 * math.sin(0.5)), abs=1e-9
    )
    assert sim.getObjectOrientation(pad, -1) == pytest.approx([0.0, 0.0, 0.5], abs=1e-9)
    # relative to the pad, the pad is at its own origin
    assert sim.getObjectPosition(pad, pad) == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    assert sim.getInt32Signal("pad_switch") is None
    sim.setInt32Signal("pad_switch", 1)
    assert sim.getInt32Signal("pad_switch") == 1
    sim.clearInt32Signal("pad_switch")
    assert sim.getInt32Signal("pad_switch") is None
    assert sim.getObject("/nothing", {"noError": True}) == -1


def test_start_pause_stop_and_the_scene_reset(sim, server):
    sim.setStepping(True)
    sim.startSimulation()
    assert sim.getSimulationState() == sim.simulation_advancing_running
    h = sim.getObject("/MTB_axis1")
    sim.setJointTargetPosition(h, 0.3)
    for _ in range(10):
        sim.step()
    assert sim.getSimulationTime() == pytest.approx(10 * DT_S, abs=1e-12)
    assert sim.getJointPosition(h) > 0.0
    sim.pauseSimulation()
    assert sim.getSimulationState() == sim.simulation_paused
    with pytest.raises(Exception, match="paused"):
        sim.step()
    sim.startSimulation()
    sim.step()
    assert sim.getSimulationTime() == pytest.approx(11 * DT_S, abs=1e-12)
    sim.stopSimulation()
    assert sim.getSimulationState() == sim.simulation_stopped
    assert sim.getSimulationTime() == 0.0
    assert sim.getJointPosition(h) == 0.0  # a fresh scene
    assert sim.setStepping(False) == 0  # stopping reset this client's stepping
    server.wait_for(r"simulation stopped: run \d+ lasted 11 steps")


def test_add_log_prints_a_status_line(sim, server):
    sim.addLog(sim.verbosity_scriptinfos, "hello from the test")
    server.wait_for(r"\[info\] client \d+: hello from the test")


def test_every_stepping_client_must_ask_before_the_scene_advances(server):
    a = server.client().require("sim")
    b = server.client().require("sim")
    try:
        assert a.setStepping(True) == 0
        assert a.setStepping(True) == 1  # the previous level
        b.setStepping(True)
        a.startSimulation()
        done = threading.Event()
        thread = threading.Thread(target=lambda: (a.step(), done.set()), daemon=True)
        thread.start()
        time.sleep(0.2)
        assert not done.is_set(), "a stepped although b had not asked"
        assert b.getSimulationTime() == 0.0
        b.step()
        assert done.wait(10)
        thread.join(10)
        assert b.getSimulationTime() == pytest.approx(DT_S, abs=1e-12)
        b.setStepping(False)  # now a alone decides
        a.step()
        assert b.getSimulationTime() == pytest.approx(2 * DT_S, abs=1e-12)
    finally:
        a.setStepping(False)
        b.setStepping(False)
        a.stopSimulation()


def test_bad_input_gets_an_error_naming_the_problem_and_the_server_goes_on(server, raw):
    def good() -> None:
        assert raw.call("sim.getSimulationState", []) == {"ret": [0]}

    good()
    cases = [
        (b"\xff\x00garbage", "not valid CBOR"),
        (cbor2.dumps([1, 2, 3]), "expected a CBOR map, got list"),
        (cbor2.dumps({"func": "sim.getSimulationState", "args": []}), "version does not match"),
        (
            cbor2.dumps({"func": 7, "args": [], "uuid": raw.uuid}),
            "'func' must be a non-empty string",
        ),
        (
            cbor2.dumps({"func": "sim.getJointPosition", "args": 5, "uuid": raw.uuid}),
            "'args' must be an array",
        ),
        (b"\x00" * (10 * 1024 * 1024), "exceeds the limit"),
        (b"\x81" * 1000 + b"\x00", "nesting depth (32)"),
        (b"\x5b" + (1 << 60).to_bytes(8, "big") + b"abc", "not valid CBOR"),
    ]
    for data, expected in cases:
        reply = raw.raw(data)
        assert expected in reply.get("err", ""), (expected, reply)
        good()
    raw.socket.send_multipart(
        [cbor2.dumps({"func": "sim.getSimulationState", "args": [], "uuid": raw.uuid}), b"x"]
    )
    assert "2 message parts" in cbor2.loads(raw.socket.recv())["err"]
    good()
    # a v1 client also gets the answer in the shape it understands
    assert raw.raw(cbor2.dumps({"func": "sim.getSimulationState", "args": []}))["success"] is False
    calls = [
        ("sim.noSuchFunction", [], "No such function: sim.noSuchFunction"),
        (
            "sim.getJointPosition",
            ["MTB_axis1"],
            "argument 1 (handle) is 'MTB_axis1'; expected an integer",
        ),
        ("sim.getJointPosition", [11, 12], "expected 1 argument(s) (handle: int), got 2"),
        ("sim.setJointTargetPosition", [11], "expected 2..3 argument(s)"),
        ("sim.setJointTargetPosition", [11, float("nan")], "expected a finite number"),
        ("sim.setJointTargetPosition", [999, 0.1], "object handle 999 does not exist"),
        ("sim.setJointTargetPosition", [15, 0.1], "object 15 (suctionPad) is not a joint"),
        ("sim.getObject", ["/NoSuchThing"], "object does not exist: '/NoSuchThing'"),
        ("sim.setInt32Signal", ["pad_switch", 2**40], "outside the int32 range"),
        ("sim.setStepping", ["yes"], "expected a boolean"),
        ("sim.step", [], "the simulation is stopped"),
        ("_*executed*_", [], "no call of this client is waiting"),
        ("zmqRemoteApi.require", ["simIK"], "no such module 'simIK'"),
    ]
    for func, args, expected in calls:
        reply = raw.call(func, args)
        assert expected in reply.get("err", ""), (func, expected, reply)
        good()
    assert "protocol version 1" in raw.call("sim.getSimulationState", [], ver=1)["err"]
    good()


def test_the_official_client_raises_the_servers_message(sim):
    with pytest.raises(Exception, match="object does not exist: '/nowhere'"):
        sim.getObject("/nowhere")
    with pytest.raises(Exception, match="argument 2 \\(targetPosition\\)"):
        sim.setJointTargetPosition(sim.getObject("/MTB_axis1"), "far")
    with pytest.raises(Exception, match="callbacks are not supported"):
        sim.addLog(sim.verbosity_scriptinfos, test_the_official_client_raises_the_servers_message)
    assert sim.getSimulationState() == sim.simulation_stopped


@pytest.mark.parametrize("profile", sorted(PROFILES))
def test_every_variants_names_resolve_on_its_profile(profile):
    scene = Scene(TwinConfig(profile=PROFILES[profile]), log=lambda line: None)
    try:
        api = SimApi(scene)
        for index, role in enumerate(ROLES):
            own = PROFILES[profile].joint_names[index]
            for name in (own, "/" + own, *JOINT_ALIASES[role]):
                assert api.resolve(name) == 11 + index, name
        for name in PAD_ALIASES:
            assert api.resolve("/" + name) == 15
        for name in ("/box", "box", "/Cuboid", "Cuboid#0"):
            assert api.resolve(name) == 20
        with pytest.raises(UnknownName, match="this scene has"):
            api.resolve("/joint9")
    finally:
        scene.close()


def test_a_client_that_goes_away_is_reported_and_no_longer_holds_back_stepping(server):
    gone = server.client()
    stepper = gone.require("sim")
    stepper.setStepping(True)
    label = server.wait_for(rf"client \d+ connected \(uuid {gone.uuid[:8]}").split(" connected")[0]
    sim = server.client().require("sim")
    sim.setStepping(True)
    sim.startSimulation()
    try:
        gone.socket.close(linger=0)  # the program ends without a word
        server.wait_for(rf"{label} disconnected$")
        sim.step()  # would wait forever if the departed stepping client still counted
        assert sim.getSimulationTime() == pytest.approx(DT_S, abs=1e-12)
    finally:
        sim.setStepping(False)
        sim.stopSimulation()
