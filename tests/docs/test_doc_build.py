"""The documentation site builds with `mkdocs build --strict` (no broken link, no page left out of
the nav, the API pages from docstrings), and its generated pages say what the code and data say."""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))

import docs_benchmarks
import docs_reference

from twin.cli.main import build_parser


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("mkdocs")
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return out


def test_the_site_builds_strict_with_every_page(site):
    for page in (
        "index.html",
        "tutorial/index.html",
        "how-to/ci-goldens/index.html",
        "reference/cli/index.html",
        "reference/python-api/index.html",
        "explanation/benchmarks/index.html",
    ):
        assert (site / page).is_file(), page
    api = (site / "reference" / "python-api" / "index.html").read_text(encoding="utf-8")
    assert "twin.load" in api and "Recording" in api  # mkdocstrings rendered the docstrings


def _section_after(page: str, anchor: str) -> str:
    at = page.index(f'id="{anchor}"')
    following = page.find('class="doc doc-heading"', page.index("</h", at))
    return page[at : following if following > 0 else len(page)]


@pytest.mark.parametrize(
    "page, anchor, sections",
    [
        ("reference/python-api", "twin.load", ("Parameters", "Returns", "Raises")),
        ("reference/task-api", "twin.sim.twin.Twin.move_to", ("Parameters", "Raises")),
        ("reference/task-api", "twin.sim.twin.Twin.settle", ("Parameters", "Returns")),
        ("reference/task-api", "twin.sim.twin.Twin.set_joint_target", ("Parameters", "Raises")),
        ("reference/task-api", "twin.sim.twin.Twin.event", ("Parameters", "Returns", "Raises")),
        ("reference/task-api", "twin.sim.twin.Twin.wait", ("Parameters", "Returns", "Raises")),
    ],
)
def test_the_api_pages_render_the_docstrings_sections(site, page, anchor, sections):
    """The Google-style Args/Returns/Raises of the public API come out as the site's sections."""
    html = (site / page / "index.html").read_text(encoding="utf-8")
    part = _section_after(html, anchor)
    for section in sections:
        assert f'doc-section-title">{section}:<' in part, (anchor, section)


def test_the_cli_reference_names_every_command_and_option(site):
    page = (site / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for name, parser in commands.choices.items():
        assert f'id="twin-{name}"' in page, name
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            for option in action.option_strings:
                assert re.search(f"<code>{re.escape(option)}(</code>| )", page), (name, option)


def test_the_benchmarks_page_shows_the_json_s_machine_date_and_every_row(site):
    doc = json.loads((ROOT / "docs" / "benchmarks.json").read_text(encoding="utf-8"))
    page = (site / "explanation" / "benchmarks" / "index.html").read_text(encoding="utf-8")
    assert doc["run"]["date"][:10] in page and doc["run"]["machine"]["cpu"].split(" (")[0] in page
    assert len(doc["rows"]) > 10
    text = docs_benchmarks.render(doc)
    assert all(row["measure"].replace("|", "\\|") in text for row in doc["rows"])


def test_a_benchmarks_json_without_its_run_is_refused(tmp_path):
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"rows": [{"section": "a", "measure": "b", "value": "c"}]}))
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "docs_benchmarks.py"), str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "'run'" in done.stderr


def test_the_tolerances_table_has_every_preset_and_field():
    from twin.compare.tolerances import FIELDS, PRESETS

    table = docs_reference.tolerances_markdown()
    assert all(f"`{name}`" in table.splitlines()[0] for name in PRESETS)
    assert all(f"| `{name}` |" in table for name in FIELDS)
