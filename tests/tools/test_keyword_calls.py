"""A call in twin/ that passes six or more arguments names them: a reordered parameter list cannot
shift values silently. Only calls whose callee takes no keywords are left positional: struct.pack
and a struct.Struct's pack (C functions) and functions that take *args (bisect's git)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
POSITIONAL_ONLY = {"struct.pack", "_HEAD.pack", "git"}  # _HEAD: mcap/batch_writer.py's Struct


def _long_positional_calls(tree: ast.AST) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call) or any(isinstance(a, ast.Starred) for a in node.args):
            continue
        name = ast.unparse(node.func)
        if len(node.args) >= 6 and name not in POSITIONAL_ONLY:
            found.append((node.lineno, name))
    return found


def test_calls_with_six_or_more_arguments_pass_them_by_keyword():
    offenders = [
        f"{path.relative_to(ROOT)}:{line}: {name}"
        for path in sorted((ROOT / "twin").rglob("*.py"))
        for line, name in _long_positional_calls(ast.parse(path.read_text(encoding="utf-8")))
    ]
    assert not offenders, "\n".join(offenders)


def test_the_check_finds_a_long_positional_call():
    assert _long_positional_calls(ast.parse("f(1, 2, 3, 4, 5, 6)")) == [(1, "f")]
    assert _long_positional_calls(ast.parse("f(1, 2, 3, 4, 5, six=6)")) == []
