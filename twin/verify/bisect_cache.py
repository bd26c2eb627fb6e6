"""The verdict cache of `twin bisect`: one JSON file per (commit, golden, verdict options) in
`.twin-bisect/` at the repository's root, which a `.gitignore` of `*` keeps out of `git status`.

A verdict is kept only when the tried commit's `twin check` finished (match, differ, or error on
that golden, such as a task file that fails to import): a commit whose check did not run at all (its
code does not import, a crash, Ctrl-C) is tried again next time, since that may be the machine's
doing, not the commit's.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from twin.record.outputs import write_atomic

CACHE_DIR = ".twin-bisect"


def golden_sha256(files: list[Path]) -> str:
    """The content of a golden: its file and the companions checked with it (a sweep golden's
    NAME.summary.json, a search golden's NAME.expect.json), by name and bytes."""
    h = hashlib.sha256()
    for f in sorted(files, key=lambda p: p.name):
        h.update(f.name.encode() + b"\0")
        h.update(hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


class VerdictCache:
    """Verdicts by key; the folder is made (with its .gitignore) on the first write."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.dir = Path(root) / CACHE_DIR

    @staticmethod
    def key(commit: str, golden: str, content_sha256: str, options: dict) -> str:
        """The key of one verdict: the commit's hash, the golden's path in the repository (its task
        is resolved from there), its content's sha256, and the verdict options."""
        text = json.dumps(
            {"commit": commit, "golden": golden, "sha256": content_sha256, "options": options},
            sort_keys=True,
        )
        return hashlib.sha256(text.encode()).hexdigest()

    def get(self, key: str) -> dict | None:
        try:
            data = json.loads((self.dir / f"{key}.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):  # missing, or a torn or foreign file: tried anew
            return None
        return data if isinstance(data, dict) and "status" in data else None

    def put(self, key: str, verdict: dict) -> None:
        self.dir.mkdir(exist_ok=True)
        ignore = self.dir / ".gitignore"
        if not ignore.exists():
            ignore.write_text("*\n", encoding="utf-8")
        write_atomic(self.dir / f"{key}.json", json.dumps(verdict, sort_keys=True) + "\n")
