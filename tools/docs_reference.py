"""Reference pages generated from the code, so they cannot drift from it.

`python tools/docs_reference.py cli` prints the CLI reference (every `twin` command, from the
argparse parsers in twin/cli), `tolerances` the tolerance presets table (twin.compare.tolerances).
mkdocs builds them through tools/mkdocs_hooks.py; nothing generated is kept in docs/.
"""

from __future__ import annotations

import argparse
import math
import sys


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:  # argparse keeps its subparsers only here
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _helps(parser: argparse.ArgumentParser) -> dict[str, str]:
    """Each subcommand's one-line help, as `twin --help` lists it."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return {a.dest: a.help or "" for a in action._choices_actions}
    return {}


def _option_row(action: argparse.Action) -> str:
    value = (
        f" {action.metavar or action.dest.upper()}"
        if action.option_strings and action.nargs != 0
        else ""
    )
    names = ", ".join(f"`{s}{value}`" for s in action.option_strings) or f"`{action.dest}`"
    text = (action.help or "—").replace("|", "\\|").replace("\n", " ")
    if action.choices and not isinstance(action, argparse._SubParsersAction):
        text += " (one of: " + ", ".join(f"`{c}`" for c in action.choices) + ")"
    return f"| {names} | {text} |"


def _usage(parser: argparse.ArgumentParser) -> str:
    formatter = argparse.HelpFormatter(parser.prog, width=96)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups, prefix="")
    return formatter.format_help().strip()


def cli_markdown() -> str:
    """The whole CLI reference as Markdown."""
    from twin.cli.main import build_parser

    root = build_parser()
    lines = [
        "# CLI reference",
        "",
        (
            "Generated from the argparse parsers in `twin/cli/` when the site is built "
            "(`tools/docs_reference.py`), so it always matches `twin COMMAND --help`. "
            "Exit codes are on [their own page](exit-codes.md)."
        ),
        "",
    ]
    helps = _helps(root)
    lines += ["| command | what |", "|---|---|"]
    lines += [
        f"| [`twin {name}`](#twin-{name}) | {helps.get(name, '')} |" for name in _subcommands(root)
    ]
    commands = {}
    for name, sub in _subcommands(root).items():
        commands[name] = sub
        for word, extra in getattr(sub, "extra_commands", {}).items():  # twin sweep compare, plot
            commands[f"{name} {word}"] = extra
    for name, sub in commands.items():
        lines += ["", f"## twin {name}", "", helps.get(name, ""), ""]
        if sub.description:
            lines += [sub.description, ""]
        lines += ["```text", _usage(sub), "```", ""]
        actions = [a for a in sub._actions if not isinstance(a, argparse._HelpAction)]
        positional = [a for a in actions if not a.option_strings]
        optional = [a for a in actions if a.option_strings]
        for title, group in (("argument", positional), ("option", optional)):
            if group:
                lines += [f"| {title} | what |", "|---|---|", *(_option_row(a) for a in group), ""]
    return "\n".join(lines) + "\n"


def _tolerance(value: float) -> str:
    if math.isinf(value):
        return "off"
    return "0" if value == 0 else f"{value:g}"


def tolerances_markdown() -> str:
    """The presets as one table: each field's unit, meaning and tolerance under every preset."""
    from twin.compare.tolerances import DEFAULT, FIELDS, NOISE_MARGINS, PRESETS

    names = list(PRESETS)
    lines = ["| field | unit | " + " | ".join(f"`{n}`" for n in names) + " |",
             "|---|---|" + "---|" * len(names)]
    for field, (unit, _) in FIELDS.items():
        cells = [_tolerance(PRESETS[n][0].get(field, 0.0)) for n in names]
        unit = unit.replace("|", " / ") or "—"
        lines.append(f"| `{field}` | {unit} | " + " | ".join(cells) + " |")
    windows = ["not paired" if PRESETS[n][1] is None else str(PRESETS[n][1]) for n in names]
    lines.append(
        "| event window | steps | how far apart a pair of events may be | "
        + " | ".join(windows)
        + " |"
    )
    margins = ", ".join(
        f"`{n}` allows each field {m:g} times the measured noise floor as well"
        for n, m in NOISE_MARGINS.items()
    )
    lines += ["", "| field | what |", "|---|---|"]
    lines += [f"| `{field}` | {what.replace('|', '/')} |" for field, (_, what) in FIELDS.items()]
    lines += ["| event window | how far apart, in steps, a pair of events may be |"]
    lines += [
        "",
        (
            f"The default is `{DEFAULT}`; {margins} "
            "(see [determinism](../explanation/determinism.md))."
        ),
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="docs_reference", description=__doc__.splitlines()[0])
    parser.add_argument("page", choices=("cli", "tolerances"))
    args = parser.parse_args(argv)
    sys.stdout.write(cli_markdown() if args.page == "cli" else tolerances_markdown())
    return 0


if __name__ == "__main__":
    sys.exit(main())
