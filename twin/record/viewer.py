"""Showing a recording in Rerun's viewer: the native window, the web viewer, or a headless screenshot.

An .mcap recording is drawn into a temporary .rrd first (twin.load + write_rrd); an .rrd is checked
(magic bytes and `rerun rrd verify`) before any viewer starts.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from twin.errors import RecordingError, TwinError
from twin.record import rerun_scene as scene
from twin.record.rerun_writer import write_rrd
from twin.record.rrd_file import file_kind, read_scalars, rerun_executable, verify_rrd
from twin.recording import Recording

DEFAULT_WINDOW_SIZE = "1280x800"
VIEWER_START_TIMEOUT_S = 30.0
LOAD_TIMEOUT_S = 60.0
TOAST_FADE_S = 2.0


class ViewerError(TwinError):
    """The Rerun viewer could not be started or did not answer."""


def load_recording(path: str | os.PathLike) -> Recording:
    """twin.load for an MCAP file (the MCAP reader owns the format and its errors)."""
    from twin.record.mcap_reader import load

    return load(path)


def as_rrd(path: str | os.PathLike, tmp_dir: str | os.PathLike) -> Path:
    """The .rrd to show for `path`: the file itself (verified), or an MCAP drawn into tmp_dir."""
    kind = file_kind(path)
    if kind == "rrd":
        verify_rrd(path)
        return Path(path)
    out = Path(tmp_dir) / (Path(path).stem + ".rrd")
    mcap_to_rrd(path, out)
    return out


def mcap_to_rrd(mcap_path: str | os.PathLike, rrd_path: str | os.PathLike) -> int:
    """Convert an MCAP recording to an .rrd; returns the frames written."""
    if file_kind(mcap_path) != "mcap":
        raise RecordingError(f"{str(mcap_path)!r} is already a Rerun .rrd file; expected an MCAP file to convert")
    return write_rrd(load_recording(mcap_path), rrd_path)


def open_native(rrd: str | os.PathLike) -> int:
    """The native viewer window on the file; returns when the window closes."""
    return subprocess.run([rerun_executable(), str(rrd)], check=False).returncode


def serve_web(rrd: str | os.PathLike, port: int) -> int:
    """Serve the web viewer (bundled in the wheel, works offline) on localhost:port until interrupted."""
    if not 1 <= port <= 65535:
        raise ViewerError(f"web viewer port {port} is out of range; expected 1..65535")
    cmd = [rerun_executable(), str(rrd), "--web-viewer", "--web-viewer-port", str(port), "--bind", "127.0.0.1"]
    return subprocess.run(cmd, check=False).returncode


def holding_time_ns(rrd: str | os.PathLike) -> int | None:
    """The last moment of the first hold: the arm is down at the place point with the box still on the
    pad (while carried, a box can hide under the arm). None if the pad never holds anything."""
    try:
        t_ns, held = read_scalars(rrd, f"/{scene.SUCTION_PATH}/holding", timeline=scene.TIME_TIMELINE)
    except RecordingError:
        return None
    rows = np.flatnonzero(held > 0.5)
    if rows.size == 0:
        return None
    gaps = np.flatnonzero(np.diff(rows) > 1)
    last = rows[gaps[0]] if gaps.size else rows[-1]
    return int(t_ns[last])


def screenshot(rrd: str | os.PathLike, out_png: str | os.PathLike, *, at_s: float | None = None,
               window_size: str = DEFAULT_WINDOW_SIZE) -> tuple[float | None, list[str]]:
    """Render the viewer headless (software Vulkan works) and save a PNG of what a user would see.

    The time cursor goes to `at_s` seconds of simulated time, else to the end of the first hold,
    else to the end. Returns (time shown in s or None for the end, problems the views reported).
    """
    from rerun.experimental import ViewerClient

    out = Path(out_png).resolve()
    if not out.parent.is_dir():
        raise ViewerError(f"cannot write {str(out_png)!r}: directory {str(out.parent)!r} does not exist")
    at_ns = round(at_s * 1e9) if at_s is not None else holding_time_ns(rrd)
    port = _free_port()
    env = dict(os.environ, RUST_LOG=os.environ.get("RUST_LOG", "error"))  # no notification toasts in the picture
    # The viewer's output goes to a file, not a pipe: a chatty viewer must never block on a full pipe.
    with tempfile.TemporaryFile() as log:
        started = time.monotonic()
        proc = subprocess.Popen([rerun_executable(), "--headless", "--port", str(port), "--window-size", window_size,
                                 "--hide-welcome-screen"], env=env, stdout=subprocess.DEVNULL, stderr=log,
                                start_new_session=True)
        try:
            client = _connect(ViewerClient, f"rerun+http://127.0.0.1:{port}/proxy", proc, log)
            try:
                client.open(str(Path(rrd).resolve()))
                timelines = _wait_loaded(client, proc)
                # Start-up notifications fade after a moment; do not photograph them.
                time.sleep(max(0.0, started + TOAST_FADE_S - time.monotonic()))
                end_ns = timelines.get(scene.TIME_TIMELINE)
                if end_ns is None:  # not a twin recording: show its end
                    at_ns = None
                    client.set_time(play_state="following")
                elif at_ns is not None and at_ns > end_ns:
                    raise ViewerError(f"time {at_ns * 1e-9:.3f} s is after the end of the recording "
                                      f"({end_ns * 1e-9:.3f} s of simulated time)")
                elif at_ns is None:
                    client.set_time(scene.TIME_TIMELINE, play_state="following")
                else:
                    client.set_time(scene.TIME_TIMELINE, duration=np.timedelta64(at_ns, "ns"), play_state="paused")
                client.save_screenshot(str(out))  # blocks until a frame with the new cursor has been painted
                problems = [f"{v.name}: {r}" for v in client.get_state().views for r in v.reports]
            except (RuntimeError, ValueError, OSError) as err:
                raise ViewerError(f"the headless Rerun viewer failed to take the screenshot: {err}") from err
        finally:
            _stop(proc)
    if not out.is_file():
        raise ViewerError(f"the headless viewer did not write {str(out)!r}")
    return (None if at_ns is None else at_ns * 1e-9), problems


def _stop(proc: subprocess.Popen) -> None:
    """End the viewer started here, and anything it started (its own process group)."""
    for sig, wait_s in ((signal.SIGTERM, 10.0), (signal.SIGKILL, None)):
        with contextlib.suppress(ProcessLookupError):  # already gone
            os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout=wait_s)
            return
        except subprocess.TimeoutExpired:
            continue


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _connect(client_cls, url: str, proc: subprocess.Popen, log):
    deadline = time.monotonic() + VIEWER_START_TIMEOUT_S
    while True:
        if proc.poll() is not None:
            log.seek(0)
            err = [ln for ln in log.read().decode(errors="replace").splitlines() if ln.strip()]
            raise ViewerError(f"the headless Rerun viewer exited with code {proc.returncode}"
                              f"{': ' + err[-1] if err else ''} (needs Vulkan, e.g. Debian's mesa-vulkan-drivers)")
        try:
            client = client_cls.connect(url)
            client.get_state()
            return client
        except Exception as err:  # the gRPC server is not up yet
            if time.monotonic() > deadline:
                raise ViewerError(f"the headless Rerun viewer did not answer on {url} within "
                                  f"{VIEWER_START_TIMEOUT_S:.0f} s: {err}") from err
            time.sleep(0.1)


def _wait_loaded(client, proc: subprocess.Popen) -> dict[str, int]:
    """Wait until the viewer holds the whole recording; returns each timeline's last time."""
    deadline = time.monotonic() + LOAD_TIMEOUT_S
    while True:
        state = client.get_state()
        if not state.loading and state.recordings and all(r.timelines for r in state.recordings):
            return {t.name: t.end for r in state.recordings for t in r.timelines if t.end is not None}
        if time.monotonic() > deadline or proc.poll() is not None:
            raise ViewerError(f"the Rerun viewer did not finish loading the recording in {LOAD_TIMEOUT_S:.0f} s")
        time.sleep(0.1)
