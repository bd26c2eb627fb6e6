"""The project's lint: `ruff check twin tools tests` is clean, lines at most 100 characters included
(pyproject.toml's [tool.ruff]), and `lint-imports` keeps the layers of
docs/explanation/architecture.md ([tool.importlinter]). A failure prints the tool's own report."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(command: list[str], root: Path = ROOT) -> subprocess.CompletedProcess:
    """command in root, which is first on the path: its twin/ is the one checked."""
    path = os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])
    return subprocess.run(
        command,
        cwd=root,
        env={**os.environ, "PYTHONPATH": path},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_ruff_check_is_clean():
    done = _run([sys.executable, "-m", "ruff", "check", "--no-cache", "twin", "tools", "tests"])
    report = done.stdout + done.stderr
    assert done.returncode == 0, f"ruff check failed (ruff is in the dev extra):\n{report}"


def _lint_imports(root: Path) -> subprocess.CompletedProcess:
    """`lint-imports` (import-linter, in the dev extra) on the pyproject.toml and twin/ of root."""
    command = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    return _run([command, "--no-cache", "--no-logo"], root)


def test_lint_imports_keeps_the_layers():
    done = _lint_imports(ROOT)
    report = done.stdout + done.stderr
    assert done.returncode == 0, f"lint-imports failed (import-linter, a dev extra):\n{report}"
    assert "Contracts: 3 kept, 0 broken." in report


@pytest.mark.parametrize(
    ("package", "imports", "broken"),
    [
        ("model", "twin.cli.main", "twin.model is not allowed to import twin.cli"),
        ("verify", "twin.export", "twin.verify is not allowed to import twin.export"),
        ("helpers", "twin.signals", "twin.helpers is not allowed to import twin.signals"),
        ("record", "twin.sim.world", "twin.record is not allowed to import twin.sim"),
        ("compare", "twin.record.outputs", "twin.compare is not allowed to import twin.record"),
    ],
)
def test_an_import_against_the_architecture_breaks_the_contract(tmp_path, package, imports, broken):
    """A copy of twin/ with one module added that imports what the architecture forbids."""
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    shutil.copytree(ROOT / "twin", tmp_path / "twin", ignore=shutil.ignore_patterns("__pycache__"))
    if (tmp_path / "twin" / package).is_dir():
        (tmp_path / "twin" / package / "against.py").write_text(f"import {imports}\n")
    else:  # a module of its own (twin/helpers.py)
        with (tmp_path / "twin" / f"{package}.py").open("a") as f:
            f.write(f"\nimport {imports}  # noqa: E402\n")
    done = _lint_imports(tmp_path)
    assert done.returncode == 1, done.stdout + done.stderr
    assert broken in done.stdout and "0 kept" not in done.stdout


def test_the_layers_name_every_package_of_twin():
    """A new package of twin/ must take its place in the layers, in the architecture's order."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    [layers] = [c["layers"] for c in config["contracts"] if c["type"] == "layers"]
    rows = [[name.strip() for name in re.split(r"[|:]", layer)] for layer in layers]
    packages = {p.parent.name for p in (ROOT / "twin").glob("*/__init__.py")}
    modules = {p.stem for p in (ROOT / "twin").glob("*.py")} - {"__init__", "__main__"}
    assert sorted(n for row in rows for n in row) == sorted(packages | modules)
    # docs/explanation/architecture.md's table lists them lowest first, a row's together
    table = (ROOT / "docs" / "explanation" / "architecture.md").read_text()
    where = [
        {table.index(f"`twin/{n}/`" if n in packages else f"`twin/{n}.py`") for n in row}
        for row in rows
    ]
    line = [{table.count("\n", 0, i) for i in places} for places in where]
    assert all(len(lines) == 1 for lines in line), "a layer's names are not one row of the table"
    order = [min(places) for places in where]
    assert order == sorted(order, reverse=True), "the layers are not the table's order, reversed"
