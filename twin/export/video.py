"""MP4 video with PyAV (the optional `av` package): the encoder LeRobot uses by default.

AV1 through SVT-AV1 (`libsvtav1`, in PyAV's wheels; decoded there by dav1d), yuv420p, a keyframe
every 2 frames and crf 30 as LeRobot's own defaults, so random access to a frame decodes at most
one other. Frame i has pts i in a 1/fps time base, so it is shown at exactly i / fps. The same
frames give the same bytes (measured: two encodings of one dataset are byte-identical).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from twin.model.errors import ConfigError

CODEC = "libsvtav1"
PIX_FMT = "yuv420p"
OPTIONS = {"g": "2", "crf": "30", "preset": "12"}  # LeRobot's defaults for libsvtav1


def require_av():
    """The av module, or a one-line ConfigError naming the package to install."""
    try:
        import av
    except ImportError:
        raise ConfigError(
            "video export needs the av package (PyAV): pip install 'twin[export]' or pip install av"
        ) from None
    return av


def check_size(name: str, width_px: int, height_px: int) -> None:
    """yuv420p halves the colour resolution: both sides must be even."""
    if width_px % 2 or height_px % 2 or width_px <= 0 or height_px <= 0:
        raise ConfigError(
            f"camera {name!r} is {width_px}x{height_px} px; video export needs an even "
            f"width and height"
        )


def encode_mp4(
    path: str | os.PathLike, frames: Iterable[np.ndarray], fps: int, width_px: int, height_px: int
) -> int:
    """Encode (H, W, 3) uint8 RGB frames into an MP4 file at fps; returns the number of frames."""
    av = require_av()
    # SVT-AV1 prints its configuration to stderr unless told not to
    os.environ.setdefault("SVT_LOG", "1")
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        return _encode(
            av=av, path=path, frames=frames, fps=fps, width_px=width_px, height_px=height_px
        )
    finally:
        # SVT-AV1, run as root, switches the calling thread to SCHED_FIFO 99: every process started
        # later would inherit it (a spinning one starved the machine)
        os.sched_setscheduler(0, policy, param)


def _encode(av, path, frames: Iterable[np.ndarray], fps: int, width_px: int, height_px: int) -> int:
    count = 0
    with av.open(str(path), "w", format="mp4") as out:
        stream = out.add_stream(CODEC, rate=fps, options=dict(OPTIONS))
        stream.width, stream.height, stream.pix_fmt = width_px, height_px, PIX_FMT
        try:
            for rgb in frames:
                frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")
                frame.pts = count
                for packet in stream.encode(frame):
                    out.mux(packet)
                count += 1
        except BaseException:  # a bad picture, Ctrl-C: end the stream first, else SVT-AV1 prints
            # "Svt[error]: deinit called without sending EOS!" under the error line
            _end_quietly(stream)
            raise
        for packet in stream.encode():
            out.mux(packet)
    return count


def _end_quietly(stream) -> None:
    """Send the encoder its end of stream, dropping what it still holds (the file is abandoned)."""
    try:
        for _ in stream.encode():
            pass
    except Exception:  # noqa: BLE001, S110 - the error being raised is the one to report
        pass


def probe(path: str | os.PathLike) -> dict:
    """LeRobot's `video.*` info of an encoded file (read back from the file itself)."""
    av = require_av()
    with av.open(str(Path(path))) as container:
        stream = container.streams.video[0]
        return {
            "video.height": stream.height,
            "video.width": stream.width,
            "video.codec": stream.codec_context.codec.canonical_name,
            "video.pix_fmt": stream.pix_fmt,
            "video.fps": int(stream.base_rate),
            "video.channels": 3,
            "has_audio": False,
            "video.g": int(OPTIONS["g"]),
            "video.crf": int(OPTIONS["crf"]),
            "video.preset": int(OPTIONS["preset"]),
            "is_depth_map": False,
        }
