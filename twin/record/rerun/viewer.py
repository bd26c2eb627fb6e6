"""Showing a recording in Rerun's viewer: the native window, the web viewer, or a headless
screenshot.

An .mcap recording is drawn into a temporary .rrd first (twin.load + write_rrd); an .rrd is checked
(magic bytes and `rerun rrd verify`) before any viewer starts. Every viewer is a `rerun` child that
listens on 127.0.0.1 only, on free ports unless told otherwise, and dies with us
(twin.record.rerun.process).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
import urllib.parse
from collections.abc import Callable
from pathlib import Path
from typing import IO

import numpy as np

from twin.model.errors import RecordingError
from twin.model.recording import Recording
from twin.record.outputs import check_target, write_atomic
from twin.record.rerun import scene
from twin.record.rerun.process import (
    LOOPBACK,
    ViewerError,
    last_log_line,
    loopback_ports,
    spawn,
    stop,
    wait_listening,
)
from twin.record.rerun.rrd_file import file_kind, read_scalars, rerun_executable, verify_rrd
from twin.record.rerun.rrd_http import serve_rrd, stop_rrd
from twin.record.rerun.vulkan import INSTALL_HINT, missing_driver
from twin.record.rerun.writer import write_rrd

__all__ = [
    "ViewerError",
    "as_rrd",
    "holding_time_ns",
    "mcap_to_rrd",
    "open_native",
    "require_display",
    "screenshot",
    "serve_web",
    "web_url",
]

DEFAULT_WINDOW_SIZE = "1280x800"
VIEWER_START_TIMEOUT_S = 30.0
LOAD_TIMEOUT_S = 60.0
TOAST_FADE_S = 2.0
SETTLE_S = 0.3  # between the photographs of a screenshot that must agree
SETTLE_TRIES = 5
DISPLAY_VARIABLES = ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")
NO_DISPLAY_HINT = "use --web, --rrd or --screenshot"
LOG_NAME = "rerun.log"  # the viewer's own output, in the caller's temporary folder


def load_recording(path: str | os.PathLike) -> Recording:
    """twin.load for an MCAP file (the MCAP reader owns the format and its errors)."""
    from twin.record.mcap.reader import load

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
        raise RecordingError(
            f"{str(mcap_path)!r} is already a Rerun .rrd file; expected an MCAP file to convert"
        )
    return write_rrd(load_recording(mcap_path), rrd_path)


def require_display() -> None:
    """ViewerError (exit 2) when a native window cannot open: on Linux and BSD a window needs an X11
    or Wayland display, named by $DISPLAY or $WAYLAND_DISPLAY."""
    if sys.platform in ("darwin", "win32") or any(os.environ.get(v) for v in DISPLAY_VARIABLES):
        return
    raise ViewerError(
        f"no display for the native viewer ($DISPLAY and $WAYLAND_DISPLAY are unset); "
        f"{NO_DISPLAY_HINT}"
    )


def open_native(rrd: str | os.PathLike, work_dir: str | os.PathLike, *, grpc_port: int = 0) -> int:
    """The native viewer window on the file; returns 0 when the window is closed.

    Its server (which SDKs and other viewers may connect to) listens on 127.0.0.1 only, on
    grpc_port or a free port. Its log and its temporary files go to work_dir (a folder the caller
    removes). A viewer that fails (e.g. cannot reach the display) is one ViewerError line with its
    last log line."""
    require_display()
    (port,) = loopback_ports(("--grpc-port", grpc_port))
    cmd = [rerun_executable(), str(rrd), "--bind", LOOPBACK, "--port", str(port)]
    code, why = _run_viewer(cmd, work_dir)
    if code != 0:
        raise ViewerError(
            f"the native Rerun viewer exited with code {code} ({why or 'no output'}); "
            f"without a working display {NO_DISPLAY_HINT}"
        )
    return 0


def _run_viewer(
    cmd: list[str],
    work_dir: str | os.PathLike,
    on_started: Callable[[subprocess.Popen, IO[bytes]], None] | None = None,
) -> tuple[int, str]:
    """Run the viewer `cmd` until it ends (on_started called once it runs), its log in work_dir;
    stopped whatever happens. Returns its exit code and, if that is not 0, its last log line."""
    with open(Path(work_dir) / LOG_NAME, "w+b") as log:
        proc = spawn(cmd, log, tmp_dir=work_dir)
        try:
            if on_started is not None:
                on_started(proc, log)
            code = proc.wait()
        finally:
            stop(proc)
        return code, (last_log_line(log) if code != 0 else "")


def web_url(web_port: int, rrd_url: str) -> str:
    """The address that opens the recording at rrd_url in the web viewer (without ?url= it shows a
    welcome page)."""
    return f"http://{LOOPBACK}:{web_port}/?url={urllib.parse.quote(rrd_url, safe='')}"


def serve_web(
    rrd: str | os.PathLike,
    work_dir: str | os.PathLike,
    *,
    web_port: int = 0,
    grpc_port: int = 0,
    on_ready: Callable[[str], None] = print,
) -> int:
    """Serve the web viewer (bundled in the wheel, works offline) on 127.0.0.1 until interrupted; no
    browser is opened (`--serve-web`: `--web-viewer` would start the default one, the user opens the
    URL).

    The page loads the file over plain HTTP from a thread of this process (twin.record.rerun.
    rrd_http) on grpc_port, not from rerun's gRPC server: that one keeps a core busy for as long as
    it serves a file. Given an http:// source, `rerun --serve-web` serves the viewer's files only.
    Both ports are the given ones or free ones, so several viewers run side by side. Once both
    listen, on_ready gets the URL that opens the recording. Its log and its temporary files go to
    work_dir (a folder the caller removes). Returns 0 when the server ends by itself."""
    web_port, grpc_port = loopback_ports(("--port", web_port), ("--grpc-port", grpc_port))
    server = serve_rrd(rrd, grpc_port, web_port)
    try:
        cmd = [
            rerun_executable(),
            server.url,
            "--serve-web",
            "--web-viewer-port",
            str(web_port),
            "--bind",
            LOOPBACK,
        ]

        def started(proc: subprocess.Popen, log: IO[bytes]) -> None:
            wait_listening(proc, (web_port,), log, "the Rerun web viewer", VIEWER_START_TIMEOUT_S)
            on_ready(web_url(web_port, server.url))

        code, why = _run_viewer(cmd, work_dir, started)
        if code != 0:
            raise ViewerError(f"the Rerun web viewer exited with code {code}: {why or 'no output'}")
    finally:
        stop_rrd(server)
    return 0


def holding_time_ns(rrd: str | os.PathLike) -> int | None:
    """The last moment of the first hold: the arm is down at the place point with the box still on
    the pad (while carried, a box can hide under the arm). None if the pad never holds anything."""
    try:
        t_ns, held = read_scalars(
            rrd, f"/{scene.SUCTION_PATH}/holding", timeline=scene.TIME_TIMELINE
        )
    except RecordingError:
        return None
    rows = np.flatnonzero(held > 0.5)
    if rows.size == 0:
        return None
    gaps = np.flatnonzero(np.diff(rows) > 1)
    last = rows[gaps[0]] if gaps.size else rows[-1]
    return int(t_ns[last])


def screenshot(
    rrd: str | os.PathLike,
    out_png: str | os.PathLike,
    work_dir: str | os.PathLike,
    *,
    at_s: float | None = None,
    window_size: str = DEFAULT_WINDOW_SIZE,
    grpc_port: int = 0,
) -> tuple[float | None, list[str]]:
    """Render the viewer headless (software Vulkan works) and save a PNG of what a user would see.

    The time cursor goes to `at_s` seconds of simulated time, else to the end of the first hold,
    else to the end. The viewer's log and temporary files go to work_dir (a folder the caller
    removes). Returns (time shown in s or None for the end, problems the views reported).
    """
    from rerun.experimental import ViewerClient

    check_target(out_png, "screenshot", "a .png file path", error=ViewerError)
    if missing := missing_driver():
        raise ViewerError(missing)
    out = (Path(work_dir) / "shot.png").resolve()  # put in place whole once settled
    at_ns = round(at_s * 1e9) if at_s is not None else holding_time_ns(rrd)
    (port,) = loopback_ports(("--grpc-port", grpc_port))
    # no notification toasts in the picture
    env = dict(os.environ, RUST_LOG=os.environ.get("RUST_LOG", "error"))
    with open(Path(work_dir) / LOG_NAME, "w+b") as log:
        started = time.monotonic()
        proc = spawn(
            [
                rerun_executable(),
                "--headless",
                "--bind",
                LOOPBACK,
                "--port",
                str(port),
                "--window-size",
                window_size,
                "--hide-welcome-screen",
            ],
            log,
            env=env,
            tmp_dir=work_dir,
        )
        try:
            client = _connect(ViewerClient, f"rerun+http://{LOOPBACK}:{port}/proxy", proc, log)
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
                    raise ViewerError(
                        f"time {at_ns * 1e-9:.3f} s is after the end of the recording "
                        f"({end_ns * 1e-9:.3f} s of simulated time)"
                    )
                elif at_ns is None:
                    client.set_time(scene.TIME_TIMELINE, play_state="following")
                else:
                    client.set_time(
                        scene.TIME_TIMELINE,
                        duration=np.timedelta64(at_ns, "ns"),
                        play_state="paused",
                    )
                # blocks until a frame with the new cursor has been painted
                client.save_screenshot(str(out))
                _settled_screenshot(client, out, Path(work_dir) / "again.png")
                problems = [f"{v.name}: {r}" for v in client.get_state().views for r in v.reports]
            except (RuntimeError, ValueError, OSError) as err:
                raise _failed(err, log) from err
        finally:
            stop(proc)
    if not out.is_file():
        raise ViewerError(f"the headless viewer did not write {str(out_png)!r}")
    write_atomic(out_png, out.read_bytes())
    return (None if at_ns is None else at_ns * 1e-9), problems


def _failed(err: Exception, log) -> ViewerError:
    """The screenshot's failure with the viewer's last log line and what to install."""
    why = last_log_line(log)
    return ViewerError(
        f"the headless Rerun viewer failed to take the screenshot: {err}"
        f"{' (its log: ' + why + ')' if why else ''}; if it has no renderer: {INSTALL_HINT}"
    )


def _settled_screenshot(client, out: Path, again: Path) -> None:
    """Photograph again until two pictures in a row agree (a few tries at most): a camera picture
    is decoded after the frame that first shows its view is painted, which on a busy machine can be
    the frame photographed."""
    for _ in range(SETTLE_TRIES):
        time.sleep(SETTLE_S)
        client.save_screenshot(str(again))
        if again.read_bytes() == out.read_bytes():
            return
        again.replace(out)


def _connect(client_cls, url: str, proc: subprocess.Popen, log):
    deadline = time.monotonic() + VIEWER_START_TIMEOUT_S
    while True:
        if proc.poll() is not None:
            err = last_log_line(log)
            raise ViewerError(
                f"the headless Rerun viewer exited with code {proc.returncode}"
                f"{': ' + err if err else ''}; if it has no renderer: {INSTALL_HINT}"
            )
        try:
            client = client_cls.connect(url)
            client.get_state()
            return client
        except Exception as err:  # the gRPC server is not up yet
            if time.monotonic() > deadline:
                raise ViewerError(
                    f"the headless Rerun viewer did not answer on {url} within "
                    f"{VIEWER_START_TIMEOUT_S:.0f} s: {err}"
                ) from err
            time.sleep(0.1)


def _wait_loaded(client, proc: subprocess.Popen) -> dict[str, int]:
    """Wait until the viewer holds the whole recording; returns each timeline's last time."""
    deadline = time.monotonic() + LOAD_TIMEOUT_S
    while True:
        state = client.get_state()
        if not state.loading and state.recordings and all(r.timelines for r in state.recordings):
            return {
                t.name: t.end for r in state.recordings for t in r.timelines if t.end is not None
            }
        if time.monotonic() > deadline or proc.poll() is not None:
            raise ViewerError(
                f"the Rerun viewer did not finish loading the recording in {LOAD_TIMEOUT_S:.0f} s"
            )
        time.sleep(0.1)
