"""`twin sweep compare` and `twin sweep plot`: argument parsing and printing only (the work is
twin.sweep.compare and twin.sweep.plot). Their files are checked before any work: an existing one is
replaced only with --force, whole."""

from __future__ import annotations

import argparse
from pathlib import Path

from twin.cli.record import add_force_option
from twin.model.errors import ConfigError, TwinError
from twin.record.outputs import check_output


class Worse(TwinError):
    """--fail-if-worse: B is worse than A beyond sampling noise."""

    exit_code = 1


def add_subcommands(p: argparse.ArgumentParser) -> None:
    """`twin sweep compare` and `twin sweep plot`: parsers of their own, chosen by the first word
    after `sweep` (`twin sweep TASK` takes any other first word as the task)."""
    kind = type(p)  # twin's parser class: one-line usage errors, exit 2
    extra = {"compare": _compare_parser(kind, p.prog), "plot": _plot_parser(kind, p.prog)}
    parse_run = p.parse_known_args

    def parse_known_args(args=None, namespace=None):
        if args and args[0] in extra:
            return extra[args[0]].parse_known_args(args[1:], namespace)
        return parse_run(args, namespace)

    p.parse_known_args = parse_known_args
    p.extra_commands = extra  # for the generated CLI reference (tools/docs_reference.py)


def _compare_parser(kind, prog: str) -> argparse.ArgumentParser:
    compare = kind(
        prog=f"{prog} compare",
        description="Compare two sweeps: B (new) against A (reference). The same "
        "scenarios (same seed and varied keys): paired, scenario by "
        "scenario (flips, Newcombe's paired interval, McNemar's exact "
        "test, the paired shift of the placement error, the smallest drop "
        "in success rate it detects at 80 % power); else Newcombe's "
        "unpaired interval. Exit 0, 1 under --fail-if-worse when B is "
        "worse, 2 bad input.",
    )
    compare.add_argument(
        "a",
        metavar="A",
        help="the reference: a result folder (twin sweep "
        "--out) or a golden NAME.toml with NAME.results.parquet",
    )
    compare.add_argument(
        "b", metavar="B", help="the new run: a result folder or a golden NAME.toml"
    )
    compare.add_argument(
        "--report",
        default=None,
        metavar="FILE",
        help="also write the report: Markdown (.md) or JSON (.json)",
    )
    compare.add_argument(
        "--fail-if-worse",
        action="store_true",
        help="exit 1 when B is worse beyond sampling noise: a significant "
        "drop in success rate (paired: McNemar p < 0.05; unpaired: "
        "Newcombe's interval below 0) or in placement error",
    )
    compare.add_argument(
        "--plot",
        default=None,
        metavar="FILE.png",
        help="also write a picture with the flips ringed (needs matplotlib)",
    )
    compare.add_argument(
        "--html",
        default=None,
        metavar="FILE.html",
        help="also write a self-contained HTML report: the flips, the paired interval and p, the "
        "success map (with matplotlib)",
    )
    add_force_option(compare, "the --report, --plot or --html file")
    compare.set_defaults(func=cmd_compare, interrupt=True)  # Ctrl-C even as a background job
    return compare


def _plot_parser(kind, prog: str) -> argparse.ArgumentParser:
    plot = kind(
        prog=f"{prog} plot",
        description="Draw a sweep: each scenario over the two "
        "varied keys that matter most, and the placement error.",
    )
    plot.add_argument(
        "dir",
        metavar="DIR",
        help="a result folder, or a golden NAME.toml with NAME.results.parquet",
    )
    plot.add_argument(
        "--out",
        default=None,
        metavar="FILE.png",
        help="the picture (default DIR/sweep.png; NAME.png for a golden)",
    )
    add_force_option(plot, "the picture")
    plot.set_defaults(func=cmd_plot, interrupt=True)  # Ctrl-C even as a background job
    return plot


def cmd_compare(args: argparse.Namespace) -> int:
    from twin.sweep.compare import compare, load_run, write_report

    inputs, force = [args.a, args.b], args.force
    if args.report:
        if not args.report.endswith((".md", ".json")):
            raise ConfigError(
                f"--report {args.report!r} is invalid; expected a file ending in .md or .json"
            )
        check_output(
            args.report, Path(args.report).suffix, inputs=inputs, option="--report", force=force
        )
    if args.plot:
        check_output(args.plot, ".png", inputs=inputs, option="--plot", force=force)
    if args.html:
        check_output(args.html, ".html", inputs=inputs, option="--html", force=force)
    if args.plot:
        plot_target(args.plot)  # matplotlib there (its import takes a while: after the paths)
    a, b = load_run(args.a), load_run(args.b)
    result = compare(a, b)
    print(result.text(), end="")
    if args.report:
        write_report(result, args.report)
        print(f"wrote {args.report}")
    if args.plot:
        from twin.sweep.plot import plot_sweep

        paired = result.result if result.is_paired else None
        plot_sweep(b.side, args.plot, f"{b.label} against {a.label}", paired, a.side)
        print(f"wrote {args.plot}")
    if args.html:
        from twin.sweep.html import write_compare_page

        write_compare_page(result, args.html)
        print(f"wrote {args.html}")
    if args.fail_if_worse and result.problems:
        raise Worse(f"{b.label} is worse than {a.label}: " + "; ".join(result.problems))
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from twin.sweep.compare import load_run

    out = args.out
    if out is None:
        path = Path(args.dir)
        out = str(path / "sweep.png") if path.is_dir() else path.stem + ".png"
    check_output(out, ".png", inputs=[args.dir], option="--out", force=args.force)
    plot_target(out)
    run = load_run(args.dir)
    plot_run(run.side, out, run.spec, run.label)
    return 0


def plot_target(path: str) -> None:
    """matplotlib importable and the picture a .png, checked before any work."""
    from twin.sweep.plot import pyplot

    if not path.endswith(".png"):
        raise ConfigError(f"plot {path!r} is invalid; expected a file ending in .png")
    pyplot()


def plot_run(side, out: str, spec, label: str) -> None:
    """A sweep's picture written to `out`, and the line that says so."""
    from twin.sweep.plot import plot_sweep

    n, ok = side.n, int(side.ok.sum())
    title = f"{label}: {spec.task} on {spec.robot}, seed {spec.seed}: {ok}/{n} ok"
    keys = plot_sweep(side, out, title)
    print(f"wrote {out} (axes: {', '.join(keys) or 'scenario'})")
