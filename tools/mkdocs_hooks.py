"""mkdocs hooks: the pages made from the code and from data at build time, so they cannot drift.

- reference/cli.md: every `twin` command, from the argparse parsers (tools/docs_reference.py);
- reference/tolerances.md: the `<!-- tolerances-table -->` marker becomes the presets table;
- explanation/benchmarks.md: the `<!-- benchmarks-table -->` marker becomes docs/benchmarks.json's
  run (tools/docs_benchmarks.py);
- the nav lists the how-to pages of LATER_HOW_TOS that exist.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

TOOLS = Path(__file__).resolve().parent
sys.path.insert(0, str(TOOLS))

import docs_benchmarks  # tools/ is not a package: on sys.path above
import docs_reference

TOLERANCES_MARKER = "<!-- tolerances-table -->"
# how-to pages written alongside the others: listed in the nav once they exist
LATER_HOW_TOS = {
    "how-to/paired-sweeps.md": "Paired sweeps",
    "how-to/search.md": "Search for what breaks a task",
    "how-to/vision-task.md": "A task that looks (cameras)",
}


def on_config(config):
    how_tos = next(entry["How-to guides"] for entry in config["nav"] if "How-to guides" in entry)
    listed = {path for entry in how_tos for path in entry.values()}
    docs = Path(config["docs_dir"])
    for path, title in LATER_HOW_TOS.items():
        if (docs / path).is_file() and path not in listed:
            how_tos.append({title: path})
    return config


def on_files(files, config):
    from mkdocs.structure.files import File

    files.append(File.generated(config, "reference/cli.md", content=docs_reference.cli_markdown()))
    return files


def on_page_markdown(markdown, page, config, files):
    path = page.file.src_uri
    if path == "reference/tolerances.md":
        return markdown.replace(TOLERANCES_MARKER, docs_reference.tolerances_markdown())
    if path == "explanation/benchmarks.md":
        data = Path(config["docs_dir"]) / "benchmarks.json"
        return docs_benchmarks.render_into(markdown, json.loads(data.read_text(encoding="utf-8")))
    return markdown
