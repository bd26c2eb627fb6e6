"""Which kind of golden a file is, from the files alone: a sweep golden's definition (a NAME.toml
with task, scenarios and seed, its NAME.summary.json beside it), a search golden (a NAME.toml
with NAME.expect.json beside it), or else a recording.

`twin check` sorts what a folder holds with these before anything is judged; judging each kind is
twin.verify (recordings) and twin.sweep (sweep and search goldens).
"""

from __future__ import annotations

import os
from pathlib import Path
from stat import S_ISREG

from twin.model.errors import ConfigError
from twin.model.json_values import load_toml_text

DEFINITION_KEYS = ("task", "scenarios", "seed")  # what makes a .toml a sweep definition
EXPECT_SUFFIX = ".expect.json"  # a search golden's expectation, beside its NAME.toml
MAX_DEFINITION_BYTES = 4 * 2**20  # the largest definition read: a golden is a few kB


def summary_path(definition: str | os.PathLike) -> Path:
    """A sweep golden's expected summary: NAME.summary.json beside NAME.toml."""
    path = Path(definition)
    return path.with_name(path.stem + ".summary.json")


def expect_path(definition: str | os.PathLike) -> Path:
    """A search golden's expectation: NAME.expect.json beside NAME.toml."""
    path = Path(definition)
    return path.with_name(path.stem + EXPECT_SUFFIX)


def is_search_golden(path: Path) -> bool:
    """A NAME.toml with NAME.expect.json beside it, wherever it lies (`twin check` takes it as a
    search golden, and the NAME.mcap beside it as part of it)."""
    return path.suffix == ".toml" and expect_path(path).is_file()


def is_sweep_golden(path: str, *, named: bool) -> bool:
    """Whether a .toml file is a sweep golden's definition (task, scenarios and seed). A file named
    on the command line must be one: ConfigError saying why not. One found in a folder that is not
    is skipped (a robot profile kept beside the goldens), unless NAME.summary.json beside it says
    it is a golden: then it is an error, never skipped."""
    problem = not_a_definition(Path(path))
    if problem is None:
        return True
    if named:
        raise ConfigError(f"sweep definition {path!r} {problem}")
    if summary_path(path).exists():
        raise ConfigError(f"sweep golden {path!r} (beside {summary_path(path).name}) {problem}")
    return False


def not_a_definition(path: Path) -> str | None:
    """None when path is a sweep definition (a TOML file with task, scenarios and seed), else why
    not."""
    try:
        text = regular_text(path, MAX_DEFINITION_BYTES)
        data = load_toml_text(text, "is not valid TOML")  # also too deep: one line
    except (ConfigError, ValueError) as err:
        return str(err)
    missing = [k for k in DEFINITION_KEYS if k not in data]
    if missing:
        return (
            f"lacks {', '.join(missing)}; expected a sweep definition with "
            f"{', '.join(DEFINITION_KEYS)}"
        )
    return None


def regular_text(path: Path, max_bytes: int) -> str:
    """path's text when it is a regular file of at most max_bytes, else ValueError saying why. A
    FIFO, device or folder is refused before it is opened (reading a FIFO waits for a writer for
    ever)."""
    not_regular = "is not a regular file (a FIFO, device or folder); expected a file"
    try:
        st = os.stat(path)
        if not S_ISREG(st.st_mode):
            raise ValueError(not_regular)
        if st.st_size > max_bytes:
            raise ValueError(f"holds {st.st_size} bytes; expected at most {max_bytes}")
        # never blocks, even if swapped for a FIFO
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as f:
            if not S_ISREG(os.fstat(f.fileno()).st_mode):
                raise ValueError(not_regular)
            data = f.read(max_bytes + 1)
    except FileNotFoundError:
        raise ValueError("does not exist") from None
    except OSError as err:
        raise ValueError(f"cannot be read: {err.strerror or err}") from err
    if len(data) > max_bytes:
        raise ValueError(f"holds more than {max_bytes} bytes; expected at most {max_bytes}")
    try:
        return data.decode()
    except UnicodeDecodeError as err:
        raise ValueError(f"is not UTF-8 text: {err}") from err
