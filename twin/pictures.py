"""Encoded camera pictures: PNG written here (fixed settings: the same pixels give the same bytes),
JPEG through Pillow, and decoding through Pillow with the header checked first, so a damaged or
oversized picture is refused by its declared size before anything is decoded. Pillow is imported
when a picture is encoded as JPEG or decoded, not with the module.

A recording's pictures (a model CameraTrack) are decoded by track_rgb and checked by check_track:
a picture whose header is not the camera's configured format and size costs at most one
configured-size decode, never a bomb's, and is a RecordingError naming the file, the camera, the
step and what was expected."""

from __future__ import annotations

import io
import struct
import warnings
import zlib

import numpy as np

from twin.model.errors import RecordingError
from twin.model.images import CameraTrack

# fixed: identical pixels give identical bytes (level 1: 0.36 ms a picture, level 6: 0.9-1.2)
PNG_COMPRESS_LEVEL = 1


def encode(rgb: np.ndarray, format: str = "png") -> bytes:
    """(h, w, 3) uint8 pixels as PNG (png_bytes) or JPEG (Pillow, quality 90)."""
    if format == "png":
        return png_bytes(rgb)
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, dtype=np.uint8), "RGB").save(
        out, format="JPEG", quality=90
    )
    return out.getvalue()


def png_bytes(rgb: np.ndarray) -> bytes:
    """A PNG of (h, w, 3) uint8 pixels: 8-bit RGB, every row unfiltered, zlib level
    PNG_COMPRESS_LEVEL, no other chunks, so the same pixels always give the same bytes. Written here
    rather than by Pillow, whose filter search took 1.5-3 ms a 320x240 picture; this takes 0.36 ms
    (the renderer's flat colours compress well without filters: 3.5 KB)."""
    h, w, _ = rgb.shape
    rows = np.empty((h, 1 + 3 * w), dtype=np.uint8)
    rows[:, 0] = 0  # filter type None
    # a view into rows: the renderer's RGBA slice is copied once, strided
    pixels = rows[:, 1:].reshape(h, w, 3)
    pixels[...] = rgb
    # 8 bits, truecolour, deflate, no filter choice, no interlace
    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return b"".join(
        (
            b"\x89PNG\r\n\x1a\n",
            _png_chunk(b"IHDR", header),
            _png_chunk(b"IDAT", zlib.compress(rows.tobytes(), PNG_COMPRESS_LEVEL)),
            _png_chunk(b"IEND", b""),
        )
    )


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


_PIL_FORMATS = {"png": "PNG", "jpeg": "JPEG"}
# the signature, then the IHDR chunk's length and type
_PNG_HEAD = b"\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR"


def decode_rgb(
    data: bytes, format: str | None = None, size_px: tuple[int, int] | None = None
) -> np.ndarray:
    """Encoded PNG or JPEG bytes as (h, w, 3) uint8 pixels. With format and size_px (width, height)
    the header is checked first and nothing else is decoded: ValueError saying what the bytes are
    instead, also for pixel data Pillow cannot decode."""
    with _open(data, format, size_px) as image:
        if size_px is not None and image.size != tuple(size_px):
            raise ValueError(f"is {image.size[0]}x{image.size[1]} px")
        try:
            image.load()
            rgb = image.convert("RGB")
        except Exception as err:  # noqa: BLE001 - Pillow raises OSError, SyntaxError, ValueError, ... on bad data
            raise ValueError(f"does not decode ({_one_line(err)})") from None
    pixels = np.asarray(rgb, dtype=np.uint8)
    if size_px is not None and pixels.shape != (size_px[1], size_px[0], 3):
        raise ValueError(f"decodes to shape {pixels.shape}")
    return pixels


def checked_header(data: bytes, format: str, size_px: tuple[int, int]) -> None:
    """ValueError unless the picture's header declares format and size_px (nothing is decoded)."""
    with _open(data, format, size_px) as image:
        if image.size != tuple(size_px):
            raise ValueError(f"is {image.size[0]}x{image.size[1]} px")


def _open(data: bytes, format: str | None, size_px: tuple[int, int] | None = None):
    """Pillow's Image.open of the bytes (it reads the header only), for format when given. A PNG's
    IHDR is read first: one of another size than size_px, or too large for Pillow, is refused with
    its size before Pillow sees it; Pillow's own limit (DecompressionBombError, and the warning it
    prints below that) never shows."""
    from PIL import Image, UnidentifiedImageError

    if not isinstance(data, (bytes, bytearray, memoryview)) or not len(data):
        raise ValueError("is empty")
    if format is not None and format not in _PIL_FORMATS:
        raise ValueError(f"is in format {format!r}; expected one of {', '.join(_PIL_FORMATS)}")
    if bytes(data[:16]) == _PNG_HEAD and len(data) >= 24 and format in (None, "png"):
        w, h = struct.unpack(">II", bytes(data[16:24]))
        limit = Image.MAX_IMAGE_PIXELS
        if (size_px is not None and (w, h) != tuple(size_px)) or (limit and w * h > limit):
            raise ValueError(f"is {w}x{h} px")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            return Image.open(
                io.BytesIO(bytes(data)), formats=None if format is None else [_PIL_FORMATS[format]]
            )
        except Image.DecompressionBombError:
            raise ValueError(f"declares more than {Image.MAX_IMAGE_PIXELS} pixels") from None
        except UnidentifiedImageError:
            what = f"a {_PIL_FORMATS[format]} picture" if format else "a picture"
            raise ValueError(
                f"is not {what} ({len(data)} bytes starting {bytes(data[:8])!r})"
            ) from None
        except Exception as err:  # noqa: BLE001 - a damaged header: SyntaxError, OSError, struct.error, ...
            raise ValueError(f"has a damaged header ({_one_line(err)})") from None


def _one_line(err: BaseException) -> str:
    text = " ".join(f"{type(err).__name__}: {err}".split())
    return text if len(text) <= 120 else text[:117] + "..."


def track_rgb(track: CameraTrack, i: int) -> np.ndarray:
    """Picture i of a camera track decoded: (height, width, 3) uint8. Its header is checked first
    (check_track): a picture that is not the camera's format and size is a RecordingError, and is
    never decoded."""
    try:
        return decode_rgb(track.data[i], track.format, (track.width_px, track.height_px))
    except ValueError as err:
        raise _bad_picture(track, i, str(err)) from None


def check_track(track: CameraTrack, i: int | None = None) -> None:
    """Picture i's header (every picture's with i None) against the camera: RecordingError
    unless it is a picture of the camera's format and configured size. Reads headers only:
    microseconds each."""
    for k in range(len(track.data)) if i is None else (i,):
        try:
            checked_header(track.data[k], track.format, (track.width_px, track.height_px))
        except ValueError as err:
            raise _bad_picture(track, k, str(err)) from None


def _bad_picture(track: CameraTrack, i: int, why: str) -> RecordingError:
    where = f"recording {track.source!r}: " if track.source else ""
    step = f"step {int(track.step[i])}" if i < len(track.step) else f"picture {i}"
    return RecordingError(
        f"{where}camera {track.name!r} picture at {step} {why}; expected a "
        f"{track.format.upper()} picture of {track.width_px}x{track.height_px} px (the camera's "
        "configured format and size)"
    )
