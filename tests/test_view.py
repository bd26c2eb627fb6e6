"""`twin view`: MCAP -> .rrd conversion, a headless screenshot that shows the arm, the box and the plots,
the web viewer, and one-line errors (exit 2) for bad files."""

import glob
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pytest

from twin.cli import main
from twin.record import rerun_scene as scene
from twin.record.mcap_reader import load
from twin.record.rrd_file import read_scalars, verify_rrd
from twin.record.viewer import holding_time_ns

HAVE_VULKAN = bool(glob.glob("/usr/share/vulkan/icd.d/*.json"))


@pytest.fixture(autouse=True)
def rerun_home(tmp_path, monkeypatch):
    """The `rerun` CLI writes an analytics config under the home directory: keep it in a tmp dir."""
    home = tmp_path / "home"
    home.mkdir()
    for var, sub in (("HOME", ""), ("XDG_CONFIG_HOME", "config"), ("XDG_DATA_HOME", "data"),
                     ("XDG_CACHE_HOME", "cache")):
        monkeypatch.setenv(var, str(home / sub))
    return home


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """One pick_place cycle recorded as MCAP and .rrd by `twin run`."""
    tmp = tmp_path_factory.mktemp("view")
    mcap, rrd = tmp / "pick_place.mcap", tmp / "pick_place.rrd"
    env = {**os.environ, "HOME": str(tmp)}
    done = subprocess.run([sys.executable, "-m", "twin.cli", "run", "pick_place", "--cycles", "1", "--record",
                           str(mcap), "--rrd", str(rrd)], capture_output=True, text=True, env=env, timeout=120,
                          check=False)
    assert done.returncode == 0, done.stderr
    return {"tmp": tmp, "mcap": mcap, "rrd": rrd}


def _one_line_error(capsys, argv: list[str], *expected: str) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("twin: error: "), captured.err
    assert "Traceback" not in captured.err
    for text in expected:
        assert text in lines[0]


def test_mcap_converts_to_an_rrd_with_every_frame(recorded, capsys):
    out = recorded["tmp"] / "converted.rrd"
    assert main(["view", str(recorded["mcap"]), "--rrd", str(out)]) == 0
    recording = load(recorded["mcap"])
    assert capsys.readouterr().out.strip() == f"wrote {out}: {len(recording.frames)} frames"
    verify_rrd(out)
    steps, z = read_scalars(out, f"/{scene.Z_PATH}/z")
    np.testing.assert_array_equal(steps, recording.frames.step)
    np.testing.assert_array_equal(z, recording.frames.joint_q[:, 2])
    # The run's own .rrd and the converted one hold the same plot data.
    steps_run, z_run = read_scalars(recorded["rrd"], f"/{scene.Z_PATH}/z")
    np.testing.assert_array_equal(steps_run, steps)
    np.testing.assert_array_equal(z_run, z)


def test_bad_files_are_one_line_errors(tmp_path, recorded, capsys):
    empty = tmp_path / "empty.rrd"
    empty.write_bytes(b"")
    text = tmp_path / "notes.rrd"
    text.write_text("not a recording\n")
    cut_rrd = tmp_path / "cut.rrd"
    cut_rrd.write_bytes(recorded["rrd"].read_bytes()[:4000])
    cut_mcap = tmp_path / "cut.mcap"
    cut_mcap.write_bytes(recorded["mcap"].read_bytes()[:3000])
    _one_line_error(capsys, ["view", str(tmp_path / "missing.mcap")], "missing.mcap", "does not exist")
    _one_line_error(capsys, ["view", str(empty)], "empty.rrd", "is empty")
    _one_line_error(capsys, ["view", str(text)], "notes.rrd", "neither an MCAP nor a Rerun .rrd file")
    _one_line_error(capsys, ["view", str(cut_rrd)], "cut.rrd", "not a valid .rrd file")
    _one_line_error(capsys, ["view", str(cut_mcap), "--screenshot", str(tmp_path / "x.png")], "cut.mcap")
    _one_line_error(capsys, ["view", str(tmp_path)], "is not a file")
    _one_line_error(capsys, ["view", str(recorded["rrd"]), "--rrd", str(tmp_path / "y.rrd")], "already a Rerun")
    _one_line_error(capsys, ["view", str(recorded["mcap"]), "--rrd", str(tmp_path / "no" / "y.rrd")],
                    "does not exist")
    assert not (tmp_path / "x.png").exists()


def test_holding_time_is_the_end_of_the_first_hold(recorded):
    recording = load(recorded["mcap"])
    held = np.flatnonzero(recording.frames.held_body >= 0)
    assert held.size > 0
    last_of_first_hold = held[np.flatnonzero(np.diff(held) > 1)[0]] if (np.diff(held) > 1).any() else held[-1]
    assert holding_time_ns(recorded["rrd"]) == recording.frames.t_ns[last_of_first_hold]


@pytest.mark.skipif(not HAVE_VULKAN, reason="no Vulkan driver (Debian: mesa-vulkan-drivers) for the headless viewer")
def test_screenshot_shows_the_arm_the_box_and_the_plots(recorded, capsys):
    from PIL import Image

    png = recorded["tmp"] / "pick_place.png"
    assert main(["view", str(recorded["mcap"]), "--screenshot", str(png)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"wrote {png}: the viewer at t = ") and "view reported" not in out
    image = np.asarray(Image.open(png).convert("RGB")).astype(int)
    assert image.shape == (800, 1280, 3)
    assert image.std() > 20.0  # not a blank or single-colour frame
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    left, right = slice(0, 700), slice(720, 1280)  # the 3D view, then the plots (column shares 5:4)
    orange = (r > 180) & (g > 100) & (g < 200) & (b < 90)  # the arm's links
    blue = (b > 150) & (r < 90) & (g < 140)  # the box
    green = (g > 150) & (r < 100) & (b < 140)  # the pad holding the box, the 'holding' plot line
    assert orange[:, left].sum() > 1000
    assert blue[:, left].sum() > 200
    assert green[:, left].sum() > 60
    assert orange[:, right].sum() > 300  # the elbow and z lines
    assert blue[:, right].sum() > 300  # the shoulder line
    assert green[:, right].sum() > 100
    _one_line_error(capsys, ["view", str(recorded["rrd"]), "--screenshot", str(png), "--at", "99"],
                    "time 99.000 s is after the end of the recording")


def _end_group(proc: subprocess.Popen) -> None:
    """Stop the twin process started here and the viewer it started (its own session's group)."""
    try:
        os.killpg(proc.pid, signal.SIGTERM)
    except ProcessLookupError:
        pass  # already gone
    proc.wait(timeout=10)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_web_viewer_is_served_on_localhost(recorded, rerun_home):
    port = _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "twin.cli", "view", str(recorded["rrd"]), "--web", "--port",
                             str(port)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            start_new_session=True)
    try:
        page = ""
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2) as response:
                    page = response.read().decode(errors="replace")
                break
            except OSError:
                time.sleep(0.2)
        assert "web viewer" in page.lower() and "<html" in page.lower()
    finally:
        _end_group(proc)
    assert proc.stdout.read().startswith(f"serving the web viewer at http://127.0.0.1:{port}")


@pytest.mark.skipif(not (HAVE_VULKAN and shutil.which("Xvfb")), reason="needs Vulkan and Xvfb for a window")
def test_native_viewer_opens_a_window_and_stays_up(recorded, rerun_home):
    # Our own X server on a display it picks itself (-displayfd): no race with other X servers.
    xvfb = subprocess.Popen(["Xvfb", "-displayfd", "1", "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True)
    try:
        display = xvfb.stdout.readline().strip()
        assert display.isdigit(), "Xvfb did not report its display"
        proc = subprocess.Popen([sys.executable, "-m", "twin.cli", "view", str(recorded["mcap"])],
                                env={**os.environ, "DISPLAY": f":{display}"}, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True, start_new_session=True)
        try:
            time.sleep(4.0)  # a viewer that cannot start exits within a second or two
            alive = proc.poll() is None
        finally:
            _end_group(proc)
        assert alive, proc.stderr.read()[-2000:]
    finally:
        xvfb.terminate()
        xvfb.wait(timeout=10)


def test_a_run_that_never_holds_is_shown_at_its_end(tmp_path):
    from twin.config import TwinConfig
    from twin.record.rerun_writer import RerunRecorder
    from twin.twin import Twin
    from twin.urdf import urdf_text

    config = TwinConfig()
    path = tmp_path / "no_hold.rrd"
    with RerunRecorder(path, config, urdf_text(config.profile)) as recorder:
        twin = Twin(config, sinks=[recorder])
        twin.move_to(0.5, 0.2)
        twin.close()
    assert holding_time_ns(path) is None


@pytest.mark.skipif(not HAVE_VULKAN, reason="no Vulkan driver (Debian: mesa-vulkan-drivers) for the headless viewer")
def test_screenshot_of_another_programs_rrd_shows_its_end(tmp_path, capsys):
    import rerun as rr

    path = tmp_path / "other.rrd"
    stream = rr.RecordingStream("another_program")
    stream.save(path)
    for i in range(10):
        stream.set_time("frame", sequence=i)
        stream.log("points", rr.Points3D([[0.1 * i, 0.0, 0.0]], radii=0.05))
    stream.flush()
    stream.disconnect()
    png = tmp_path / "other.png"
    assert main(["view", str(path), "--screenshot", str(png), "--at", "2.5"]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {png}: the viewer at the end of the run"
    assert png.stat().st_size > 10_000
