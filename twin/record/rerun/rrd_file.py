"""Checking and reading back .rrd files: magic bytes, `rerun rrd verify`, and scalar series by
entity."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader

from twin.model.errors import RecordingError

RRD_MAGIC = b"RRF2"
MCAP_MAGIC = b"\x89MCAP"
VERIFY_TIMEOUT_S = 120.0


def rerun_executable() -> str:
    """The viewer binary that ships with rerun-sdk (not the Python wrapper on PATH, which would
    leave its child running when terminated), else `rerun` from PATH."""
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        binary = Path(spec.origin).parent / "rerun"
        if binary.is_file() and os.access(binary, os.X_OK):
            return str(binary)
    exe = shutil.which("rerun")
    if exe is None:
        raise RecordingError(
            "the 'rerun' command is not on PATH; expected it from the rerun-sdk package"
        )
    return exe


def file_kind(path: str | os.PathLike) -> str:
    """'rrd' or 'mcap' by the file's first bytes; RecordingError for a missing, empty or other
    file."""
    p = Path(path)
    if not p.exists():
        raise RecordingError(f"recording {str(p)!r} does not exist")
    if not p.is_file():
        raise RecordingError(f"recording {str(p)!r} is not a file; expected an .mcap or .rrd file")
    try:
        with p.open("rb") as f:
            head = f.read(8)
    except OSError as err:
        raise RecordingError(f"cannot read recording {str(p)!r}: {err}") from err
    if not head:
        raise RecordingError(f"recording {str(p)!r} is empty; expected an MCAP or Rerun .rrd file")
    if head.startswith(RRD_MAGIC):
        return "rrd"
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    raise RecordingError(
        f"{str(p)!r} is neither an MCAP nor a Rerun .rrd file (starts with {head[:4]!r}; "
        f"expected {MCAP_MAGIC!r} or {RRD_MAGIC!r})"
    )


def verify_rrd(path: str | os.PathLike) -> None:
    """Rerun's own check (`rerun rrd verify`) plus the magic bytes; RecordingError naming the
    fault."""
    if file_kind(path) != "rrd":
        raise RecordingError(f"{str(path)!r} is an MCAP file, not a Rerun .rrd file")
    try:
        done = subprocess.run(
            [rerun_executable(), "rrd", "verify", str(path)],
            capture_output=True,
            text=True,
            timeout=VERIFY_TIMEOUT_S,
            check=False,
        )
    except subprocess.TimeoutExpired as err:
        raise RecordingError(
            f"'rerun rrd verify {path}' did not finish in {VERIFY_TIMEOUT_S:.0f} s"
        ) from err
    if done.returncode != 0:
        lines = [ln.strip() for ln in (done.stderr + done.stdout).splitlines() if ln.strip()]
        why = next(
            (ln for ln in lines if not ln.startswith(("Error: Verification failed", "0 files"))), ""
        )
        raise RecordingError(
            f"{str(path)!r} is not a valid .rrd file (rerun rrd verify: {why or 'failed'})"
        )


def read_scalars(
    path: str | os.PathLike, entity: str, *, timeline: str = "step"
) -> tuple[np.ndarray, np.ndarray]:
    """(times, values) of the Scalars logged on `entity` (e.g. '/plots/z_m/z'), sorted by time."""
    times, values = [], []
    try:
        chunks = list(RrdReader(str(path)).stream())
    except (OSError, ValueError, RuntimeError) as err:
        raise RecordingError(f"cannot read {str(path)!r} as a Rerun recording: {err}") from err
    for chunk in chunks:
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        column = next((n for n in names if n.endswith("Scalars:scalars")), None)
        if column is None or timeline not in names:
            continue
        times.append(batch.column(timeline).to_numpy(zero_copy_only=False))
        values.append(_first_of_each_row(batch.column(column)))
    if not times:
        raise RecordingError(
            f"{str(path)!r} has no scalars on {entity!r} along timeline {timeline!r}"
        )
    t = np.concatenate(times)
    v = np.concatenate(values)
    order = np.argsort(t, kind="stable")
    return t[order], v[order]


def _first_of_each_row(column: pa.Array) -> np.ndarray:
    """The single value in each row of a list column (NaN for an empty or null row)."""
    offsets = column.offsets.to_numpy()
    flat = column.flatten().to_numpy(zero_copy_only=False).astype(np.float64)
    out = np.full(len(column), np.nan)
    has = offsets[1:] > offsets[:-1]
    out[has] = flat[offsets[:-1][has] - offsets[0]]
    return out
