"""`twin view --web` in a real browser: Debian's chromium (headless, driven by Playwright) opens the
URL the command prints and shows the recording, its camera pictures beside the 3D view, not Rerun's
welcome page (which the same server shows without the URL's ?url=); once the page has it, the
serving processes idle."""

from __future__ import annotations

import os
import re
import select
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image
from support.cpu import tree_cpu_over_s

pytestmark = [
    pytest.mark.slow,  # the web viewer's WASM takes 40-70 s to load here
    pytest.mark.skipif(
        shutil.which("chromium") is None,
        reason="needs Debian's chromium (tools/setup_test_system.sh)",
    ),
]
LOAD_TIMEOUT_S = 240
# a screenshot of a software-rendered WebGL page waits for a frame: 30 s (Playwright's default)
# ran out once on a machine loaded by other jobs
SHOT_TIMEOUT_MS = 120_000
# Once the page shows the recording, all that `twin view --web` runs together: measured 9.6 s of CPU
# over 10 s while rerun's gRPC server streamed the file, 0.00 s with the .rrd over plain HTTP.
IDLE_WALL_S = 5.0
IDLE_MAX_CPU_S = 0.5
URL = re.compile(
    r"serving the web viewer at (http://127\.0\.0\.1:\d+/)(\?url=\S+) \(Ctrl-C to stop\)$"
)


def _colours(png) -> dict[str, int]:
    """Pixel counts of the recording's colours: the arm's orange links, the blue box, the joint
    plots' lines."""
    image = np.asarray(Image.open(png).convert("RGB")).astype(int)
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    return {
        "orange": int(((r > 180) & (g > 100) & (g < 200) & (b < 90)).sum()),
        "blue box": int(((b > 180) & (r < 90) & (g > 90) & (g < 150)).sum()),
    }


def _shows_recording(colours: dict[str, int]) -> bool:
    return colours["orange"] > 3000 and colours["blue box"] > 400


@pytest.fixture
def web_view(camera_run, tmp_path):
    """`twin view CAMERA.rrd --web` as a real process: (its pid, the printed URL's page and
    query). The session's camera run (the viewer only reads it), not one recorded for this test."""
    env = {**os.environ, "HOME": str(tmp_path), "TMPDIR": str(tmp_path)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin.cli", "view", str(camera_run["rrd"]), "--web"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env=env,
    )
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 120)
        line = proc.stdout.readline().strip() if ready else ""
        match = URL.match(line)
        assert match, f"no URL line: {line!r}"
        yield proc.pid, match[1], match[2]
    finally:
        try:
            os.killpg(proc.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
        proc.wait(timeout=30)


def test_the_printed_url_opens_the_recording_in_chromium(web_view, tmp_path):
    from playwright.sync_api import sync_playwright

    pid, page_url, query = web_view
    shots = {"printed": tmp_path / "printed.png", "bare": tmp_path / "bare.png"}
    seen: dict[str, dict[str, int]] = {}
    with sync_playwright() as p:
        browser = p.chromium.launch(
            executable_path=shutil.which("chromium"),
            args=["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
        )
        try:
            pages = {}
            for name, url in (("printed", page_url + query), ("bare", page_url)):
                pages[name] = browser.new_page(viewport={"width": 1280, "height": 800})
                pages[name].goto(url)
            deadline = time.monotonic() + LOAD_TIMEOUT_S
            # only the printed page is looked at while both load: a screenshot makes the software
            # renderer draw a frame, so each costs CPU the loading pages need
            while time.monotonic() < deadline:
                pages["printed"].wait_for_timeout(5000)
                pages["printed"].screenshot(path=shots["printed"], timeout=SHOT_TIMEOUT_MS)
                seen["printed"] = _colours(shots["printed"])
                if _shows_recording(seen["printed"]):
                    break
            # the bare page has had as long to load; meanwhile nothing is asked of the server
            served_cpu_s = tree_cpu_over_s(pid, IDLE_WALL_S)
            pages["bare"].screenshot(path=shots["bare"], timeout=SHOT_TIMEOUT_MS)
            seen["bare"] = _colours(shots["bare"])
        finally:
            browser.close()
    assert _shows_recording(seen["printed"]), (
        f"the page never showed the recording: {seen} ({shots['printed']})"
    )
    assert not _shows_recording(seen["bare"]), (
        f"without ?url= the page is Rerun's welcome page: {seen}"
    )
    assert served_cpu_s < IDLE_MAX_CPU_S, (
        f"twin view --web used {served_cpu_s:.2f} s of CPU over {IDLE_WALL_S} s with the page open"
    )
