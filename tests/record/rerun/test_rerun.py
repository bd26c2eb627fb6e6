"""The Rerun sink: a pick_place run written as .rrd, checked by `rerun rrd verify` and read back
chunk by chunk against the frames it was given."""

import math
import os
import subprocess

import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from twin.model.config import SceneObject, TwinConfig
from twin.model.errors import RecordingError
from twin.model.profiles import PROFILES
from twin.model.recording import Recording
from twin.record.rerun import scene
from twin.record.rerun.joints import JointMotion
from twin.record.rerun.rrd_file import read_scalars, rerun_executable, verify_rrd
from twin.record.rerun.writer import RerunRecorder, write_rrd
from twin.robot.urdf import urdf_joints, urdf_text
from twin.sim.twin import Twin
from twin.tasks import pick_place, run_task
from twin.verify.collectors import FrameCollector

BATCH_STEPS = 400  # three full batches plus a partial one in a ~1400-step run


def rerun_env(home) -> dict:
    """The `rerun` CLI writes an analytics config under the home directory: keep it in a tmp dir."""
    return {**os.environ, "HOME": str(home), "XDG_CONFIG_HOME": str(home / "config"),
            "XDG_DATA_HOME": str(home / "data"), "XDG_CACHE_HOME": str(home / "cache")}


@pytest.fixture(autouse=True)
def rerun_home(tmp_path, monkeypatch):
    """verify_rrd runs the `rerun` CLI, which writes an analytics config under the home
    directory."""
    for var, value in rerun_env(tmp_path / "home").items():
        if var == "HOME" or var.startswith("XDG_"):
            monkeypatch.setenv(var, value)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One pick_place cycle recorded by a RerunRecorder beside a FrameCollector."""
    tmp = tmp_path_factory.mktemp("rerun")
    config = TwinConfig()
    path = tmp / "pick_place.rrd"
    collector = FrameCollector()
    recorder = RerunRecorder(path, config, urdf_text(config.profile), batch_steps=BATCH_STEPS)
    twin = Twin(config, sinks=[collector, recorder])
    try:
        run_task(twin, pick_place.run, {"cycles": 1})
    finally:
        twin.close()
        recorder.close()
    return {
        "path": path,
        "config": config,
        "collector": collector,
        "cols": collector.columns(),
        "recorder": recorder,
        "tmp": tmp,
    }


def _component(path, entity: str, component: str) -> tuple[np.ndarray, list]:
    """(steps, per-row values) of one temporal component on one entity, sorted by step."""
    steps, rows = [], []
    for chunk in RrdReader(str(path)).stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if component not in batch.schema.names:
            continue
        steps.extend(batch.column(scene.STEP_TIMELINE).to_pylist())
        rows.extend(batch.column(component).to_pylist())
    order = np.argsort(steps, kind="stable")
    return np.asarray(steps)[order], [rows[i] for i in order]


def test_rerun_rrd_verify_accepts_the_file(run):
    home = run["tmp"] / "home"
    home.mkdir(exist_ok=True)
    done = subprocess.run(
        [rerun_executable(), "rrd", "verify", str(run["path"])],
        capture_output=True,
        text=True,
        env=rerun_env(home),
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "1 file verified without error" in done.stdout + done.stderr
    verify_rrd(run["path"])  # magic bytes + the same check, as `twin view` runs it


def test_every_frame_is_written_once(run):
    cols = run["cols"]
    assert run["recorder"].frames_written == len(cols) > 3 * BATCH_STEPS
    steps, _ = read_scalars(run["path"], f"/{scene.Z_PATH}/z")
    np.testing.assert_array_equal(steps, cols.step)


@pytest.mark.parametrize("role", scene.ROLES)
def test_joint_plots_hold_the_frames_positions_and_targets(run, role):
    cols = run["cols"]
    j = scene.ROLES.index(role)
    base = scene.Z_PATH if role == "z" else scene.ANGLES_PATH
    for suffix, expected in (("", cols.joint_q[:, j]), ("_target", cols.joint_target[:, j])):
        steps, values = read_scalars(run["path"], f"/{base}/{role}{suffix}")
        np.testing.assert_array_equal(steps, cols.step)
        np.testing.assert_array_equal(values, expected)  # float64 in, float64 out
    t_ns, _ = read_scalars(run["path"], f"/{base}/{role}", timeline=scene.TIME_TIMELINE)
    np.testing.assert_array_equal(t_ns.astype("timedelta64[ns]").astype(np.int64), cols.t_ns)


def test_suction_plots_follow_the_pad(run):
    cols = run["cols"]
    _, on = read_scalars(run["path"], f"/{scene.SUCTION_PATH}/on")
    _, holding = read_scalars(run["path"], f"/{scene.SUCTION_PATH}/holding")
    np.testing.assert_array_equal(on, cols.suction_on.astype(float))
    np.testing.assert_array_equal(holding, (cols.held_body >= 0).astype(float))
    assert holding.max() == 1.0 and holding.min() == 0.0  # the run did pick the box up


def test_box_and_pad_move_as_in_the_frames(run):
    cols = run["cols"]
    steps, translations = _component(
        run["path"], "/" + scene.object_path("box"), "Transform3D:translation"
    )
    np.testing.assert_array_equal(steps, cols.step)
    np.testing.assert_allclose(
        np.array([t[0] for t in translations]), cols.object_poses[:, 0, :3], atol=1e-6
    )
    _, pads = _component(run["path"], "/" + scene.PAD_PATH, "Cylinders3D:centers")
    pad_m = run["config"].profile.pad_length_m
    np.testing.assert_allclose(
        np.array([p[0] for p in pads]), cols.pad_pose[:, :3] + [0, 0, pad_m / 2], atol=1e-6
    )
    _, colors = _component(run["path"], "/" + scene.PAD_PATH, "Cylinders3D:colors")
    held = cols.held_body >= 0
    expected = np.array(
        [
            scene.PAD_HOLDING_RGB if h else scene.PAD_ON_RGB if on else scene.PAD_OFF_RGB
            for h, on in zip(held, cols.suction_on, strict=True)
        ]
    )
    rgba = np.array([c[0] for c in colors], dtype=np.uint32)
    np.testing.assert_array_equal(
        np.stack([rgba >> 24, (rgba >> 16) & 255, (rgba >> 8) & 255], axis=1), expected
    )


def test_joint_transforms_turn_the_urdf_links_by_the_joint_values(run):
    cols = run["cols"]
    names = run["config"].profile.joint_names
    for j in (0, 1, 3):  # revolute about +z: the rotation angle is the joint value
        steps, quats = _component(
            run["path"], "/" + scene.joint_path(names[j]), "Transform3D:quaternion"
        )
        np.testing.assert_array_equal(steps, cols.step)
        q = np.array([row[0] for row in quats])
        angle = 2.0 * np.arctan2(q[:, 2], q[:, 3])
        np.testing.assert_allclose(
            np.angle(np.exp(1j * (angle - cols.joint_q[:, j]))), 0.0, atol=1e-6
        )
    _, translations = _component(
        run["path"], "/" + scene.joint_path(names[2]), "Transform3D:translation"
    )
    z = np.array([t[0][2] for t in translations])
    np.testing.assert_allclose(z, -cols.joint_q[:, 2], atol=1e-6)  # the Z joint's axis is 0 0 -1
    _, parents = _component(
        run["path"], "/" + scene.joint_path(names[2]), "Transform3D:parent_frame"
    )
    assert {p[0] for p in parents} == {"MTB_link2"}


def test_events_and_commands_become_text_logs(run):
    collector = run["collector"]
    steps, texts = _component(run["path"], "/" + scene.EVENTS_PATH, "TextLog:text")
    assert len(texts) == len(collector.events) > 5
    assert [t[0] for t in texts][:2] == [
        " ".join(p for p in (e.kind, e.body, e.message) if p) for e in collector.events[:2]
    ]
    assert any(t[0].startswith("attach box") for t in texts)
    np.testing.assert_array_equal(steps, sorted(e.step for e in collector.events))
    _, commands = _component(run["path"], "/" + scene.COMMANDS_PATH, "TextLog:text")
    assert len(commands) == len(collector.commands) > 5


@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # a cut-short file has none
def test_events_and_commands_go_out_with_each_batch_of_frames(tmp_path):
    """A view cut short (its process killed: no close) still shows the events and commands of the
    frames it sent: they go out with each batch, not only at the close."""
    config = TwinConfig()
    collector = FrameCollector()
    recorder = RerunRecorder(
        tmp_path / "cut.rrd", config, urdf_text(config.profile), batch_steps=100
    )
    twin = Twin(config, sinks=[collector, recorder])
    run_task(twin, pick_place.run, {"cycles": 1})
    twin.close()
    recorder.stream.flush()  # what a kill leaves: no close
    sent = recorder.frames_written
    partial = tmp_path / "cut.rrd.partial"
    _, texts = _component(partial, "/" + scene.EVENTS_PATH, "TextLog:text")
    events = [" ".join(p for p in (e.kind, e.body, e.message) if p) for e in collector.events]
    before = sum(e.step < sent - 1 for e in collector.events)
    assert before > 5
    assert [t[0] for t in texts] == events[: len(texts)] and len(texts) >= before
    _, commands = _component(partial, "/" + scene.COMMANDS_PATH, "TextLog:text")
    assert len(commands) >= sum(c.step < sent - 1 for c in collector.commands) > 5


def test_static_scene_has_the_robot_the_box_and_a_blueprint(run):
    reader = RrdReader(str(run["path"]))
    static = {c.entity_path for c in reader.stream() if c.is_static}
    # Rerun's URDF loader drew the links
    assert "/robot/mtb/visual_geometries/MTB_link1/visual_0" in static
    assert "/" + scene.object_path("box") in static
    assert len(reader.blueprints()) == 1
    assert reader.recordings()[0].application_id == scene.APPLICATION_ID


def test_write_rrd_converts_a_recording_through_the_same_sink(run):
    collector, cols = run["collector"], run["cols"]
    recording = Recording(
        config=run["config"],
        frames=cols,
        commands=collector.commands,
        events=collector.events,
        run={"source": "task", "task": "pick_place", "params": {"cycles": 1}},
        urdf=urdf_text(run["config"].profile),
    )
    out = run["tmp"] / "converted.rrd"
    assert write_rrd(recording, out, batch_steps=333) == len(cols)
    verify_rrd(out)
    for entity in (
        f"/{scene.ANGLES_PATH}/shoulder",
        f"/{scene.Z_PATH}/z_target",
        f"/{scene.SUCTION_PATH}/holding",
    ):
        steps_a, a = read_scalars(run["path"], entity)
        steps_b, b = read_scalars(out, entity)
        np.testing.assert_array_equal(steps_a, steps_b)
        np.testing.assert_array_equal(a, b)
    _, texts = _component(out, "/" + scene.EVENTS_PATH, "TextLog:text")
    assert len(texts) == len(collector.events)


def _urdf_with_tilted_joints() -> str:
    """Joints with rotated origins and oblique (unit) axes, to check the transform maths in
    general."""
    link = '<link name="{0}"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>'
    joint = (
        '<joint name="{0}" type="{1}"><parent link="{2}"/><child link="{3}"/>'
        '<origin xyz="{4}" rpy="{5}"/><axis xyz="{6}"/><limit lower="-3" upper="3" '
        'effort="1" velocity="1"/>'
        "</joint>"
    )
    return (
        '<?xml version="1.0"?><robot name="tilted">'
        + "".join(link.format(n) for n in "abcd")
        + joint.format("j1", "revolute", "a", "b", "0.1 -0.2 0.3", "0.3 -0.5 1.1", "0.6 0 0.8")
        + joint.format(
            "j2", "prismatic", "b", "c", "0.4 0.0 -0.1", "-1.0 0.2 0.4", "0.48 -0.6 0.64"
        )
        + joint.format("j3", "continuous", "c", "d", "0 0 0", "0 0 0", "0 1 0")
        + "</robot>"
    )


@pytest.mark.parametrize("source", ["mtb", "tilted"])
def test_vectorised_joint_transforms_match_rerun(tmp_path, source):
    path = tmp_path / "robot.urdf"
    path.write_text(urdf_text(PROFILES["mtb"]) if source == "mtb" else _urdf_with_tilted_joints())
    tree = rr.urdf.UrdfTree.from_file_path(path)
    ours = {j.name: j for j in urdf_joints(path.read_text())}
    values = np.array([-2.5, -0.7, 0.0, 0.05, 0.9, 2.9])
    for joint in tree.joints():
        motion = JointMotion.from_urdf_joint(ours[joint.name])
        translations, quaternions = motion.transforms(values)
        for k, value in enumerate(values):
            ref = joint.compute_transform(float(value), clamp=False)
            ref_t = np.array(ref.translation.as_arrow_array().to_pylist()[0])
            ref_q = np.array(ref.quaternion.as_arrow_array().to_pylist()[0])
            np.testing.assert_allclose(translations[k], ref_t, atol=1e-6)
            assert (
                min(np.abs(quaternions[k] - ref_q).max(), np.abs(quaternions[k] + ref_q).max())
                < 1e-6
            )
        assert math.isclose(np.linalg.norm(quaternions[-1]), 1.0, abs_tol=1e-12)


def test_bad_output_and_batch_size_are_one_line_errors(tmp_path):
    config = TwinConfig()
    with pytest.raises(RecordingError, match="does not exist"):
        RerunRecorder(tmp_path / "missing" / "x.rrd", config, urdf_text(config.profile))
    with pytest.raises(RecordingError, match="batch size 0"):
        RerunRecorder(tmp_path / "x.rrd", config, urdf_text(config.profile), batch_steps=0)
    with pytest.raises(RecordingError, match="has no joint 'MTB_axis1'"):
        RerunRecorder(tmp_path / "y.rrd", config, _urdf_with_tilted_joints())
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no file was started


def test_a_user_urdf_with_stl_meshes_is_drawn_from_its_meshes(tmp_path):
    from support.user_robot import write_user_robot  # the STL-mesh SCARA the URDF tests build

    from twin.robot.profile_files import get_profile

    config = TwinConfig(profile=get_profile(str(write_user_robot(tmp_path))))
    path = tmp_path / "stl.rrd"
    recorder = RerunRecorder(path, config, urdf_text(config.profile))
    twin = Twin(config, sinks=[recorder])
    try:
        twin.move_to(0.5, 0.3)
    finally:
        twin.close()
        recorder.close()
    verify_rrd(path)
    meshes = {
        c.entity_path
        for c in RrdReader(str(path)).stream()
        if c.is_static and "Asset3D:blob" in c.to_record_batch().schema.names
    }
    links = ("base", "arm1", "arm2", "quill", "tool0")
    assert {f"/robot/stl_scara/visual_geometries/{link}/visual_0" for link in links} <= meshes
    steps, shoulder = read_scalars(path, f"/{scene.ANGLES_PATH}/shoulder")
    assert len(steps) == recorder.frames_written == twin.step_index + 1
    assert shoulder[-1] == twin.frame.joint_q[0]


def test_to_stream_logs_into_a_stream_the_caller_opened(tmp_path):
    config = TwinConfig()
    path = tmp_path / "own.rrd"
    stream = rr.RecordingStream(scene.APPLICATION_ID)
    stream.save(path)  # the caller's output choice; the recorder only logs
    recorder = RerunRecorder.to_stream(stream, config, urdf_text(config.profile), batch_steps=7)
    twin = Twin(config, sinks=[recorder])
    twin.step(20)
    twin.close()
    recorder.close()
    stream.flush()
    stream.disconnect()
    verify_rrd(path)
    steps, elbow_rad = read_scalars(path, f"/{scene.ANGLES_PATH}/elbow")
    np.testing.assert_array_equal(steps, np.arange(21))
    assert elbow_rad[-1] == twin.frame.joint_q[1]
    assert RrdReader(str(path)).blueprints() == []  # the caller sends its own blueprint, if any


@pytest.mark.parametrize(
    "objects", [(), (SceneObject("box a/b"), SceneObject("box2", pos_m=(0.3, 0.6, 0.025)))]
)
def test_any_number_of_objects_with_any_names(tmp_path, objects):
    config = TwinConfig(objects=objects)
    path = tmp_path / "scene.rrd"
    with RerunRecorder(path, config, urdf_text(config.profile), batch_steps=4) as recorder:
        twin = Twin(config, sinks=[recorder])
        twin.step(10)
        twin.close()
    verify_rrd(path)
    for k, obj in enumerate(objects):
        steps, translations = _component(
            path, "/" + scene.object_path(obj.name), "Transform3D:translation"
        )
        np.testing.assert_array_equal(steps, np.arange(11))
        np.testing.assert_allclose(translations[-1][0], twin.frame.object_poses[k][:3], atol=1e-6)
    assert recorder.frames_written == 11


@pytest.mark.parametrize("source", ["mtb", "tilted"])
def test_the_drawing_and_the_mcap_transforms_pose_every_joint_alike(source):
    """Both read the joints through robot.urdf: the vectorised poses (Rerun) and the scalar ones
    (the MCAP's /tf) agree to rounding for every moving joint."""
    from twin.record.mcap.scene_tf import SceneTransforms

    text = urdf_text(PROFILES["mtb"]) if source == "mtb" else _urdf_with_tilted_joints()
    joints = [j for j in urdf_joints(text) if j.moving]
    scalar = SceneTransforms(text, tuple(j.name for j in joints), ())
    values = np.array([-2.5, -0.7, 0.0, 0.05, 0.9, 2.9])
    for joint, digested in zip(joints, [j for j in scalar.joints if j.column >= 0], strict=True):
        translations, quaternions = JointMotion.from_urdf_joint(joint).transforms(values)
        for k, value in enumerate(values):
            xyz, quat = digested.pose(float(value))
            np.testing.assert_allclose(translations[k], xyz, rtol=0, atol=1e-15)
            np.testing.assert_allclose(quaternions[k], quat, rtol=0, atol=1e-15)
