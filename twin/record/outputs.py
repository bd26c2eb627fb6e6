"""Output files: checked before any work, written beside their place and renamed in when complete.

A recording is never written in place: a run killed part-way would leave a broken file where a good
one was. Writers fill `NAME.partial` beside the target (`twin recover` finds it after a kill), then
fsync it and rename it over the target, so the target is either the old file or the whole new one.
"""

from __future__ import annotations

import ctypes
import functools
import os
import secrets
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from stat import S_IMODE

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
    force: bool | None = None,
) -> Path:
    """`path` as a Path if it may be written: it ends in `suffix`, it is no folder, its folder
    exists (runs/ is made if missing: make_default_folder), it is none of `inputs` (nor the same
    file through a link), and, with force=False, it does not exist yet (refuse_existing).
    ConfigError (exit 2) otherwise."""
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
    if force is False:
        refuse_existing(p, option)
    return p


def refuse_existing(path: str | os.PathLike, option: str, *, folder: bool = False) -> None:
    """ConfigError (exit 2) naming `path` if it exists (with folder=True: a folder holding
    anything): a user's file is replaced only with --force. A command's own unfinished output
    (`NAME.partial`) is another path, so it never counts."""
    p = Path(path)
    if folder:
        taken = p.is_dir() and any(p.iterdir())
    else:
        taken = p.exists() or p.is_symlink()
    if taken:
        what = "is a folder that is not empty" if folder else "exists already"
        raise ConfigError(
            f"{option} {str(path)!r} {what}; expected a new "
            f"{'or empty folder' if folder else 'path'}, or --force to replace it"
        )


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


SYNC_FILE_RANGE_WRITE = 2  # Linux's flag: start writing the range's dirty pages, do not wait
WRITEBACK_BYTES = 256 * 1024  # a growing file's writeback is started at most this often (Writeback)


@functools.cache
def _sync_file_range():
    """libc's sync_file_range, or None where the C library has none (not Linux) or cannot be
    loaded so (CDLL(None) is refused on Windows)."""
    try:
        call = getattr(ctypes.CDLL(None, use_errno=True), "sync_file_range", None)
    except (OSError, TypeError):
        return None
    if call is not None:
        call.argtypes = [ctypes.c_int, ctypes.c_int64, ctypes.c_int64, ctypes.c_uint]
    return call


def start_writeback(fd: int) -> None:
    """Have the OS start putting what is written to the open file `fd` on disk, without waiting
    for it; where the OS has no such call, or it fails, nothing happens."""
    call = _sync_file_range()
    if call is not None:
        call(fd, 0, 0, SYNC_FILE_RANGE_WRITE)  # 0 bytes: to the end of the file


class Writeback:
    """A growing file's writeback, started each time another `every_bytes` of it are written: the
    fsync that finishes it (publish) then writes only what came since. A writer says how large its
    file has grown (grew_to) whenever it likes: the call costs about 0.1 ms of CPU on our machines
    (the MCAP writer's per frame rose 11% with one at every flush), so it is made only so often."""

    def __init__(self, fd: int, every_bytes: int = WRITEBACK_BYTES) -> None:
        self.fd, self.every_bytes = fd, every_bytes
        self._started_at = 0  # the file's size at the last writeback started

    def grew_to(self, size: int) -> None:
        if size - self._started_at >= self.every_bytes:
            start_writeback(self.fd)
            self._started_at = size


def publish(written: str | os.PathLike, target: str | os.PathLike) -> None:
    """Put a completely written file (or folder) in its place: fsync it, rename it over `target`
    (atomic on one file system), fsync the folder so the rename itself is durable. The one rename of
    the twin's outputs; OutputError naming `target` and the system's reason if any step fails."""
    try:
        fsync_file(written)
        os.replace(written, target)
        folder = os.open(Path(target).parent, os.O_RDONLY)
        try:
            os.fsync(folder)
        finally:
            os.close(folder)
    except OSError as err:
        raise _cannot_write(target, err) from err


@contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside `target` (`.NAME.<hex>.tmp`: hidden, in the same folder, made
    with the mode a new file gets, or target's mode if it exists) for the body to write; when the
    body ends, the file is fsynced and renamed over `target` (publish), so `target` is the old file
    or the whole new one. The temporary is removed on any error or KeyboardInterrupt; a failed write
    is an OutputError naming `target` and the system's reason (a read-only folder, a full disk)."""
    target = Path(target)
    tmp = target.with_name(f".{target.name}.{secrets.token_hex(4)}.tmp")
    try:
        mode = S_IMODE(os.stat(target).st_mode)
    except OSError:
        mode = None  # a new file: the mode the umask gives it, as a plain write would
    try:
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            if mode is not None:
                os.chmod(tmp, mode)
        except OSError as err:
            raise _cannot_write(target, err) from err
        try:
            yield tmp
        except OSError as err:
            raise _cannot_write(target, err) from err
        publish(tmp, target)
    finally:
        with suppress(OSError):  # never made, or its folder refuses: the error above says why
            tmp.unlink(missing_ok=True)


def write_atomic(target: str | os.PathLike, data: str | bytes) -> None:
    """Write `data` (text as UTF-8) to `target` through atomic_path: all of it or, on an
    OutputError, nothing changed."""
    with atomic_path(target) as tmp:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)


def _cannot_write(target: str | os.PathLike, err: OSError) -> OutputError:
    return OutputError(f"cannot write {str(target)!r}: {err.strerror or err}")
