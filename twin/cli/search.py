"""The `twin search` command: argument parsing, progress and printing only (the run and its files
are twin.search.folder, the rounds twin.search.search, a saved failure twin.search.golden)."""

from __future__ import annotations

import argparse
import sys

from twin.cli.args import add_executor_options, add_param_option, params_dict, whole_number


def fraction(text: str) -> float:
    """An argparse type: a precision as a fraction of a key's half-width, 0 < p < 1."""
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(
            f"--precision {text!r} is invalid; expected a fraction of the "
            "half-width, 0 < p < 1 (e.g. 0.01)"
        )
    return value


def add_search_command(sub) -> None:
    p = sub.add_parser(
        "search",
        help="search for the smallest perturbation that breaks a task, and the "
        "boundary along each key",
        description="Seeded and deterministic: the same results on any job count or executor. "
        "Size of a scenario: the sum over keys of |value - nominal| / half-width. "
        "Writes DIR/search.json and DIR/minimal.mcap (the smallest failure's "
        "recording). Exit 0 done (a failure found or not), 2 bad input, 130 Ctrl-C "
        "(what was found is written).",
    )
    p.add_argument("task", help="a built-in task or path/to/task.py")
    p.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="KEY=LOW..HIGH",
        required=True,
        help="a searched key and its range around the nominal value (repeatable); keys as for "
        "twin sweep (box.x_m, pad.max_pull_force_n, robot.revolute_max_velocity_rad_s, "
        "task.<float parameter>, ...)",
    )
    add_param_option(p)
    p.add_argument(
        "--robot", default="mtb", help="profile: mtb (default), seed000..seed003, or a profile file"
    )
    p.add_argument("--rate-hz", type=float, default=240.0, help="physics rate (default 240 Hz)")
    p.add_argument(
        "--timeout",
        type=float,
        default=None,
        metavar="SECONDS",
        help="a run whose task passes this much simulated time fails",
    )
    p.add_argument(
        "--seed",
        type=whole_number(0),
        default=0,
        metavar="S",
        help="the exploration's seed (default 0)",
    )
    p.add_argument(
        "--budget", type=whole_number(1), required=True, metavar="N", help="at most N runs"
    )
    p.add_argument(
        "--precision",
        type=fraction,
        default=0.01,
        metavar="P",
        help="boundaries and shrinking to P times each key's half-width (default 0.01)",
    )
    add_executor_options(p)
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="the output folder (created; its parent must exist, or be runs/, which is made)",
    )
    p.add_argument(
        "--save-golden",
        default=None,
        metavar="NAME",
        help="keep the smallest failure as a test: recordings/search/NAME.toml (the scenario), "
        "NAME.mcap (its recording) and NAME.expect.json; `twin check` then runs it",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="write into an --out folder that is not empty and over an existing --save-golden "
        "NAME's files (without it either is refused before any work)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    p.set_defaults(func=cmd_search, interrupt=True)  # Ctrl-C even as a background job


def cmd_search(args: argparse.Namespace) -> int:
    from twin.jobs.executors import make_executor
    from twin.search import folder
    from twin.search.golden import check_name
    from twin.search.search import prepare_search
    from twin.sweep.spec import SweepSpec, parse_vary

    spec = SweepSpec(
        task=args.task,
        scenarios=1,
        robot=args.robot,
        seed=args.seed,
        vary=parse_vary(args.vary),
        params=params_dict(args.param),
        rate_hz=args.rate_hz,
        timeout_s=args.timeout,
    )
    # every key, range and parameter, before anything runs
    _, ranges = prepare_search(spec, args.precision)
    if args.save_golden is not None:
        check_name(args.save_golden)
        if not args.force:
            folder.refuse_golden(args.save_golden)
    out = folder.prepare_folder(args.out, force=args.force)
    executor = make_executor(
        args.executor, args.jobs, args.scheduler, preload=("twin.search.search",)
    )
    try:
        done = folder.run(
            spec,
            ranges,
            executor,
            args.budget,
            out=out,
            save_as=args.save_golden,
            progress=None if args.quiet else _progress,
        )
    finally:
        executor.close()
    for line in summary_lines(done.data, executor, done.wall_s):
        print(line)
    print("wrote " + ", ".join(str(p) for p in done.wrote))
    if done.stopped_by is not None and done.result.minimal is not None:
        print(
            f"not recorded: {out / folder.MINIMAL}"
            + (" and the --save-golden files" if args.save_golden else "")
            + " (the search was interrupted; search.json holds the smallest failure so far)"
        )
    if done.stopped_by is not None:
        raise done.stopped_by  # 130 (Ctrl-C) or 128 + the signal, after search.json is written
    return 0


def _progress(phase: str, result) -> None:
    print(
        f"search: {phase}: {result.runs}/{result.budget} runs, {len(result.failures)} failing",
        file=sys.stderr,
        flush=True,
    )


def summary_lines(data: dict, executor, wall_s: float) -> list[str]:
    left = data["budget"] - data["runs"]
    budget = (
        f" (budget: the next round needs more than the {left} run{'s' * (left != 1)} left)"
        if left > 0
        else " (budget spent)"
    )
    stopped = {"budget": budget, "interrupted": " (interrupted)"}.get(data["stopped"], "")
    head = (
        f"search {data['task']} on {data['robot']}: {data['runs']} runs of "
        f"{data['budget']}{stopped}, "
        f"seed {data['seed']}, {executor.jobs} jobs ({executor.name}), wall {wall_s:.1f} s"
    )
    lines = [head]
    nominal = data["nominal"]
    if nominal is not None and nominal["outcome"] != "ok":
        lines.append(f"the nominal scene fails: {nominal['reason']}")
    minimal = data["minimal"]
    if minimal is None:
        lines.append("no failure found within the ranges")
    else:
        keys = data["keys"]
        moved = [
            f"{name} = {v:.6g} ({_offset(v, keys[name])})"
            for name, v in minimal["values"].items()
            if v != keys[name]["nominal"]
        ] or ["the nominal values"]
        lines.append(f"smallest failure (size {minimal['size']:.4f}, {data['size']}):")
        lines.append("  " + ", ".join(moved))
        lines.append(f"  reason: {minimal['reason']}")
    lines.append("boundary along each key (the others nominal):")
    for name, b in data["boundary"].items():
        if b is None:
            lines.append(f"  {name}: not searched")
        elif b["failing"] is None:
            lines.append(
                f"  {name}: passes over the whole range {data['keys'][name]['low']:.6g}.."
                f"{data['keys'][name]['high']:.6g}"
            )
        else:
            note = "" if b["converged"] else " (not converged)"
            lines.append(
                f"  {name}: passes at {b['passing']:.6g}, fails at {b['failing']:.6g} "
                f"({b['side']} side; precision {b['precision']:.3g}){note}"
            )
    return lines


def _offset(value: float, key: dict) -> str:
    offset = value - key["nominal"]
    return f"nominal {offset:+.4g}, {abs(offset) / key['half_width']:.3f} of the half-width"
