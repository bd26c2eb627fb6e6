"""A camera run's .rrd holds each picture as an encoded image on the camera's entity (also when an
MCAP file is drawn), and the viewer shows the pictures beside the 3D view, which frames the whole
workspace."""

from __future__ import annotations

import glob

import numpy as np
import pytest
from PIL import Image
from rerun.chunk import RrdReader

import twin
from twin.cli.main import main


@pytest.fixture(autouse=True)
def rerun_home(tmp_path, monkeypatch):
    """The `rerun` CLI writes an analytics config under the home directory: keep it in a tmp dir."""
    for var in ("HOME", "XDG_CONFIG_HOME", "XDG_DATA_HOME", "XDG_CACHE_HOME", "TMPDIR"):
        (tmp_path / var).mkdir()
        monkeypatch.setenv(var, str(tmp_path / var))


def _pictures(rrd, entity: str) -> dict[int, bytes]:
    """step -> the encoded picture logged on entity."""
    out = {}
    for chunk in RrdReader(str(rrd)).stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if "EncodedImage:blob" not in batch.schema.names:
            continue
        steps = batch.column("step").to_pylist()
        for step, blob in zip(steps, batch.column("EncodedImage:blob").to_pylist(), strict=True):
            out[step] = bytes(blob[0])
    return out


def test_rrd_holds_every_picture_on_the_cameras_entity(camera_run, tmp_path, capsys):
    rec = twin.load(camera_run["mcap"])
    for name in ("overhead", "wrist"):
        track = rec.cameras[name]
        live = _pictures(camera_run["rrd"], f"/world/cameras/{name}")
        assert live == dict(zip(track.step.tolist(), track.data, strict=True))
    drawn = tmp_path / "drawn.rrd"
    assert main(["view", str(camera_run["mcap"]), "--rrd", str(drawn)]) == 0
    assert _pictures(drawn, "/world/cameras/wrist") == _pictures(
        camera_run["rrd"], "/world/cameras/wrist"
    )


@pytest.mark.slow
@pytest.mark.skipif(
    not glob.glob("/usr/share/vulkan/icd.d/*.json"), reason="the headless viewer needs Vulkan"
)
def test_viewer_shows_the_pictures_beside_the_3d_view(camera_run, tmp_path, capsys):
    png = tmp_path / "camera.png"
    # at the attach
    assert main(["view", str(camera_run["rrd"]), "--screenshot", str(png), "--at", "2.27"]) == 0
    image = np.asarray(Image.open(png).convert("RGB")).astype(int)
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    view_3d, pictures = slice(0, 550), slice(565, 830)  # column shares 5 : 2.5 : 4 of 1280 px
    white = (r > 250) & (g > 250) & (b > 250)  # the rendered pictures' background
    blue = (b > 150) & (r < 90) & (g < 140)  # the box
    orange = (r > 180) & (g > 100) & (g < 200) & (b < 90)  # the arm's links
    assert white[80:760, pictures].mean() > 0.3  # the two camera views show pictures
    assert blue[:, pictures].sum() > 500  # the box under the pad, large in the wrist picture
    # the whole arm and the box in 3D
    assert blue[:, view_3d].sum() > 20 and orange[:, view_3d].sum() > 300
    # the 3D view below its title bar (the top bar has orange text)
    inside = (orange | blue)[45:765, 0:550]
    rows, cols = np.nonzero(inside)
    # nothing cut off
    assert rows.min() > 10 and rows.max() < 710 and cols.min() > 10 and cols.max() < 540
