"""Output files: checked before any work, written beside their place and renamed in when complete.

A recording is never written in place: a run killed part-way would leave a broken file where a good
one was. Writers fill `NAME.partial` beside the target (`twin recover` finds it after a kill), then
fsync it and rename it over the target, so the target is either the old file or the whole new one.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from twin.model.errors import ConfigError, OutputError, TwinError

PARTIAL_SUFFIX = ".partial"
DEFAULT_FOLDER = "runs"  # where runs go by default: created when needed, as no other folder is


def make_default_folder(folder: str | os.PathLike) -> bool:
    """Create `runs/` (relative to the working directory) if `folder` is it and it is missing, so
    the README's first command works in a fresh clone; any other folder is the user's to create.
    True if `folder` exists (now). OutputError if runs/ cannot be made."""
    folder = Path(folder)
    if folder.is_dir() or folder != Path(DEFAULT_FOLDER):
        return folder.is_dir()
    try:
        folder.mkdir(exist_ok=True)  # exist_ok: made meanwhile by a twin started beside this one
    except FileExistsError:  # a file of that name
        return False
    except OSError as err:
        raise OutputError(
            f"cannot create the folder {DEFAULT_FOLDER!r}: {err.strerror or err}"
        ) from err
    return True


def partial_path(path: str | os.PathLike) -> Path:
    """Where a recording of `path` is written until it is finalized: `runs/x.mcap` ->
    `runs/x.mcap.partial`."""
    p = Path(path)
    return p.with_name(p.name + PARTIAL_SUFFIX)


def final_path(partial: str | os.PathLike) -> Path | None:
    """The target a `.partial` file was written for, or None if `partial` is not one."""
    p = Path(partial)
    return p.with_name(p.name[: -len(PARTIAL_SUFFIX)]) if p.name.endswith(PARTIAL_SUFFIX) else None


def check_output(
    path: str | os.PathLike,
    suffix: str,
    *,
    inputs: Iterable[str | os.PathLike] = (),
    option: str = "output",
) -> Path:
    """`path` as a Path if it may be written: it ends in `suffix`, it is no folder, its folder
    exists (runs/ is made if missing: make_default_folder), and it is none of `inputs` (nor the same
    file through a link). ConfigError (exit 2) otherwise."""
    p = Path(path)
    if p.suffix != suffix:
        raise ConfigError(f"{option} {str(path)!r} should end in {suffix}")
    if p.is_dir():
        raise ConfigError(
            f"cannot write {option} {str(path)!r}: it is a folder; expected a {suffix} file path"
        )
    folder = p.parent
    if not make_default_folder(folder):
        why = "is not a folder" if folder.exists() else "does not exist"
        raise ConfigError(
            f"cannot write {option} {str(path)!r}: folder {str(folder)!r} {why}; create it first"
        )
    for source in inputs:
        if _same_file(p, Path(source)):
            link = (
                ""
                if p.absolute() == Path(source).absolute()
                else " (the same file under another name)"
            )
            raise ConfigError(
                f"{option} {str(path)!r} would overwrite its input {str(source)!r}{link}; "
                "expected another path"
            )
    return p


def check_target(
    path: str | os.PathLike,
    what: str,
    expected: str,
    *,
    error: type[TwinError] = ConfigError,
    folder: bool = False,
) -> Path:
    """`path` as a Path a writer may create: the folder it goes in exists, and it is no folder (with
    folder=True: no file). `error` saying which, naming `what` and the `expected` kind of path."""
    p = Path(path)
    if not p.parent.is_dir():
        raise error(
            f"cannot write {what} {str(path)!r}: folder {str(p.parent)!r} does not "
            f"exist; create it first"
        )
    if (p.exists() and not p.is_dir()) if folder else p.is_dir():
        raise error(
            f"cannot write {what} {str(path)!r}: it is a "
            f"{'file' if folder else 'folder'}; expected {expected}"
        )
    return p


def _same_file(a: Path, b: Path) -> bool:
    """True for the same path, or two names of one file (symbolic or hard link)."""
    if a.absolute() == b.absolute():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist: they cannot be one file
        return False


def fsync_file(path: str | os.PathLike) -> None:
    """Have the OS put the file's bytes on disk (a finished recording survives a power cut)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def publish(written: str | os.PathLike, target: str | os.PathLike) -> None:
    """Put a completely written file in its place: fsync it, rename it over `target` (atomic on one
    file system), fsync the folder so the rename itself is durable."""
    fsync_file(written)
    os.replace(written, target)
    folder = os.open(Path(target).parent, os.O_RDONLY)
    try:
        os.fsync(folder)
    finally:
        os.close(folder)
