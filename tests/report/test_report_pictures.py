"""The pictures at the onset: `twin diff --html` of two camera runs whose pick waits differ shows,
for each camera, the golden's and the candidate's first pictures after the onset that differ and
their difference, as inline PNGs that decode to the camera's size."""

from __future__ import annotations

import base64
import io
import re

from PIL import Image
from support.camera_run import record_camera_run
from support.cli import twin


def test_diff_html_shows_each_camera_at_the_onset(camera_run, tmp_path, capsys):
    other = record_camera_run(tmp_path, "--param", "pause_s=0.45")  # the default waits 0.5 s
    code, _, err = twin(capsys, "diff", camera_run["mcap"], other["mcap"], "--html",
                        tmp_path / "c.html")
    assert code == 1, err
    page = (tmp_path / "c.html").read_text()
    assert "camera overhead: the first pictures after the onset (step " in page
    assert "camera wrist: the first pictures after the onset" in page
    pictures = re.findall(r'<img alt="([^"]+)" src="data:image/png;base64,([^"]+)"', page)
    captions = [c for c, _ in pictures]
    assert len(pictures) == 6, captions  # golden, candidate, difference for each camera
    assert captions[0].startswith("golden, step ") and captions[1].startswith("candidate, step ")
    assert captions[2].startswith("difference")
    sizes = {Image.open(io.BytesIO(base64.b64decode(data))).size for _, data in pictures}
    assert all(w >= 64 and h >= 48 for w, h in sizes), sizes
    difference = Image.open(io.BytesIO(base64.b64decode(pictures[2][1]))).convert("RGB")
    golden = Image.open(io.BytesIO(base64.b64decode(pictures[0][1]))).convert("L")
    assert golden.getextrema()[1] > 0 and difference.size == golden.size
    # at the step where the frames first diverge the pictures differ too, and say so
    assert captions[2].startswith("difference (brightened x"), captions
    assert max(high for _, high in difference.getextrema()) == 255  # brightened to full scale
