"""The docs' benchmarks page, rendered from `tools/bench.py --json` output (docs/benchmarks.json).

`python tools/docs_benchmarks.py [FILE.json]` prints the page's table; mkdocs renders it into
docs/explanation/benchmarks.md at the `<!-- benchmarks-table -->` marker (tools/mkdocs_hooks.py).
To refresh the figures: `python tools/bench.py --json docs/benchmarks.json` on a quiet machine.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

DEFAULT = Path(__file__).resolve().parents[1] / "docs" / "benchmarks.json"
MARKER = "<!-- benchmarks-table -->"


class BenchmarksError(ValueError):
    """docs/benchmarks.json is missing a part the page shows."""


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|")


def render(doc: dict) -> str:
    """The run's date, machine and command, then its table, section by section."""
    run = doc.get("run")
    rows = doc.get("rows")
    if not isinstance(run, dict) or not isinstance(rows, list) or not rows:
        raise BenchmarksError(
            "benchmarks JSON needs 'run' (date, machine) and 'rows': "
            "make it with tools/bench.py --json"
        )
    machine = run["machine"]
    load = run.get("load_average", {})
    lines = [
        f"Measured on **{run['date'][:10]}** ({run['date']}) with `{run['command']}`.",
        "",
        "| machine | |",
        "|---|---|",
        f"| CPU | {_cell(machine['cpu'])} |",
        f"| cores | {machine['cpus']} |",
        f"| kernel | {_cell(machine['kernel'])} |",
        f"| Python / PyBullet API | {machine['python']} / {machine['pybullet']} |",
    ]
    if load:
        before = ", ".join(f"{x:.2f}" for x in load["before"])
        after = ", ".join(f"{x:.2f}" for x in load["after"])
        lines.append(f"| load average (1, 5, 15 min) | before {before}; after {after} |")
    lines += ["", "| section | measure | value |", "|---|---|---|"]
    lines += [
        f"| {_cell(r['section'])} | {_cell(r['measure'])} | {_cell(r['value'])} |" for r in rows
    ]
    return "\n".join(lines) + "\n"


def render_into(page: str, doc: dict) -> str:
    """The page with its marker replaced by the rendered table."""
    if MARKER not in page:
        raise BenchmarksError(f"the benchmarks page has no {MARKER} marker")
    return page.replace(MARKER, render(doc))


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0]) if args else DEFAULT
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        sys.stdout.write(render(doc))
    except (OSError, ValueError, KeyError) as err:
        print(f"docs_benchmarks: error: {path}: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
