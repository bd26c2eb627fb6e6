"""`twin export --format lerobot` from start to end: check the folder, load (and with --verify
replay) the recordings, cut and resample the episodes, write the dataset with its provenance."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from twin.export.episodes import Episode, episodes
from twin.export.lerobot import Written, write_dataset
from twin.export.sources import Source, check_recording, load_source, verify
from twin.model.errors import ConfigError
from twin.record.outputs import check_target


def check_folder(out: Path, inputs: list[str], overwrite: bool) -> Path:
    """The dataset folder may be written: its parent exists, and it is new, an empty folder, or with
    overwrite an earlier dataset (it holds meta/info.json) holding none of the inputs."""
    check_target(out, "dataset", "a folder path", folder=True)
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise ConfigError(
                f"dataset folder {str(out)!r} is not empty; expected a new or empty folder "
                "(or --force to replace an earlier dataset)"
            )
        if not (out / "meta" / "info.json").is_file():
            raise ConfigError(
                f"dataset folder {str(out)!r} holds no meta/info.json; --force replaces only "
                "an earlier dataset"
            )
        inside = [p for p in inputs if out.resolve() in Path(p).resolve().parents]
        if inside:
            raise ConfigError(
                f"input {inside[0]!r} is inside dataset folder {str(out)!r}, which --overwrite "
                "would replace; expected another folder"
            )
    return out


def export_lerobot(
    paths: list[str],
    out: Path,
    fps: int,
    *,
    mode: str = "recording",
    task: str | None = None,
    verify_first: bool = False,
    overwrite: bool = False,
    say: Callable[[str], None] = lambda line: None,
) -> tuple[Written | None, list[Source]]:
    """Export the recordings at paths as a LeRobot dataset in out; returns what was written (None
    when --verify left every recording out: then nothing is written) and every source, verified or
    not."""
    check_folder(out, paths, overwrite)
    sources = [load_source(path) for path in paths]
    # a damaged file is exit 2 before any work, also before --verify's replay
    for source in sources:
        check_recording(source.rec, fps)
    if verify_first:
        for source in sources:
            verify(source)
            say(
                f"{'verified' if source.verified else 'left out'} {source.path}: replay "
                f"{source.replay}"
            )
    kept = [s for s in sources if s.verified is not False]
    if not kept:
        return None, sources
    eps = episodes([s.rec for s in kept], fps, mode)
    tasks = [task if task is not None else _default_task(ep) for ep in eps]
    written = write_dataset(
        eps,
        tasks,
        out.absolute(),
        fps,
        provenance(sources, eps, fps, mode, verify_first),
        overwrite=overwrite,
    )  # absolute: `-o .` has a folder to write beside
    written.path = out
    return written, sources


def _default_task(ep: Episode) -> str:
    run = ep.rec.run or {}
    return str(run.get("task") or run.get("source") or "twin recording")


def provenance(
    sources: list[Source], eps: list[Episode], fps: int, mode: str, verified: bool
) -> dict:
    """meta/twin_provenance.json: how the dataset was made and from which files (name and sha256),
    whether each replayed exactly, and which episodes came from it."""
    from twin.record.mcap.metadata import versions

    entries = []
    for source in sources:
        entry = source.provenance()
        mine = [(i, ep) for i, ep in enumerate(eps) if ep.rec is source.rec]
        entry["exported"] = bool(mine)
        entry["episodes"] = [
            {
                "episode_index": i,
                "cycle": ep.cycle,
                "first_step": int(ep.rec.frames.step[ep.rows[0]]),
                "frames": len(ep),
            }
            for i, ep in mine
        ]
        entries.append(entry)
    return {
        "exported_by": "twin export",
        "twin_version": versions()["twin"],
        "fps": fps,
        "episodes": mode,
        "verify": verified,
        "sources": entries,
    }
