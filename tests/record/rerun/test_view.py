"""`twin view`: MCAP -> .rrd conversion, a headless screenshot that shows the arm, the box and the
plots, the web and native viewers on loopback and free ports, side by side, their `rerun` child
never outliving `twin view` (SIGTERM, SIGHUP, SIGKILL), no temporary folder left behind, and
one-line errors (exit 2) for bad files, busy ports and a missing display."""

import glob
import os
import re
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request

import numpy as np
import psutil
import pytest
from support.cli import free_port
from support.cpu import tree_cpu_over_s

from twin.cli import main
from twin.record.mcap.reader import load
from twin.record.rerun import scene
from twin.record.rerun.rrd_file import read_scalars, verify_rrd
from twin.record.rerun.viewer import holding_time_ns

pytestmark = pytest.mark.slow  # seconds each: `-m "not slow"` leaves them out

HAVE_VULKAN = bool(glob.glob("/usr/share/vulkan/icd.d/*.json"))


@pytest.fixture(autouse=True)
def rerun_home(tmp_path, monkeypatch):
    """The `rerun` CLI writes an analytics config under the home directory: keep it in a tmp dir."""
    home = tmp_path / "home"
    home.mkdir()
    for var, sub in (
        ("HOME", ""),
        ("XDG_CONFIG_HOME", "config"),
        ("XDG_DATA_HOME", "data"),
        ("XDG_CACHE_HOME", "cache"),
    ):
        monkeypatch.setenv(var, str(home / sub))
    return home


@pytest.fixture(scope="module", autouse=True)
def no_view_folders_left_in_the_temp_dir():
    """However a test ends, no `twin-view-*` folder of ours is left in the system's temp dir."""
    before = set(glob.glob(os.path.join(tempfile.gettempdir(), "twin-view-*")))
    yield
    assert set(glob.glob(os.path.join(tempfile.gettempdir(), "twin-view-*"))) <= before


@pytest.fixture(autouse=True)
def view_tmp(tmp_path, monkeypatch):
    """A temp dir of the test's own (for `twin view` in this process and in children), empty when
    the test is over: no `twin-view-*` folder, nor a `rerun-data-*` one the viewer makes."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    yield tmp
    assert not list(tmp.iterdir())


@pytest.fixture(scope="module")
def recorded(pick_place_cli):
    """One pick_place cycle recorded as MCAP and .rrd by `twin run` (the session's shared
    recording)."""
    return pick_place_cli


def _one_line_error(capsys, argv: list[str], *expected: str) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("twin: error: "), captured.err
    assert "Traceback" not in captured.err
    for text in expected:
        assert text in lines[0]


def test_mcap_converts_to_an_rrd_with_every_frame(recorded, tmp_path, capsys):
    out = tmp_path / "converted.rrd"
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
    _one_line_error(
        capsys, ["view", str(tmp_path / "missing.mcap")], "missing.mcap", "does not exist"
    )
    _one_line_error(capsys, ["view", str(empty)], "empty.rrd", "is empty")
    _one_line_error(
        capsys, ["view", str(text)], "notes.rrd", "neither an MCAP nor a Rerun .rrd file"
    )
    _one_line_error(capsys, ["view", str(cut_rrd)], "cut.rrd", "not a valid .rrd file")
    _one_line_error(
        capsys, ["view", str(cut_mcap), "--screenshot", str(tmp_path / "x.png")], "cut.mcap"
    )
    _one_line_error(capsys, ["view", str(tmp_path)], "is not a file")
    _one_line_error(
        capsys, ["view", str(recorded["rrd"]), "--rrd", str(tmp_path / "y.rrd")], "already a Rerun"
    )
    _one_line_error(
        capsys,
        ["view", str(recorded["mcap"]), "--rrd", str(tmp_path / "no" / "y.rrd")],
        "does not exist",
    )
    assert not (tmp_path / "x.png").exists()


def test_holding_time_is_the_end_of_the_first_hold(recorded):
    recording = load(recorded["mcap"])
    held = np.flatnonzero(recording.frames.held_body >= 0)
    assert held.size > 0
    last_of_first_hold = (
        held[np.flatnonzero(np.diff(held) > 1)[0]] if (np.diff(held) > 1).any() else held[-1]
    )
    assert holding_time_ns(recorded["rrd"]) == recording.frames.t_ns[last_of_first_hold]


@pytest.mark.skipif(
    not HAVE_VULKAN, reason="no Vulkan driver (Debian: mesa-vulkan-drivers) for the headless viewer"
)
def test_screenshot_shows_the_arm_the_box_and_the_plots(recorded, tmp_path, capsys):
    from PIL import Image

    png = tmp_path / "pick_place.png"
    png.write_bytes(b"the user's own picture")  # --force replaces it, once the new one is whole
    assert main(["view", str(recorded["mcap"]), "--screenshot", str(png), "--force"]) == 0
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
    shown = png.read_bytes()
    _one_line_error(
        capsys,
        ["view", str(recorded["rrd"]), "--screenshot", str(png), "--at", "99"],
        f"--screenshot {str(png)!r} exists already",
        "--force to replace it",
    )
    _one_line_error(
        capsys,
        ["view", str(recorded["rrd"]), "--screenshot", str(png), "--at", "99", "--force"],
        "time 99.000 s is after the end of the recording",
    )
    assert png.read_bytes() == shown  # a failed screenshot leaves the old picture whole


URL = re.compile(
    r"serving the web viewer at (http://127\.0\.0\.1:(\d+)/\?url=(\S+)) \(Ctrl-C to stop\)$"
)


def _start_view(*argv: str, env: dict[str, str] | None = None) -> subprocess.Popen:
    """`twin view ARGV` as a real process in a session of its own."""
    return subprocess.Popen(
        [sys.executable, "-m", "twin.cli", "view", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env=env,
    )


def _end_group(proc: subprocess.Popen) -> None:
    """Stop the twin process started here (its own session's group; its viewer has a group of its
    own)."""
    try:
        os.killpg(proc.pid, signal.SIGTERM)
    except ProcessLookupError:
        pass  # already gone
    proc.wait(timeout=30)


def _served(proc: subprocess.Popen, timeout_s: float = 120.0) -> tuple[str, int, int]:
    """(URL, web port, recording's port) from the line `twin view --web` prints once both listen:
    the page's ?url= names the .rrd, served over HTTP by twin view itself."""
    line = _first_line(proc, timeout_s)
    match = URL.match(line)
    assert match, (
        f"no URL line: {line!r}; stderr: {proc.stderr.read() if proc.poll() is not None else ''}"
    )
    source = urllib.parse.unquote(match[3])
    rrd = re.fullmatch(r"http://127\.0\.0\.1:(\d+)/[^/?#]+\.rrd", source)
    assert rrd, source
    return match[1], int(match[2]), int(rrd[1])


def _first_line(proc: subprocess.Popen, timeout_s: float) -> str:
    """The first line the process prints, or what came before timeout_s (never blocks past it: the
    viewer, a grandchild, keeps the pipe open, so a line without its newline would otherwise wait
    forever)."""
    deadline, data = time.monotonic() + timeout_s, b""
    fd = proc.stdout.fileno()
    while b"\n" not in data:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            break
        chunk = os.read(fd, 4096)
        if not chunk:
            break
        data += chunk
    return data.split(b"\n", 1)[0].decode(errors="replace").strip()


def _viewer_child(proc: subprocess.Popen) -> psutil.Process:
    (child,) = psutil.Process(proc.pid).children()
    assert child.name() == "rerun"
    return child


def _listening(process: psutil.Process) -> set[tuple[str, int]]:
    return {
        c.laddr[:2] for c in process.net_connections(kind="inet") if c.status == psutil.CONN_LISTEN
    }


_free_port = free_port


def test_two_web_viewers_run_side_by_side_on_loopback(recorded):
    first = _start_view(str(recorded["rrd"]), "--web")
    second = _start_view(str(recorded["mcap"]), "--web")
    try:
        url1, web1, grpc1 = _served(first)
        url2, web2, grpc2 = _served(second)
        assert len({web1, grpc1, web2, grpc2}) == 4
        for proc, web, grpc in ((first, web1, grpc1), (second, web2, grpc2)):
            assert _listening(_viewer_child(proc)) == {("127.0.0.1", web)}
            assert _listening(psutil.Process(proc.pid)) == {("127.0.0.1", grpc)}  # the .rrd
        for url in (url1, url2):
            with urllib.request.urlopen(url, timeout=10) as response:
                page = response.read().decode(errors="replace").lower()
            assert "<html" in page and "web viewer" in page
        assert first.poll() is None and second.poll() is None
    finally:
        _end_group(first)
        _end_group(second)


def test_given_ports_are_used_and_busy_ones_are_one_line_errors(recorded, capsys):
    web, grpc = _free_port(), _free_port()
    proc = _start_view(str(recorded["rrd"]), "--web", "--port", str(web), "--grpc-port", str(grpc))
    try:
        assert _served(proc)[1:] == (web, grpc)
        _one_line_error(
            capsys,
            ["view", str(recorded["rrd"]), "--web", "--port", str(web)],
            f"--port {web}: 127.0.0.1:{web} is already in use",
        )
        _one_line_error(
            capsys,
            ["view", str(recorded["rrd"]), "--web", "--grpc-port", str(grpc)],
            f"--grpc-port {grpc}: 127.0.0.1:{grpc} is already in use",
        )
    finally:
        _end_group(proc)
    _one_line_error(
        capsys,
        ["view", str(recorded["rrd"]), "--web", "--port", str(web), "--grpc-port", str(web)],
        f"--port and --grpc-port are the same port {web}",
    )


IDLE_WALL_S = 5.0
# Measured over 10 s of serving: rerun's gRPC server streaming the file used 9.6 s of CPU (one core
# spinning); the viewer's files and the .rrd over plain HTTP, 0.00 s.
IDLE_MAX_CPU_S = 0.5


def test_the_web_viewer_idles_while_it_serves(recorded):
    """Every process `twin view --web` runs (itself, rerun and what rerun starts) together use less
    than IDLE_MAX_CPU_S of CPU over IDLE_WALL_S of serving: no core kept busy for the user."""
    proc = _start_view(str(recorded["rrd"]), "--web")
    try:
        _served(proc)
        time.sleep(1.0)  # past the start-up
        used_s = tree_cpu_over_s(proc.pid, IDLE_WALL_S)
        assert proc.poll() is None
        assert used_s < IDLE_MAX_CPU_S, f"{used_s:.2f} s of CPU over {IDLE_WALL_S} s of serving"
    finally:
        _end_group(proc)


def _fetch(url: str, origin: str, method: str = "GET") -> tuple[int, dict[str, str], bytes]:
    request = urllib.request.Request(url, method=method, headers={"Origin": origin})
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status, dict(response.headers), response.read()
    except urllib.error.HTTPError as err:
        return err.code, dict(err.headers), b""


def test_the_recording_is_served_whole_and_to_the_viewer_page_only(recorded):
    proc = _start_view(str(recorded["rrd"]), "--web")
    try:
        url, web, port = _served(proc)
        source = urllib.parse.unquote(urllib.parse.urlparse(url).query.removeprefix("url="))
        page = f"http://127.0.0.1:{web}"
        status, headers, body = _fetch(source, page)
        assert status == 200 and body == recorded["rrd"].read_bytes()
        assert headers["Access-Control-Allow-Origin"] == page
        status, headers, body = _fetch(source, page, "HEAD")
        assert status == 200 and body == b""
        assert int(headers["Content-Length"]) == recorded["rrd"].stat().st_size
        # another page in the same browser may not read it; no other path is served
        status, headers, _ = _fetch(source, f"http://127.0.0.1:{_free_port()}")
        assert status == 200 and "Access-Control-Allow-Origin" not in headers
        assert _fetch(f"http://127.0.0.1:{port}/", page)[0] == 404
        assert _fetch(f"http://127.0.0.1:{port}/../{recorded['rrd'].name}", page)[0] == 404
        assert proc.poll() is None
    finally:
        _end_group(proc)


@pytest.mark.skipif(
    not HAVE_VULKAN, reason="no Vulkan driver (Debian: mesa-vulkan-drivers) for the headless viewer"
)
def test_the_printed_url_streams_the_recording(recorded, tmp_path):
    """What the web page loads from its ?url=: a headless viewer opens that source and gets the
    whole run."""
    from rerun.experimental import ViewerClient

    from twin.record.rerun.rrd_file import rerun_executable

    proc = _start_view(str(recorded["mcap"]), "--web")
    port = _free_port()
    # its own TMPDIR: a killed viewer leaves rerun-data-*
    with open(tmp_path / "headless.log", "wb") as log:
        headless = subprocess.Popen(
            [
                rerun_executable(),
                "--headless",
                "--bind",
                "127.0.0.1",
                "--port",
                str(port),
                "--hide-welcome-screen",
            ],
            stdout=log,
            stderr=log,
            start_new_session=True,
            env={**os.environ, "TMPDIR": str(tmp_path)},
        )
    try:
        url = _served(proc)[0]
        source = urllib.parse.unquote(urllib.parse.urlparse(url).query.removeprefix("url="))
        deadline = time.monotonic() + 60
        while True:
            try:
                client = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")
                client.get_state()
                break
            except Exception:  # noqa: BLE001 - whatever the client raises while the headless viewer is not up yet
                assert time.monotonic() < deadline and headless.poll() is None
                time.sleep(0.2)
        client.open(source)
        ends = {}
        while time.monotonic() < deadline and not ends.get(scene.TIME_TIMELINE):
            state = client.get_state()
            if not state.loading:
                ends = {t.name: t.end for r in state.recordings for t in r.timelines}
            time.sleep(0.2)
        recording = load(recorded["mcap"])
        assert ends[scene.TIME_TIMELINE] == recording.frames.t_ns[-1]
        assert ends["step"] == recording.frames.step[-1]
    finally:
        os.killpg(headless.pid, signal.SIGKILL)
        headless.wait(timeout=10)
        _end_group(proc)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_ends_the_viewer_and_removes_the_temp_folder(recorded, view_tmp, signum):
    proc = _start_view(str(recorded["mcap"]), "--web")  # an .mcap is drawn into a temporary .rrd
    try:
        _served(proc)
        child = _viewer_child(proc)
        assert len(list(view_tmp.glob("twin-view-*"))) == 1
        os.kill(proc.pid, signum)  # the twin process alone, as `kill` or a closed terminal does
        assert proc.wait(timeout=30) == 128 + signum
        assert proc.stderr.read().strip() == f"twin: stopped by {signal.Signals(signum).name}"
        _, alive = psutil.wait_procs([child], timeout=10)
        assert not alive, f"rerun {child.pid} outlived twin view"
    finally:
        _end_group(proc)
    assert not list(view_tmp.glob("twin-view-*"))


def test_the_viewer_dies_with_a_killed_twin(recorded, view_tmp):
    proc = _start_view(str(recorded["rrd"]), "--web")
    try:
        _served(proc)
        child = _viewer_child(proc)
        os.kill(proc.pid, signal.SIGKILL)
        assert proc.wait(timeout=30) == -signal.SIGKILL
        _, alive = psutil.wait_procs([child], timeout=10)
        assert not alive, f"rerun {child.pid} outlived twin view"
    finally:
        _end_group(proc)
    # Nothing runs after SIGKILL: the folder (here in the test's own temp dir) is left for the OS.
    for folder in view_tmp.glob("twin-view-*"):
        shutil.rmtree(folder)


def test_no_display_is_one_line_naming_the_other_ways(recorded, monkeypatch, capfd):
    for var in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(var, raising=False)
    assert main(["view", str(recorded["mcap"])]) == 2
    out, err = capfd.readouterr()
    assert out == "" and err.count("\n") == 1, err
    assert (
        err.startswith("twin: error: no display for the native viewer")
        and "--web, --rrd or --screenshot" in err
    )


def test_an_unreachable_display_is_one_line_without_rerun_noise(recorded, monkeypatch, capfd):
    """The real viewer starts, fails to reach the X server, and its log stays out of the
    terminal."""
    unused = next(n for n in range(90, 200) if not os.path.exists(f"/tmp/.X11-unix/X{n}"))
    monkeypatch.setenv("DISPLAY", f":{unused}")
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(recorded["rrd"])]) == 2
    out, err = capfd.readouterr()
    assert out == "" and err.count("\n") == 1, err
    assert err.startswith("twin: error: the native Rerun viewer exited with code 1")
    assert "X server" in err and "--web, --rrd or --screenshot" in err


@pytest.mark.skipif(
    not (HAVE_VULKAN and shutil.which("Xvfb")), reason="needs Vulkan and Xvfb for a window"
)
def test_native_viewer_opens_a_window_on_loopback_beside_a_web_viewer(recorded, view_tmp):
    # Our own X server on a display it picks itself (-displayfd): no race with other X servers.
    xvfb = subprocess.Popen(
        ["Xvfb", "-displayfd", "1", "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
    )
    try:
        display = xvfb.stdout.readline().strip()
        assert display.isdigit(), "Xvfb did not report its display"
        grpc = _free_port()
        native = _start_view(
            str(recorded["mcap"]),
            "--grpc-port",
            str(grpc),
            env={**os.environ, "DISPLAY": f":{display}"},
        )
        web = _start_view(str(recorded["rrd"]), "--web")
        try:
            _served(web)
            deadline = time.monotonic() + 60
            # converting, then starting
            while native.poll() is None and time.monotonic() < deadline:
                children = psutil.Process(native.pid).children()
                if children and _listening(children[0]):
                    break
                time.sleep(0.2)
            time.sleep(2.0)  # a viewer that cannot open its window exits within a second or two
            assert native.poll() is None, native.stderr.read()[-2000:]
            assert _listening(_viewer_child(native)) == {("127.0.0.1", grpc)}
            child = _viewer_child(native)
            os.kill(native.pid, signal.SIGTERM)
            assert native.wait(timeout=30) == 128 + signal.SIGTERM
            assert not psutil.wait_procs([child], timeout=10)[1]
            assert web.poll() is None
        finally:
            _end_group(native)
            _end_group(web)
    finally:
        xvfb.terminate()
        xvfb.wait(timeout=10)


def test_a_run_that_never_holds_is_shown_at_its_end(tmp_path):
    from twin.model.config import TwinConfig
    from twin.record.rerun.writer import RerunRecorder
    from twin.robot.urdf import urdf_text
    from twin.sim.twin import Twin

    config = TwinConfig()
    path = tmp_path / "no_hold.rrd"
    with RerunRecorder(path, config, urdf_text(config.profile)) as recorder:
        twin = Twin(config, sinks=[recorder])
        twin.move_to(0.5, 0.2)
        twin.close()
    assert holding_time_ns(path) is None


@pytest.mark.skipif(
    not HAVE_VULKAN, reason="no Vulkan driver (Debian: mesa-vulkan-drivers) for the headless viewer"
)
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
