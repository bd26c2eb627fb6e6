"""`twin export --format lerobot` on real runs: LeRobot's v3.0 layout, exact timestamps, contiguous
indices, the recorded values, decodable video, and --verify leaving out a recording whose replay
differs from it."""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import av
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from support.cli import twin

import twin as twin_pkg
from twin.pictures import track_rgb
from twin.verify.replay import save

ROOT = Path(__file__).resolve().parents[2]
SEED001 = ROOT / "recordings" / "pick_place_seed001.mcap"
SEED000_LOOP = ROOT / "recordings" / "seed000_seed000.mcap"
FPS = 30
VIDEO = "videos/observation.images.overhead/chunk-000/file-000.mp4"


@pytest.fixture(scope="module")
def camera_run(tmp_path_factory):
    """Two pick_place cycles with the overhead camera, recorded by `twin run` (in this process)."""
    path = tmp_path_factory.mktemp("camera_run") / "cam.mcap"
    from twin.cli import main

    assert (
        main(["run", "pick_place", "--cycles", "2", "--camera", "overhead", "--record", str(path)])
        == 0
    )
    return path


@pytest.fixture(scope="module")
def dataset(camera_run, tmp_path_factory):
    """The camera run as a verified dataset at 30 fps, one episode per cycle (two)."""
    out = tmp_path_factory.mktemp("ds") / "pick_place_ds"
    from twin.cli import main

    assert (
        main(
            [
                "export",
                str(camera_run),
                "--format",
                "lerobot",
                "--fps",
                str(FPS),
                "--episodes",
                "cycles",
                "--task",
                "pick the box and place it",
                "--verify",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    return out


def test_layout_and_info(dataset):
    files = sorted(str(p.relative_to(dataset)) for p in dataset.rglob("*") if p.is_file())
    assert files == [
        "data/chunk-000/file-000.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "meta/info.json",
        "meta/stats.json",
        "meta/tasks.parquet",
        "meta/twin_provenance.json",
        VIDEO,
    ]
    info = json.loads((dataset / "meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == FPS
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert (
        info["video_path"] == "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    )
    assert (info["chunks_size"], info["data_files_size_in_mb"], info["video_files_size_in_mb"]) == (
        1000,
        100,
        200,
    )
    assert (
        info["total_episodes"] == 2
        and info["total_tasks"] == 1
        and info["splits"] == {"train": "0:2"}
    )
    assert info["robot_type"] == "mtb"
    data = pq.read_table(dataset / "data/chunk-000/file-000.parquet")
    assert info["total_frames"] == data.num_rows
    features = info["features"]
    assert list(features) == [
        "observation.state",
        "action",
        "observation.images.overhead",
        "timestamp",
        "frame_index",
        "episode_index",
        "index",
        "task_index",
    ]
    assert features["observation.state"]["shape"] == [6] and features["action"]["shape"] == [5]
    assert features["action"]["names"][-1] == "suction.command"
    image = features["observation.images.overhead"]
    assert image["dtype"] == "video" and image["shape"] == [240, 320, 3]
    assert image["names"] == ["height", "width", "channels"]
    assert image["info"]["video.codec"] == "av1" and image["info"]["video.pix_fmt"] == "yuv420p"
    assert image["info"]["video.fps"] == FPS
    assert data.column_names == [
        "observation.state",
        "action",
        "timestamp",
        "frame_index",
        "episode_index",
        "index",
        "task_index",
    ]
    assert str(data.schema.field("observation.state").type) == "fixed_size_list<element: float>[6]"
    assert str(data.schema.field("timestamp").type) == "float"
    # one per episode
    assert pq.ParquetFile(dataset / "data/chunk-000/file-000.parquet").num_row_groups == 2
    tasks = pd.read_parquet(dataset / "meta/tasks.parquet")
    assert tasks.index.name == "task" and tasks.iloc[0].name == "pick the box and place it"
    assert tasks.loc["pick the box and place it", "task_index"] == 0
    stats = json.loads((dataset / "meta/stats.json").read_text())
    assert set(stats) == set(features)
    for key in ("min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"):
        assert key in stats["action"]
    assert stats["index"]["count"] == [data.num_rows]
    assert np.array(stats["observation.images.overhead"]["mean"]).shape == (3, 1, 1)


def test_timestamps_are_exact_and_indices_contiguous(dataset):
    data = pq.read_table(dataset / "data/chunk-000/file-000.parquet").to_pandas()
    episodes = pq.read_table(dataset / "meta/episodes/chunk-000/file-000.parquet").to_pandas()
    assert list(episodes["episode_index"]) == [0, 1]
    assert list(data["index"]) == list(range(len(data)))
    assert data["episode_index"].is_monotonic_increasing
    for _, ep in episodes.iterrows():
        rows = data.iloc[ep["dataset_from_index"] : ep["dataset_to_index"]]
        assert (rows["episode_index"] == ep["episode_index"]).all() and len(rows) == ep["length"]
        frame_index = rows["frame_index"].to_numpy()
        assert np.array_equal(frame_index, np.arange(ep["length"]))
        ts = rows["timestamp"].to_numpy()
        assert ts.dtype == np.float32
        # as LeRobot computes and stores it
        assert np.array_equal(ts, (frame_index / FPS).astype(np.float32))
        assert np.all(
            np.abs(ts.astype(np.float64) - frame_index / FPS) <= np.spacing(np.float32(ts.max()))
        )
        # LeRobot's timestamp sync check (tolerance_s 1e-4)
        assert np.all(np.abs(np.diff(ts) - 1 / FPS) < 1e-4)
        assert list(ep["tasks"]) == ["pick the box and place it"]
    assert episodes["dataset_to_index"].iloc[-1] == len(data)
    assert list(episodes["dataset_from_index"].iloc[1:]) == list(
        episodes["dataset_to_index"].iloc[:-1]
    )


def test_state_and_action_are_recorded_values(dataset, camera_run):
    """At 240 Hz recorded and 30 fps exported, dataset frame k of an episode is the recorded step
    first_step + 8k: state and action are that frame's values, as float32."""
    rec = twin_pkg.load(camera_run)
    data = pq.read_table(dataset / "data/chunk-000/file-000.parquet").to_pandas()
    provenance = json.loads((dataset / "meta/twin_provenance.json").read_text())
    (source,) = provenance["sources"]
    assert (
        source["verified"] is True and source["replay"] == "exact" and source["file"] == "cam.mcap"
    )
    phase_steps = [
        e.step
        for e in rec.events
        if e.kind == "phase" and e.message.startswith("cycle ") and "pick" in e.message
    ]
    assert [ep["first_step"] for ep in source["episodes"]] == phase_steps
    table = rec.to_arrow()
    command = table.column("suction.command").to_numpy(zero_copy_only=False)
    for ep in source["episodes"]:
        rows = data[data["episode_index"] == ep["episode_index"]]
        steps = ep["first_step"] + 8 * rows["frame_index"].to_numpy()
        state = np.stack(rows["observation.state"].to_numpy())
        action = np.stack(rows["action"].to_numpy())
        assert np.array_equal(state[:, :4], rec.frames.joint_q[steps].astype(np.float32))
        assert np.array_equal(state[:, 5], (rec.frames.held_body[steps] >= 0).astype(np.float32))
        assert np.array_equal(action[:, :4], rec.frames.joint_target[steps].astype(np.float32))
        assert np.array_equal(action[:, 4], command[steps].astype(np.float32))
        # each cycle switches suction on and holds the box
        assert action[:, 4].any() and state[:, 5].any()


def test_video_decodes_one_frame_per_dataset_frame(dataset, camera_run):
    rec = twin_pkg.load(camera_run)
    episodes = pq.read_table(dataset / "meta/episodes/chunk-000/file-000.parquet").to_pandas()
    total = int(episodes["length"].sum())
    with av.open(str(dataset / VIDEO)) as container:
        stream = container.streams.video[0]
        frames = [
            (f.pts * stream.time_base, f.to_ndarray(format="rgb24"))
            for f in container.decode(stream)
        ]
    assert len(frames) == total
    assert all(img.shape == (240, 320, 3) for _, img in frames)
    assert [float(t) for t, _ in frames] == [i / FPS for i in range(total)]
    key = "videos/observation.images.overhead"
    assert list(episodes[f"{key}/from_timestamp"]) == [0.0, episodes["length"].iloc[0] / FPS]
    assert list(episodes[f"{key}/to_timestamp"]) == list(episodes["dataset_to_index"] / FPS)
    # frame 0 of episode 1 shows the camera image taken nearest its time (AV1 at crf 30 is lossy)
    first = int(episodes["dataset_from_index"].iloc[1])
    provenance = json.loads((dataset / "meta/twin_provenance.json").read_text())
    step = provenance["sources"][0]["episodes"][1]["first_step"]
    track = rec.cameras["overhead"]
    shown = track_rgb(track, int(np.argmin(np.abs(track.step - step)))).astype(np.float64)
    assert np.abs(frames[first][1].astype(np.float64) - shown).mean() < 4.0
    # not a stale one
    first_picture = track_rgb(track, 0).astype(np.float64)
    assert np.abs(frames[first][1].astype(np.float64) - first_picture).mean() > 0


def test_same_input_gives_the_same_bytes(camera_run, tmp_path, capsys):
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        assert (
            twin(capsys, "export", camera_run, "--format", "lerobot", "--fps", "15", "-o", out)[0]
            == 0
        )
    for path in sorted(p for p in outs[0].rglob("*") if p.is_file()):
        assert path.read_bytes() == (outs[1] / path.relative_to(outs[0])).read_bytes(), path


def test_decimated_run_and_a_golden_at_an_uneven_rate(tmp_path, capsys):
    """A --rate 4 run and a golden, both without camera, at 7 fps: each dataset frame is the
    recorded frame nearest its time."""
    mcap = tmp_path / "rate4.mcap"
    assert (
        twin(capsys, "run", "pick_place", "--cycles", "1", "--rate", "4", "--record", mcap)[0] == 0
    )
    out = tmp_path / "ds"
    code, stdout, _ = twin(
        capsys, "export", mcap, SEED001, "--format", "lerobot", "--fps", "7", "-o", out
    )
    assert code == 0 and "2 episode(s)" in stdout and "no camera" in stdout
    info = json.loads((out / "meta/info.json").read_text())
    assert info["video_path"] is None and "observation.images.overhead" not in info["features"]
    assert info["robot_type"] == "mtb+seed001"
    data = pq.read_table(out / "data/chunk-000/file-000.parquet").to_pandas()
    rec = twin_pkg.load(mcap)
    rows = data[data["episode_index"] == 0]
    assert len(rows) == rec.frames.t_ns[-1] * 7 // 10**9 + 1
    # the recorded frame nearest each sample time k / 7 s (the earlier of two as near)
    off = np.abs(rec.frames.t_ns[None, :] * 7 - rows["frame_index"].to_numpy()[:, None] * 10**9)
    nearest = np.argmin(off, axis=1)
    state = np.stack(rows["observation.state"].to_numpy())
    assert np.array_equal(state[:, :4], rec.frames.joint_q[nearest].astype(np.float32))
    # 240/4 Hz to 7 fps: uneven strides
    assert len(set(np.diff(rec.frames.step[nearest]).tolist())) > 1


def _tampered_copy(src: Path, dst: Path) -> None:
    """A real recording whose frames are not what its commands replay to: one joint target 0.01 rad
    off."""
    rec = twin_pkg.load(src)
    i = next(i for i, c in enumerate(rec.commands) if c.kind == "joint_target" and c.step > 0)
    c = rec.commands[i]
    rec.commands[i] = dataclasses.replace(c, args={**c.args, "q": c.args["q"] + 0.01})
    save(rec, dst)


def test_verify_leaves_out_a_recording_whose_replay_differs(pick_place_mcap, tmp_path, capsys):
    good = pick_place_mcap[0]
    bad = tmp_path / "tampered.mcap"
    _tampered_copy(good, bad)
    out = tmp_path / "ds"
    code, stdout, err = twin(
        capsys, "export", good, bad, "--format", "lerobot", "--fps", "10", "--verify", "-o", out
    )
    assert code == 1 and "1 of 2 recording(s) left out" in err and err.count("\n") == 1
    assert f"verified {good}: replay exact" in stdout
    assert f"left out {bad}: replay differs: step " in stdout
    info = json.loads((out / "meta/info.json").read_text())
    assert info["total_episodes"] == 1
    provenance = json.loads((out / "meta/twin_provenance.json").read_text())
    by_file = {s["file"]: s for s in provenance["sources"]}
    assert (
        by_file["tampered.mcap"]["verified"] is False
        and by_file["tampered.mcap"]["exported"] is False
    )
    assert by_file["pick.mcap"]["exported"] is True and len(by_file["pick.mcap"]["sha256"]) == 64
    assert provenance["verify"] is True and provenance["twin_version"]
    # alone, nothing is written
    code, _, err = twin(
        capsys,
        "export",
        bad,
        "--format",
        "lerobot",
        "--fps",
        "10",
        "--verify",
        "-o",
        tmp_path / "none",
    )
    assert code == 1 and "nothing written" in err and not (tmp_path / "none").exists()
    # without --verify it is exported, and the sidecar says it was not checked
    assert (
        twin(
            capsys,
            "export",
            bad,
            "--format",
            "lerobot",
            "--fps",
            "10",
            "-o",
            tmp_path / "unchecked",
        )[0]
        == 0
    )
    provenance = json.loads((tmp_path / "unchecked/meta/twin_provenance.json").read_text())
    assert (
        provenance["sources"][0]["verified"] is None
        and provenance["sources"][0]["replay"] == "not checked"
    )


def test_overwrite_replaces_a_dataset_whole(pick_place_mcap, tmp_path, capsys):
    out = tmp_path / "ds"
    assert (
        twin(capsys, "export", pick_place_mcap[0], "--format", "lerobot", "--fps", "10", "-o", out)[
            0
        ]
        == 0
    )
    code, _, err = twin(
        capsys, "export", pick_place_mcap[0], "--format", "lerobot", "--fps", "20", "-o", out
    )
    assert code == 2 and "is not empty" in err
    assert json.loads((out / "meta/info.json").read_text())["fps"] == 10  # untouched
    assert (
        twin(
            capsys,
            "export",
            pick_place_mcap[0],
            "--format",
            "lerobot",
            "--fps",
            "20",
            "--overwrite",
            "-o",
            out,
        )[0]
        == 0
    )
    assert json.loads((out / "meta/info.json").read_text())["fps"] == 20
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]  # no .partial or .old folder left


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["--format", "lerobot", "-o", "ds"], "--format lerobot needs --fps N"),
        (["--format", "lerobot", "--fps", "2.5", "-o", "ds"], "'2.5' is not a whole number >= 1"),
        (["--format", "lerobot", "--fps", "0", "-o", "ds"], "'0' is not a whole number >= 1"),
        (
            ["--format", "lerobot", "--fps", "30", "--table", "events", "-o", "ds"],
            "--table is for --format parquet",
        ),
        (["--format", "lerobot", "--fps", "30", "-o", "full"], "'full' is not empty"),
        (
            ["--format", "lerobot", "--fps", "30", "--overwrite", "-o", "full"],
            "holds no meta/info.json",
        ),
        (["--format", "lerobot", "--fps", "30", "-o", "no/ds"], "folder 'no' does not exist"),
        (
            ["--format", "lerobot", "--fps", "30", "--episodes", "cycles", "-o", "ds"],
            "has no pick-place cycles",
        ),
    ],
)
def test_bad_lerobot_exports_are_one_line_exit_2(tmp_path, capsys, monkeypatch, argv, expected):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "notes.txt").write_text("mine")
    code, _, err = twin(capsys, "export", SEED000_LOOP, *argv)
    assert (
        code == 2 and err.startswith("twin: error: ") and err.count("\n") == 1 and expected in err
    ), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full"]
    assert (tmp_path / "full" / "notes.txt").read_text() == "mine"


def test_recordings_with_different_cameras_are_refused(
    camera_run, pick_place_mcap, tmp_path, capsys
):
    code, _, err = twin(
        capsys,
        "export",
        camera_run,
        pick_place_mcap[0],
        "--format",
        "lerobot",
        "--fps",
        "10",
        "-o",
        tmp_path / "ds",
    )
    assert code == 2 and "different cameras" in err and not (tmp_path / "ds").exists()
    assert list(tmp_path.iterdir()) == []


def test_video_without_pyav_is_one_line_exit_2(camera_run, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "av", None)  # import av now raises ImportError
    code, _, err = twin(
        capsys, "export", camera_run, "--format", "lerobot", "--fps", "10", "-o", tmp_path / "ds"
    )
    assert (
        code == 2
        and err
        == "twin: error: video export needs the av package (PyAV): pip install 'twin[export]' "
        "or pip install av\n"
    )
    assert list(tmp_path.iterdir()) == []


def test_an_empty_folder_is_filled_in_place(pick_place_mcap, tmp_path, capsys, monkeypatch):
    """`-o .` in an empty folder: the dataset lands in it (the folder itself is not replaced)."""
    folder = tmp_path / "ds"
    folder.mkdir()
    inode = folder.stat().st_ino
    monkeypatch.chdir(folder)
    assert (
        twin(capsys, "export", pick_place_mcap[0], "--format", "lerobot", "--fps", "10", "-o", ".")[
            0
        ]
        == 0
    )
    assert folder.stat().st_ino == inode and (folder / "meta" / "info.json").is_file()
    assert sorted(p.name for p in folder.iterdir()) == ["data", "meta"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
