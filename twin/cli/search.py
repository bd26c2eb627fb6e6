"""The `twin search` command: argument parsing, progress and printing only (the work is
twin.sweep.search; a saved failure is twin.sweep.search_golden)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from twin.cli.args import add_executor_options, add_param_option, params_dict, whole_number
from twin.model.errors import ConfigError
from twin.signals import Terminated

RESULT, MINIMAL = "search.json", "minimal.mcap"


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
    p.set_defaults(func=cmd_search)


def cmd_search(args: argparse.Namespace) -> int:
    from twin.sweep.executors import make_executor
    from twin.sweep.search import Search, prepare_search
    from twin.sweep.search_golden import check_name
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
    _, ranges = prepare_search(
        spec, args.precision
    )  # every key, range and parameter, before anything runs
    if args.save_golden is not None:
        check_name(args.save_golden)
        if not args.force:
            _refuse_golden(args.save_golden)
    out = _out_dir(args.out, force=args.force)
    executor = make_executor(args.executor, args.jobs, args.scheduler)
    search = Search(spec, ranges, executor, args.budget, progress=None if args.quiet else _progress)
    t0 = time.perf_counter()
    try:
        result = search.run()
    except (KeyboardInterrupt, Terminated):
        _finish(search.result, out, args, time.perf_counter() - t0, executor, record=False)
        raise
    finally:
        executor.close()
    _finish(result, out, args, time.perf_counter() - t0, executor, record=True)
    return 0


def _progress(phase: str, result) -> None:
    print(
        f"search: {phase}: {result.runs}/{result.budget} runs, {len(result.failures)} failing",
        file=sys.stderr,
        flush=True,
    )


def _finish(
    result, out: Path, args: argparse.Namespace, wall_s: float, executor, *, record: bool
) -> None:
    """Write search.json (and, unless interrupted, the smallest failure's recording and golden);
    print the summary."""
    from twin.record.outputs import write_atomic
    from twin.sweep.search import probe_spec, result_json
    from twin.sweep.search_golden import record_scenario, save_golden

    data = result_json(result)
    write_atomic(out / RESULT, json.dumps(data, indent=2, allow_nan=False) + "\n")
    minimal = result.minimal
    wrote = [out / RESULT]
    if record and minimal is not None:
        spec = probe_spec(result.spec, [r.name for r in result.ranges], minimal.values)
        record_scenario(spec, out / MINIMAL)
        wrote.append(out / MINIMAL)
        if args.save_golden:
            wrote += save_golden(
                args.save_golden,
                spec,
                minimal.outcome,
                minimal.error,
                {k: data[k] for k in ("keys", "size", "minimal", "boundary", "runs")},
            )
    for line in summary_lines(data, executor, wall_s):
        print(line)
    print("wrote " + ", ".join(str(p) for p in wrote))
    if not record and minimal is not None:
        print(
            f"not recorded: {out / MINIMAL}"
            + (" and the --save-golden files" if args.save_golden else "")
            + " (the search was interrupted; search.json holds the smallest failure so far)"
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


def _refuse_golden(name: str) -> None:
    """--save-golden NAME refused (exit 2) when any of its three files exists, before any work."""
    from twin.model.golden_files import expect_path
    from twin.record.outputs import refuse_existing
    from twin.sweep.search_golden import SEARCH_DIR

    definition = SEARCH_DIR / f"{name}.toml"
    for path in (definition, definition.with_suffix(".mcap"), expect_path(definition)):
        refuse_existing(path, f"--save-golden {name}:")


def _out_dir(path: str, *, force: bool) -> Path:
    from twin.record.outputs import make_default_folder, refuse_existing

    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {path!r} is a file; expected a folder")
    if not force:
        refuse_existing(out, "--out", folder=True)
    if not make_default_folder(out.parent):
        raise ConfigError(f"--out {path!r}: folder {str(out.parent)!r} does not exist")
    try:
        out.mkdir(exist_ok=True)
        (out / MINIMAL).unlink(missing_ok=True)  # an earlier search's failure is not this one's
    except OSError as err:
        raise ConfigError(f"--out {path!r}: {err.strerror or err}") from err
    return out
