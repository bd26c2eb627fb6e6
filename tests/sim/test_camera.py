"""Cameras render what the twin does, the same pixels every time, without touching the physics."""

from __future__ import annotations

import numpy as np
import pytest

from twin import load as load_recording
from twin.model.config import TwinConfig
from twin.model.images import CAMERAS, CameraSpec, camera, camera_view, optical_pose
from twin.model.quat import rotate
from twin.pictures import decode_rgb
from twin.sim.camera import CameraRenderer, RenderWorld, render_frame
from twin.sim.twin import Twin
from twin.tasks import TASKS, run_task
from twin.verify.collectors import ColumnCollector

SMALL = (160, 120)


def _run(cameras: tuple[CameraSpec, ...], steps: int | None = None) -> ColumnCollector:
    collector = ColumnCollector()
    twin = Twin(TwinConfig(cameras=cameras), sinks=[collector])
    try:
        if steps is None:
            run_task(twin, TASKS["pick_place"], {"cycles": 1})
        else:
            twin.step(steps)
    finally:
        twin.close()
    return collector


@pytest.fixture(scope="module")
def pick_place_with_cameras() -> ColumnCollector:
    return _run((camera("overhead", SMALL), camera("wrist", SMALL)))


def test_cameras_leave_the_physics_untouched(pick_place_with_cameras):
    plain = _run(()).columns()
    with_cameras = pick_place_with_cameras.columns()
    assert len(plain) == len(with_cameras) > 1000
    for name in ("joint_q", "joint_qd", "object_poses", "hold_force_n"):
        assert np.array_equal(getattr(plain, name), getattr(with_cameras, name)), name


def test_pictures_come_at_the_cameras_rate_in_step_order(pick_place_with_cameras):
    images = pick_place_with_cameras.images
    every = camera("overhead").every_steps(TwinConfig().dt_ns)
    assert every == 16  # 15 Hz at 240 Hz
    last = int(pick_place_with_cameras.columns().step[-1])
    for name in ("overhead", "wrist"):
        steps = [im.step for im in images if im.camera == name]
        assert steps == list(range(0, last + 1, every))
    assert all(
        im.format == "png" and decode_rgb(im.data).shape == (120, 160, 3) for im in images[:4]
    )


def test_the_same_run_gives_the_same_bytes(pick_place_with_cameras):
    again = _run((camera("overhead", SMALL), camera("wrist", SMALL)))
    assert [im.data for im in again.images] == [im.data for im in pick_place_with_cameras.images]


def test_the_render_process_draws_what_the_stepping_thread_would(pick_place_with_cameras):
    config = TwinConfig(cameras=(camera("overhead", SMALL), camera("wrist", SMALL)))
    frames = pick_place_with_cameras.columns()
    world = RenderWorld(config)
    try:
        for i in (0, 608, 1008):  # camera steps (every 16th)
            frame = frames.frame(i)
            here = render_frame(world, config.cameras, frame)
            there = [im for im in pick_place_with_cameras.images if im.step == frame.step]
            assert [im.data for im in here] == [im.data for im in there]
    finally:
        world.close()


def _pixel_of(
    spec: CameraSpec, pad_pose: tuple, point: tuple[float, float, float]
) -> tuple[int, int]:
    """Where a world point lands in the picture (column, row), from the camera's pose and K."""
    pose = optical_pose(*camera_view(spec, pad_pose))
    inverse = (-pose[3], -pose[4], -pose[5], pose[6])
    x, y, z = rotate(inverse, tuple(p - e for p, e in zip(point, pose[:3], strict=True)))
    k = spec.intrinsics()
    return round(k[0] * x / z + k[2]), round(k[4] * y / z + k[5])


def test_overhead_sees_the_box_where_it_stands():
    spec = camera("overhead")
    collector = _run((spec,), steps=1)
    first = collector.images[0]
    pixels = decode_rgb(first.data)
    # the box's top
    col, row = _pixel_of(spec, collector.columns().frame(0).pad_pose, (0.2, 0.7, 0.05))
    r, g, b = (int(v) for v in pixels[row, col])
    assert b > r + 80 and b > 150, (col, row, (r, g, b))  # the box is blue (0.2, 0.5, 0.9)
    # the empty place point
    col, row = _pixel_of(spec, collector.columns().frame(0).pad_pose, (-0.3, -0.55, 0.0))
    assert np.array_equal(pixels[row, col], pixels[0, 0])  # nothing there yet: the background


def test_wrist_camera_moves_with_the_pad(pick_place_with_cameras):
    wrist = [im for im in pick_place_with_cameras.images if im.camera == "wrist"]
    frames = pick_place_with_cameras.columns()
    for im in (wrist[0], wrist[40]):
        pad = frames.pad_pose[im.step]
        offset = np.asarray(im.pose[:3]) - pad[:3]
        expected = rotate(tuple(pad[3:]), CAMERAS["wrist"].eye_m)
        assert np.allclose(offset, expected, atol=1e-12)
    assert wrist[0].data != wrist[40].data


def test_a_twin_without_cameras_has_no_renderer():
    twin = Twin(TwinConfig())
    try:
        assert not any(isinstance(s, CameraRenderer) for s in twin.sinks)
    finally:
        twin.close()


def test_a_jpeg_camera_gives_jpeg_pictures():
    from dataclasses import replace

    spec = replace(camera("overhead", SMALL), format="jpeg")
    images = _run((spec,), steps=20).images
    assert [im.step for im in images] == [0, 16]
    assert all(im.format == "jpeg" and im.data[:2] == b"\xff\xd8" for im in images)
    assert decode_rgb(images[0].data).shape == (120, 160, 3)


def test_drawn_here_or_in_the_render_process_the_file_is_byte_identical(
    pick_place_with_cameras, tmp_path
):
    """A daemon process (a pool's worker) may not fork, so it draws the pictures itself: it hands
    them on at the same points of the run, so its MCAP file is the one the render process gives."""
    from twin.record.mcap.writer import McapRecorder
    from twin.robot.urdf import urdf_text

    config = TwinConfig(cameras=(camera("overhead", SMALL), camera("wrist", SMALL)))
    frames = pick_place_with_cameras.columns()
    files = []
    for background in (True, False):
        path = tmp_path / f"background_{background}.mcap"
        recorder = McapRecorder(
            path,
            config,
            {"source": "task", "task": "", "params": {}},
            urdf=urdf_text(config.profile),
        )
        renderer = CameraRenderer(config, recorder.on_image, background=background)
        for i in range(len(frames)):
            frame = frames.frame(i)
            recorder.on_frame(frame)
            renderer.on_frame(frame)
        renderer.close()
        recorder.close()
        files.append(path.read_bytes())
    assert files[0] == files[1]
    assert len(load_recording(tmp_path / "background_False.mcap").cameras["wrist"]) == 89
