"""A LeRobot v3.0 dataset, written with pyarrow and PyAV (no LeRobot, no torch).

The layout and fields follow LeRobot's own code (src/lerobot/datasets: utils.py, feature_utils.py,
dataset_metadata.py, dataset_writer.py, compute_stats.py, video_utils.py):

  meta/info.json                  codebase_version "v3.0", fps, features, totals, path templates
  meta/stats.json                 per feature: min, max, mean, std, count, q01, q10, q50, q90, q99
  meta/tasks.parquet              task_index, indexed by the task text (pandas index "task")
  meta/episodes/chunk-000/file-000.parquet
                                  one row per episode: where its frames and video are, its stats
  meta/twin_provenance.json       (ours) each source file, its sha256, whether its replay was exact
  data/chunk-000/file-000.parquet one row per frame, one row group per episode
  videos/observation.images.<camera>/chunk-000/file-000.mp4
                                  every episode, one after the other

Frames: `observation.state` = joint positions (rad, z in m) + suction.on + suction.holding,
`action` = joint targets + suction.command (float32); `timestamp` = frame_index / fps as float32,
as LeRobot computes and stores it. Everything goes to one file per kind (chunk 0, file 0): LeRobot
reads any file size; it starts new files only while recording.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twin.export.episodes import NS_PER_S, Episode, nearest
from twin.export.stats import feature_stats, image_sample, image_stride, sampled_image_stats
from twin.model.errors import ConfigError, RecordingError
from twin.pictures import track_rgb
from twin.record.outputs import fsync_file, publish
from twin.record.tables import frame_column_names, suction_command

CODEBASE_VERSION = "v3.0"
CHUNK_FILE = "chunk-{chunk_index:03d}/file-{file_index:03d}"
DATA_PATH = "data/" + CHUNK_FILE + ".parquet"
VIDEO_PATH = "videos/{video_key}/" + CHUNK_FILE + ".mp4"
EPISODES_PATH = "meta/episodes/" + CHUNK_FILE + ".parquet"
CHUNKS_SIZE, DATA_FILES_MB, VIDEO_FILES_MB = 1000, 100, 200  # LeRobot's defaults
INDEX_FEATURES = ("timestamp", "frame_index", "episode_index", "index", "task_index")
PROVENANCE_PATH = "meta/twin_provenance.json"


@dataclass
class Written:
    """What an export wrote: the dataset folder, episodes and frames, the camera keys."""

    path: Path
    episodes: int
    frames: int
    video_keys: list[str] = field(default_factory=list)


def state_names(rec) -> tuple[list[str], list[str]]:
    """The names of observation.state's and action's components (the frame table's column names)."""
    columns = frame_column_names([o.name for o in rec.config.objects])
    positions = [c for c in columns if c.startswith("joint.") and ".position_" in c]
    targets = [c for c in columns if c.startswith("joint.") and ".target_" in c]
    return positions + ["suction.on", "suction.holding"], targets + ["suction.command"]


def episode_arrays(ep: Episode, command: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """observation.state and action of each dataset frame of an episode (float32); command is its
    recording's suction.command column (record.tables.suction_command)."""
    f, rows = ep.rec.frames, ep.rows
    state = np.column_stack([f.joint_q[rows], f.suction_on[rows], f.held_body[rows] >= 0])
    action = np.column_stack([f.joint_target[rows], command[rows]])
    return state.astype(np.float32), action.astype(np.float32)


def camera_names(episodes: list[Episode]) -> list[str]:
    """The cameras every episode's recording has (the same set in each, each of one size, else
    ConfigError)."""
    sets = {tuple(sorted(getattr(ep.rec, "cameras", None) or {})) for ep in episodes}
    if len(sets) > 1:
        raise ConfigError(
            "the recordings have different cameras: "
            + " vs ".join("(" + ", ".join(s) + ")" for s in sorted(sets))
            + "; expected the same cameras in every recording"
        )
    names = list(sets.pop()) if sets else []
    for name in names:
        sizes = {(ep.rec.cameras[name].width_px, ep.rec.cameras[name].height_px) for ep in episodes}
        if len(sizes) > 1:
            raise ConfigError(
                f"the recordings' camera {name!r} has different sizes: "
                + " vs ".join(f"{w}x{h}" for w, h in sorted(sizes))
                + " px; expected one size in every recording"
            )
    return names


def check_finite(episodes: list[Episode]) -> None:
    """RecordingError (exit 2) for a NaN or infinite value among the exported frames' state and
    action: LeRobot normalizes features by their stats.json mean and std, which one NaN makes NaN
    (and strict JSON has no NaN), so such a recording is refused, naming the value; the csv and
    parquet tables keep it."""
    for ep in episodes:
        f, rows = ep.rec.frames, ep.rows
        state_of, action_of = state_names(ep.rec)
        for values, names in ((f.joint_q[rows], state_of), (f.joint_target[rows], action_of)):
            # 1e300 is finite, but not as the float32 the dataset holds
            with np.errstate(over="ignore"):
                bad = np.argwhere(~np.isfinite(values.astype(np.float32)))
            if bad.size:
                k, j = (int(v) for v in bad[0])
                raise RecordingError(
                    f"recording {ep.rec.path!r}: {names[j]} is {values[k, j]} at step "
                    f"{int(f.step[rows[k]])}; expected finite float32 values in a dataset (its "
                    "stats.json and LeRobot's normalization need them; --format csv or parquet "
                    "keeps them)"
                )


def camera_picks(ep: Episode, name: str, fps: int) -> np.ndarray:
    """Which of the camera's pictures each dataset frame shows: the one taken nearest its time
    (episodes.nearest)."""
    track = ep.rec.cameras[name]
    if len(track.t_ns) == 0:
        raise ConfigError(f"recording {ep.rec.path!r}: camera {name!r} has no images")
    elapsed = (np.asarray(track.t_ns, dtype=np.int64) - ep.t0_ns) * fps
    return nearest(elapsed, np.arange(len(ep), dtype=np.int64) * NS_PER_S)


def write_dataset(
    episodes: list[Episode],
    tasks: list[str],
    out: Path,
    fps: int,
    provenance: dict,
    *,
    overwrite: bool = False,
) -> Written:
    """Write the episodes (with one task text each) as a LeRobot v3.0 dataset in folder `out`.

    Written in a temporary folder beside `out` and renamed into place when complete, so `out` is
    either what it was or the whole new dataset. Such folders left by killed exports (their process
    is gone) are removed first."""
    if not episodes:
        raise ConfigError("no episode to export")
    cameras = camera_names(episodes)
    check_finite(episodes)
    if cameras:
        from twin.export.video import require_av

        require_av()  # before any work: a missing PyAV is one line, and nothing is written
    remove_stale(out)
    tmp = out.parent / f".{out.name}.partial-{os.getpid()}"
    if tmp.exists():  # left by a killed export of this process id: ours by its name
        shutil.rmtree(tmp)
    tmp.mkdir()
    try:
        _write_all(
            root=tmp,
            episodes=episodes,
            tasks=tasks,
            cameras=cameras,
            fps=fps,
            provenance=provenance,
        )
        _publish(tmp, out, overwrite)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return Written(
        out,
        len(episodes),
        sum(len(ep) for ep in episodes),
        [f"observation.images.{c}" for c in cameras],
    )


def remove_stale(out: Path) -> list[Path]:
    """Remove what killed exports of `out` left beside it: `.NAME.partial-PID` folders, and
    `.NAME.old-PID-*` folders (an overwritten dataset) once `out` holds a complete dataset again.
    Only those whose process PID is gone, or is a later process that reused the id (it started after
    the folder last changed): a running export's folders are kept. Returns the folders removed."""
    removed = []
    try:
        entries = list(out.parent.iterdir())
    except OSError:
        return removed
    partial, old = f".{out.name}.partial-", f".{out.name}.old-"
    for entry in entries:
        name = entry.name
        if name.startswith(partial):
            pid_text = name[len(partial) :]
        elif name.startswith(old) and (out / "meta" / "info.json").is_file():
            pid_text = name[len(old) :].partition("-")[0]
        else:
            continue
        if not pid_text.isdigit() or entry.is_symlink() or not entry.is_dir():
            continue
        pid = int(pid_text)
        if pid != os.getpid() and _writing(pid, entry):
            continue
        shutil.rmtree(entry, ignore_errors=True)
        removed.append(entry)
    return removed


def _writing(pid: int, folder: Path) -> bool:
    """Whether process pid may still be writing folder: it is alive and started before the folder
    last changed (a process started later only reuses a dead export's id). Alive when unsure."""
    if not 0 < pid <= 2**31:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # PermissionError: another user's live process
        return True
    started = _start_time(pid)
    try:
        changed = folder.stat().st_mtime
    except OSError:
        return True
    return started is None or started <= changed + 2.0  # /proc's boot time has whole seconds


def _start_time(pid: int) -> float | None:
    """When process pid started (seconds since the epoch), from /proc; None where there is no
    /proc."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        with open("/proc/stat", "rb") as f:
            boot = next(int(line.split()[1]) for line in f if line.startswith(b"btime "))
        # field 22, starttime, in clock ticks
        return boot + int(fields[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration):
        return None


def _write_all(
    root: Path,
    episodes: list[Episode],
    tasks: list[str],
    cameras: list[str],
    fps: int,
    provenance: dict,
) -> None:
    task_index = {t: i for i, t in enumerate(dict.fromkeys(tasks))}
    ep_rows, ep_stats, totals = _write_data(root, episodes, tasks, task_index, fps)
    video_info, image_stats_by_key = _write_videos(root, episodes, cameras, fps, ep_rows)
    stats = {k: feature_stats(v) for k, v in totals.items()}
    for key, per_episode in image_stats_by_key.items():
        for episode_stats, per in zip(ep_stats, per_episode, strict=True):
            episode_stats[key] = per
        stats[key] = _merged_image_stats(per_episode)
    _write_episodes(root, ep_rows, ep_stats)
    _write_tasks(root, task_index)
    features = _features(*state_names(episodes[0].rec), video_info)
    info = {
        "codebase_version": CODEBASE_VERSION,
        "fps": fps,
        "features": features,
        "total_episodes": len(episodes),
        "total_frames": sum(len(ep) for ep in episodes),
        "total_tasks": len(task_index),
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": DATA_FILES_MB,
        "video_files_size_in_mb": VIDEO_FILES_MB,
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH if cameras else None,
        "robot_type": "+".join(dict.fromkeys(ep.rec.config.profile.name for ep in episodes)),
        "splits": {"train": f"0:{len(episodes)}"},
    }
    _write_json(root / "meta/info.json", info)
    _write_json(root / "meta/stats.json", {k: stats[k] for k in features})
    _write_json(root / PROVENANCE_PATH, provenance)


def _write_data(
    root: Path, episodes: list[Episode], tasks: list[str], task_index: dict[str, int], fps: int
):
    """data/chunk-000/file-000.parquet, one row group per episode. Returns each episode's row of the
    episodes table (so far), each episode's stats, and every column over the whole dataset."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = root / DATA_PATH.format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True)
    # once per recording, not per cycle
    commands = {id(ep.rec): suction_command(ep.rec) for ep in episodes}
    ep_rows, ep_stats, parts, writer, start = [], [], [], None, 0
    for e, (ep, task) in enumerate(zip(episodes, tasks, strict=True)):
        n = len(ep)
        state, action = episode_arrays(ep, commands[id(ep.rec)])
        frame_index = np.arange(n, dtype=np.int64)
        cols = {
            "observation.state": state,
            "action": action,
            "timestamp": (frame_index / fps).astype(np.float32),
            "frame_index": frame_index,
            "episode_index": np.full(n, e, dtype=np.int64),
            "index": start + frame_index,
            "task_index": np.full(n, task_index[task], dtype=np.int64),
        }
        table = pa.table({k: _arrow_column(v) for k, v in cols.items()})
        writer = writer or pq.ParquetWriter(path, table.schema, compression="snappy")
        writer.write_table(table)  # one row group per episode, as LeRobot writes them
        parts.append(cols)
        ep_stats.append({k: feature_stats(v) for k, v in cols.items()})
        ep_rows.append(
            {
                "episode_index": e,
                "tasks": [task],
                "length": n,
                "data/chunk_index": 0,
                "data/file_index": 0,
                "dataset_from_index": start,
                "dataset_to_index": start + n,
            }
        )
        start += n
    writer.close()
    return ep_rows, ep_stats, {k: np.concatenate([c[k] for c in parts]) for k in parts[0]}


def _arrow_column(values: np.ndarray):
    """A numpy column as LeRobot's Arrow type: scalars as they are, vectors as fixed-size lists."""
    import pyarrow as pa

    if values.ndim == 1:
        return pa.array(values)
    return pa.FixedSizeListArray.from_arrays(pa.array(values.reshape(-1)), values.shape[1])


def _write_videos(
    root: Path, episodes: list[Episode], cameras: list[str], fps: int, ep_rows: list[dict]
) -> tuple[dict, dict]:
    """One MP4 per camera holding every episode in order; the episode rows get their video spans."""
    from twin.export.video import check_size, encode_mp4, probe

    info, stats = {}, {}
    for name in cameras:
        key = f"observation.images.{name}"
        track = episodes[0].rec.cameras[name]
        check_size(name, track.width_px, track.height_px)
        shape = (track.height_px, track.width_px, 3)
        path = root / VIDEO_PATH.format(video_key=key, chunk_index=0, file_index=0)
        path.parent.mkdir(parents=True)
        stats[key] = []
        encode_mp4(
            path,
            _camera_images(
                episodes=episodes,
                name=name,
                fps=fps,
                shape=shape,
                ep_rows=ep_rows,
                stats_out=stats[key],
            ),
            fps,
            shape[1],
            shape[0],
        )
        info[key] = {"shape": list(shape), "info": probe(path)}
    return info, stats


def _camera_images(
    episodes: list[Episode],
    name: str,
    fps: int,
    shape: tuple[int, int, int],
    ep_rows: list[dict],
    stats_out: list[dict],
):
    """Each episode's images of one camera in turn, decoded one picture at a time (a picture shown
    by several dataset frames is decoded once: they come in order); records each episode's video
    span in its row and, once its images are through, its image statistics in stats_out (from the
    sampled frames' subsampled copies, image_stats's sample)."""
    key, at = f"observation.images.{name}", 0
    stride = image_stride(shape)
    for ep, row in zip(episodes, ep_rows, strict=True):
        track = ep.rec.cameras[name]
        if (track.height_px, track.width_px, 3) != shape:
            raise ConfigError(
                f"recording {ep.rec.path!r}: camera {name!r} is "
                f"{track.width_px}x{track.height_px} px; "
                f"expected {shape[1]}x{shape[0]} px as in the first recording"
            )
        picks = camera_picks(ep, name, fps).tolist()
        sampled = set(image_sample(len(picks)))
        row.update(
            {
                f"videos/{key}/chunk_index": 0,
                f"videos/{key}/file_index": 0,
                f"videos/{key}/from_timestamp": at / fps,
                f"videos/{key}/to_timestamp": (at + len(ep)) / fps,
            }
        )
        at += len(ep)
        thumbs, shown, image = [], -1, None
        for k, i in enumerate(picks):
            if i != shown:
                # (height, width, 3) as configured, or a RecordingError
                image, shown = track_rgb(track, i), i
            if k in sampled:
                # a copy: the picture itself is not kept
                thumbs.append(image[::stride, ::stride].copy())
            yield image
        stats_out.append(sampled_image_stats(thumbs))


def _merged_image_stats(per_episode: list[dict]) -> dict:
    """The dataset's image stats from the episodes' (as LeRobot merges them: count-weighted mean
    and variance, min of mins, max of maxes, low quantiles' min and high quantiles' max)."""
    arr = {k: np.array([p[k] for p in per_episode], dtype=np.float64) for k in per_episode[0]}
    counts = arr["count"].reshape(-1, 1, 1, 1)
    total = counts.sum()
    mean = (arr["mean"] * counts).sum(axis=0) / total
    var = ((arr["std"] ** 2 + (arr["mean"] - mean) ** 2) * counts).sum(axis=0) / total
    out = {
        "min": arr["min"].min(axis=0).tolist(),
        "max": arr["max"].max(axis=0).tolist(),
        "mean": mean.tolist(),
        "std": np.sqrt(var).tolist(),
        "count": [int(total)],
    }
    for key in (k for k in per_episode[0] if k.startswith("q")):
        out[key] = (arr[key].min(axis=0) if int(key[1:]) <= 50 else arr[key].max(axis=0)).tolist()
    return out


def _features(state_of: list[str], action_of: list[str], video_info: dict) -> dict:
    features = {
        "observation.state": {"dtype": "float32", "shape": [len(state_of)], "names": state_of},
        "action": {"dtype": "float32", "shape": [len(action_of)], "names": action_of},
    }
    for key, v in video_info.items():
        features[key] = {
            "dtype": "video",
            "shape": v["shape"],
            "names": ["height", "width", "channels"],
            "info": v["info"],
        }
    features["timestamp"] = {"dtype": "float32", "shape": [1], "names": None}
    for key in INDEX_FEATURES[1:]:
        features[key] = {"dtype": "int64", "shape": [1], "names": None}
    return features


def _write_episodes(root: Path, ep_rows: list[dict], ep_stats: list[dict]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = []
    for row, stats in zip(ep_rows, ep_stats, strict=True):
        flat = dict(row)
        for feature, values in stats.items():
            for stat, value in values.items():
                flat[f"stats/{feature}/{stat}"] = value
        flat["meta/episodes/chunk_index"], flat["meta/episodes/file_index"] = 0, 0
        rows.append(flat)
    table = pa.Table.from_pylist(rows)
    path = root / EPISODES_PATH.format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True)
    pq.write_table(table, path, compression="snappy")


def _write_tasks(root: Path, task_index: dict[str, int]) -> None:
    """tasks.parquet as pandas writes LeRobot's DataFrame (task_index, indexed by the task text):
    the pandas metadata is written by hand, so pandas is not needed to write it."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    pandas_meta = {
        "index_columns": ["task"],
        "column_indexes": [
            {
                "name": None,
                "field_name": None,
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": {"encoding": "UTF-8"},
            }
        ],
        "columns": [
            {
                "name": "task_index",
                "field_name": "task_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {
                "name": "task",
                "field_name": "task",
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": None,
            },
        ],
        "attributes": {},
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }
    table = pa.table(
        {
            "task_index": pa.array(list(task_index.values()), pa.int64()),
            "task": pa.array(list(task_index), pa.string()),
        },
        metadata={"pandas": json.dumps(pandas_meta)},
    )
    pq.write_table(table, root / "meta/tasks.parquet")


def _write_json(path: Path, value: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(value, indent=4, allow_nan=False) + "\n")


def _publish(tmp: Path, out: Path, overwrite: bool) -> None:
    """Move the finished dataset into place: as a new folder, into an empty one, or (overwrite) over
    an old dataset, which is renamed aside first and removed only once the new one is in place."""
    for path in sorted(tmp.rglob("*")):
        if path.is_file():
            fsync_file(path)
    if out.exists() and any(out.iterdir()):
        if not overwrite:  # checked before any work too; a folder filled meanwhile is not replaced
            raise ConfigError(
                f"output folder {str(out)!r} is not empty; expected a new or empty "
                f"folder (or --force)"
            )
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-{os.getpid()}-", dir=out.parent))
        publish(out, old / out.name)
        publish(tmp, out)
        shutil.rmtree(old, ignore_errors=True)
    elif out.exists():
        # an empty folder (perhaps the current one): filled in place, meta/ (info.json) last
        for name in sorted(p.name for p in tmp.iterdir() if p.name != "meta") + ["meta"]:
            publish(tmp / name, out / name)
        tmp.rmdir()
    else:
        publish(tmp, out)
