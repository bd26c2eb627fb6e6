"""A recorded camera is in the MCAP file as foxglove.CompressedImage and CameraCalibration channels
that the stock mcap reader decodes with Foxglove's schemas from the file alone; twin.load gives the
pictures."""

from __future__ import annotations

import io
import json

import numpy as np
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from PIL import Image

import twin
from twin.cli.main import main
from twin.model.config import TwinConfig
from twin.pictures import track_rgb

PICTURES = 89  # a pick_place cycle: steps 0..1419, a picture every 16 steps


def _decoded(path, topic: str) -> list:
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [
            (schema.name, channel, message, proto)
            for schema, channel, message, proto in reader.iter_decoded_messages(topics=[topic])
        ]


def test_image_channel_decodes_with_the_stock_reader_and_foxglove_schemas(camera_run):
    pictures = _decoded(camera_run["mcap"], "/camera/overhead/image")
    assert len(pictures) == PICTURES
    schema, channel, message, first = pictures[0]
    assert schema == "foxglove.CompressedImage" and channel.message_encoding == "protobuf"
    assert first.frame_id == "camera_overhead" and first.format == "png"
    image = Image.open(io.BytesIO(first.data))
    assert image.format == "PNG" and image.size == (320, 240)
    # the file's own schema decodes to what Foxglove's published message type reads
    assert CompressedImage.FromString(message.data).data == first.data
    times = [m.log_time for _, _, m, _ in pictures]
    assert times == sorted(times) and times[1] - times[0] == 16 * TwinConfig().dt_ns
    assert [p.timestamp.ToNanoseconds() for *_, p in pictures] == times


def test_calibration_goes_with_each_picture(camera_run):
    calibrations = _decoded(camera_run["mcap"], "/camera/wrist/calibration")
    assert len(calibrations) == PICTURES
    schema, _, _, c = calibrations[0]
    assert schema == "foxglove.CameraCalibration"
    assert (c.frame_id, c.width, c.height, c.distortion_model) == (
        "camera_wrist",
        320,
        240,
        "plumb_bob",
    )
    fx, _, cx, _, fy, cy, *_ = c.K
    assert fx == fy > 0 and (cx, cy) == (160, 120)
    assert list(c.P[:3]) == list(c.K[:3]) and c.P[3] == 0


def test_camera_pose_is_on_tf(camera_run):
    transforms = [
        t
        for *_, m in _decoded(camera_run["mcap"], "/tf")
        for t in m.transforms
        if t.child_frame_id == "camera_overhead"
    ]
    assert len(transforms) == PICTURES
    assert transforms[0].parent_frame_id == "world"
    assert (
        transforms[0].translation.x,
        transforms[0].translation.y,
        transforms[0].translation.z,
    ) == (0.0, 0.075, 1.6)


def test_twin_load_gives_the_pictures(camera_run):
    rec = twin.load(camera_run["mcap"])
    assert [c.name for c in rec.config.cameras] == ["overhead", "wrist"]
    track = rec.cameras["wrist"]
    assert (track.name, track.width_px, track.height_px, track.format) == ("wrist", 320, 240, "png")
    assert (
        track.step.dtype == np.int64
        and track.t_ns.dtype == np.int64
        and len(track.data) == PICTURES
    )
    assert list(track.step[:3]) == [0, 16, 32] and np.array_equal(
        track.t_ns, track.step * rec.config.dt_ns
    )
    pixels = track_rgb(track, 40)
    assert pixels.shape == (240, 320, 3) and pixels.dtype == np.uint8 and pixels.std() > 10


def test_config_stores_the_cameras_and_a_run_without_them_stores_none(camera_run):
    with open(camera_run["mcap"], "rb") as f:
        records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    config = json.loads(records["twin.config"]["json"])
    assert [c["name"] for c in config["cameras"]] == ["overhead", "wrist"]
    assert config["cameras"][0]["rate_hz"] == 15.0
    assert "cameras" not in TwinConfig().to_dict()


def test_camera_options_refuse_bad_values_in_one_line(capsys, tmp_path):
    for argv, expected in (
        (["--camera", "side"], "invalid choice: 'side'"),
        (
            ["--camera", "overhead", "--camera-size", "320"],
            "--camera-size '320' is invalid; expected WxH",
        ),
        (["--camera", "overhead", "--camera-size", "8x8"], "each 16..4096 pixels"),
        (["--camera-hz", "5"], "--camera-size and --camera-hz need a --camera NAME"),
        (["--camera", "overhead", "--camera-hz", "0"], "camera 'overhead' rate 0.0 Hz is invalid"),
        (["--camera", "wrist", "--camera", "wrist"], "names a camera twice"),
    ):
        code = main(["run", "pick_place", "--record", str(tmp_path / "x.mcap"), *argv])
        err = capsys.readouterr().err
        assert (
            code == 2
            and err.startswith("twin: error: ")
            and expected in err
            and err.count("\n") == 1
        ), err
    assert not (tmp_path / "x.mcap").exists()


def test_a_pictures_pose_is_read_from_the_files_tf_also_when_decimated(tmp_path):
    """The pad camera's pose on /tf is where it was when the picture was taken; a decimated file
    (rate 3, a picture every 16 steps) holds no frame at most picture steps, and load gives that
    pose exactly."""
    from twin.model.images import camera
    from twin.record import open_recorders
    from twin.record.images import recorded_images
    from twin.sim.world import engine_versions
    from twin.verify.check import record_task
    from twin.verify.collectors import FrameCollector

    config = TwinConfig(cameras=(camera("wrist", (64, 48)),))
    collector = FrameCollector()
    run = {"source": "task", "task": "pick_place", "params": {"cycles": 1}}
    with open_recorders(
        config, run, mcap_path=tmp_path / "r3.mcap", rate=3, engine=engine_versions()
    ) as sinks:
        record_task(config, "pick_place", {"cycles": 1}, sinks=[collector, *sinks])
    rec = twin.load(tmp_path / "r3.mcap")
    track = rec.cameras["wrist"]
    assert len(track) == len(collector.images) == PICTURES
    assert np.array_equal(track.pose, np.array([im.pose for im in collector.images]))
    assert any(int(s) % 3 for s in track.step)  # pictures between the file's frames
    shown = recorded_images(rec.config.cameras, rec.cameras, rec.frames.step, rec.frames.pad_pose)
    assert [im.pose for im in shown] == [im.pose for im in collector.images]
