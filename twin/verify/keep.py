"""`twin check --keep DIR`: what a golden that differs leaves behind to look at, and nothing for one
that matches.

An .mcap golden (status differ or refused): DIR/NAME.mcap, its re-run as recorded (the file
`--update` would write), DIR/NAME.md, the Markdown report `twin diff --report` writes, and
DIR/NAME.rrd, the ghost view `twin diff --rrd` writes. A sweep golden: DIR/NAME.md (its report)
and the new run's DIR/NAME.summary.json (with DIR/NAME.results.parquet when the golden is paired).
A search golden: DIR/NAME.mcap (its scenario recorded again) and DIR/NAME.md.

NAME is the golden's file stem; goldens of one call that share a stem are named by their path
below the deepest folder they share, '/' -> '__' (a/x.mcap and b/x.mcap: a__x and b__x). A
golden's files are written under hidden temporary names in DIR (`.NAME.partial.mcap`) and renamed
into place when all of them are done; an error, a match or Ctrl-C removes them."""

from __future__ import annotations

import os
import shutil
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from twin.model.errors import ConfigError, OutputError
from twin.record.outputs import partial_path, publish

# what each kind of golden may leave in DIR, by suffix
SUFFIXES = {
    "recording": (".mcap", ".md", ".rrd"),
    "sweep": (".md", ".summary.json", ".results.parquet"),
    "search": (".mcap", ".md"),
}
KEPT = ("differ", "refused")  # the statuses whose files are kept


def keep_names(paths: list[str]) -> dict[str, str]:
    """Each golden's NAME in the --keep folder: its stem, or, for goldens sharing one, the path
    below the deepest folder they share without its suffix, '/' -> '__'. ConfigError if two are
    still one name (x.mcap and x.toml in one folder)."""
    by_stem: dict[str, list[str]] = defaultdict(list)
    for p in paths:
        by_stem[Path(p).stem].append(p)
    names = {}
    for stem, group in by_stem.items():
        if len(group) == 1:
            names[group[0]] = stem
            continue
        absolute = [os.path.abspath(p) for p in group]
        shared = os.path.commonpath([os.path.dirname(a) for a in absolute])
        for p, a in zip(group, absolute, strict=True):
            below = Path(os.path.relpath(a, shared))
            names[p] = "__".join([*below.parent.parts, below.stem])
    seen: dict[str, str] = {}
    for p, name in names.items():
        if name in seen:
            raise ConfigError(
                f"--keep would name the files of {seen[name]!r} and {p!r} alike ({name!r}); "
                "expected goldens that differ in name or folder (check them in two calls)"
            )
        seen[name] = p
    return names


def plan_keep(folder: str, goldens, *, force: bool) -> dict[str, str]:
    """DIR/NAME for each golden (goldens: verify.check.Goldens), checked before any work: DIR is a
    folder or can be made in an existing one, the check does not walk it (what it keeps would be
    goldens next time), and no file --keep may write exists (unless force) or is a golden's. Makes
    DIR. A one-line ConfigError otherwise."""
    target = Path(folder)
    if target.exists() and not target.is_dir():
        raise ConfigError(f"--keep {folder!r} is a file; expected a folder (made if missing)")
    if not target.exists() and not target.parent.is_dir():
        raise ConfigError(
            f"--keep {folder!r}: its folder {str(target.parent)!r} does not exist; create it first"
        )
    for walked in goldens.folders:
        if _walks_into(Path(walked), target):
            raise ConfigError(
                f"--keep {folder!r} lies in {walked!r}, which is checked: what it keeps would be "
                "checked as goldens next time; expected a folder outside it (or a hidden one)"
            )
    kinds = {p: "recording" for p in goldens.recordings}
    kinds |= {p: "sweep" for p in goldens.sweeps} | {p: "search" for p in goldens.searches}
    names = keep_names(list(kinds))
    inputs = _inputs(goldens)
    for p, name in names.items():
        for suffix in SUFFIXES[kinds[p]]:
            path = target / (name + suffix)
            if not os.path.lexists(path):
                continue
            if _identity(path) in inputs:
                raise ConfigError(
                    f"--keep would write {str(path)!r}, which is a golden's file; expected "
                    "another folder"
                )
            if not force:
                raise ConfigError(
                    f"--keep would replace {str(path)!r}; --force replaces files in the --keep "
                    "folder"
                )
    try:
        target.mkdir(exist_ok=True)
    except OSError as err:
        raise OutputError(f"cannot create --keep {folder!r}: {err.strerror or err}") from err
    return {p: os.path.abspath(target / name) for p, name in names.items()}


def _walks_into(walked: Path, target: Path) -> bool:
    """Whether a check of the folder walked reaches target (hidden folders are skipped)."""
    try:
        below = target.resolve().relative_to(walked.resolve())
    except ValueError:
        return False
    return not any(part.startswith(".") for part in below.parts)


def _inputs(goldens) -> set[tuple[int, int]]:
    """The (device, inode) of every file of the goldens: the recordings, a sweep's definition,
    summary and results, a search golden's definition, expectation and recording."""
    files = list(goldens.recordings)
    for p in goldens.sweeps:
        stem = Path(p).with_suffix("")
        files += [p, f"{stem}.summary.json", f"{stem}.results.parquet"]
    for p in goldens.searches:
        stem = Path(p).with_suffix("")
        files += [p, f"{stem}.expect.json", f"{stem}.mcap"]
    return {_identity(f) for f in files if os.path.exists(f)}


def _identity(path: str | os.PathLike) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


class Staged:
    """One golden's kept files: written under hidden temporary names beside their places
    (`DIR/.NAME.partial.SUFFIX`), renamed into place together by publish; discard removes what was
    not published."""

    def __init__(self, base: str) -> None:
        self.base = Path(base)
        self.temps: dict[str, Path] = {}

    def temp(self, suffix: str) -> Path:
        """Where the file DIR/NAME+suffix is written until publish."""
        path = self.base.with_name(f".{self.base.name}.partial{suffix}")
        self.temps[suffix] = path
        return path

    def write_text(self, suffix: str, text: str) -> None:
        try:
            self.temp(suffix).write_text(text)
        except OSError as err:
            raise OutputError(f"cannot write {str(self.temp(suffix))!r}: {err.strerror}") from err

    def publish(self) -> list[str]:
        """Rename every file into place (OutputError if one cannot be); their final paths."""
        done = []
        for suffix, path in list(self.temps.items()):
            final = self.base.with_name(self.base.name + suffix)
            publish(path, final)
            del self.temps[suffix]
            done.append(str(final))
        return done

    def discard(self) -> None:
        for path in self.temps.values():
            path.unlink(missing_ok=True)
            partial_path(path).unlink(missing_ok=True)  # a writer stopped before its rename
        self.temps.clear()


@contextmanager
def staging(base: str | None) -> Iterator[Staged | None]:
    """A Staged for DIR/NAME (None without --keep) whose unpublished files are removed at the end,
    however it comes (an error, a match, Ctrl-C)."""
    if base is None:
        yield None
        return
    staged = Staged(base)
    try:
        yield staged
    finally:
        staged.discard()


def keep_recording(staged: Staged, golden, candidate, result, recorded: Path) -> list[str]:
    """An .mcap golden's files: the re-run recorded (copied when it was recorded elsewhere, beside
    the golden for --update), the Markdown report and the diff view."""
    from twin.compare.report import write_report
    from twin.verify.diff_view import write_diff_rrd

    mcap = staged.temp(".mcap")
    if recorded != mcap:
        try:
            shutil.copyfile(recorded, mcap)
        except OSError as err:
            raise OutputError(f"cannot write {str(mcap)!r}: {err.strerror or err}") from err
    # the report names the candidate by the file kept beside it, not "<memory>"
    result.candidate = {**result.candidate, "path": f"{Path(staged.base).name}.mcap"}
    write_report(result, staged.temp(".md"))
    write_diff_rrd(golden, candidate, result, staged.temp(".rrd"))
    return staged.publish()


def outcome_markdown(outcome, title: str) -> str:
    """A sweep's or search golden's report as Markdown: the verdict line, then the report."""
    return (
        f"# {title}: {outcome.status}\n\n"
        f"`{outcome.path}`: {outcome.summary}\n\n"
        f"```text\n{outcome.report.rstrip()}\n```\n"
    )
