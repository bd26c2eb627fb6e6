"""The `twin sweep` command: argument parsing, progress and printing only (the work is
twin.sweep)."""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

from twin.cli.args import add_executor_options, add_param_option, params_dict, whole_number
from twin.cli.sweep_compare import add_subcommands, plot_run, plot_target
from twin.model.errors import ConfigError, TwinError

# a scenario that gave no result (twin.jobs.guard)
NO_RESULT = ("worker died", "killed: ", "timed out: ")


class BelowThreshold(TwinError):
    """--fail-under: the success rate is below the rate asked for."""

    exit_code = 1


def rate(text: str) -> float:
    """An argparse type: a success rate 0..1 (or a percentage such as 95%)."""
    try:
        value = float(text[:-1]) / 100 if text.endswith("%") else float(text)
    except ValueError:
        value = -1.0
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(
            f"--fail-under {text!r} is invalid; expected a rate 0..1 or a percentage"
        )
    return value


def seconds(text: str) -> float:
    """An argparse type: a wall-clock duration in seconds, finite and >= 0 (0: no limit)."""
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(
            f"--scenario-timeout {text!r} is invalid; expected seconds >= 0 (0: no limit)"
        )
    return value


def only_list(text: str) -> list[int]:
    """An argparse type: scenario indices, e.g. 7 or 3,7,12."""
    try:
        out = [int(t) for t in text.split(",")]
    except ValueError:
        out = [-1]
    if not out or min(out) < 0:
        raise argparse.ArgumentTypeError(
            f"--only {text!r} is invalid; expected scenario numbers such as 7 or 3,7"
        )
    return out


def add_sweep_command(sub) -> None:
    p = sub.add_parser(
        "sweep",
        help="run a task over many seeded scenarios (varied scene, pad, robot, task values) "
        "and report statistics",
        description="Scenario i's values depend only on (--seed, i); its run is the same whatever "
        "the executor or job count. Writes DIR/results.parquet, DIR/summary.json, "
        "DIR/sweep.toml and DIR/failures/scenario-<i>.mcap. Exit 0 done, 1 under "
        "--fail-under, 2 bad input, 130 Ctrl-C (the results so far are written).",
    )
    _add_what_options(p)
    add_executor_options(p, os.cpu_count() or 1, f"default: every core, {os.cpu_count()}")
    p.add_argument(
        "--dashboard",
        action="store_true",
        help="with --executor dask and no --scheduler: serve Dask's dashboard on 127.0.0.1 on "
        "a free "
        "port (its address is printed); without it no HTTP server runs",
    )
    p.add_argument(
        "--batch",
        type=whole_number(1),
        default=None,
        metavar="N",
        help="scenarios per task sent to a worker (default: about 4 tasks per worker, 2 on "
        "Dask; at most 16)",
    )
    _add_output_options(p)
    p.set_defaults(func=cmd_sweep, interrupt=True)  # Ctrl-C even as a background job
    p.epilog = (
        "twin sweep compare A B: two sweeps' results compared (paired when they ran "
        "the same scenarios); twin sweep plot DIR: a sweep's picture. See "
        "`twin sweep compare --help`."
    )
    add_subcommands(p)


def _add_what_options(p: argparse.ArgumentParser) -> None:
    """What a sweep runs: the task or definition, the robot, the scenarios and what varies."""
    p.add_argument("task", help="a built-in task, path/to/task.py, or a sweep definition NAME.toml")
    p.add_argument(
        "--robot", default=None, help="profile: mtb (default), seed000..seed003, or a profile file"
    )
    p.add_argument("--rate-hz", type=float, default=None, help="physics rate (default 240 Hz)")
    p.add_argument(
        "--scenarios", type=whole_number(1), default=None, metavar="N", help="how many scenarios"
    )
    p.add_argument(
        "--seed",
        type=whole_number(0),
        default=None,
        metavar="S",
        help="the sweep's seed (default 0)",
    )
    p.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="KEY=DIST",
        help="a varied value (repeatable): KEY box.x_m, box.y_m, box.yaw_rad, box.mass_kg, "
        "box.friction "
        "(any scene object), pad.<suction field>, robot.revolute_max_velocity_rad_s, "
        "robot.prismatic_max_velocity_m_s, engine.<field>, task.<parameter>; DIST uniform(a,b), "
        "normal(mu,sigma), choice(v1,v2,...) or a value",
    )
    add_param_option(p)
    p.add_argument(
        "--timeout",
        type=float,
        default=None,
        metavar="SECONDS",
        help="a scenario whose task runs past this much simulated time fails",
    )
    p.add_argument(
        "--scenario-timeout",
        type=seconds,
        default=None,
        metavar="S",
        help="a scenario that gives no result within S seconds of wall time (hung without "
        "stepping) is ended and fails with that reason (default: 120 s plus 1 s per simulated "
        "second of the task: its --timeout, else the longest scenario so far; 0: no limit)",
    )


def _add_output_options(p: argparse.ArgumentParser) -> None:
    """Where a sweep writes, what it keeps, and how it ends: --out, --save, --resume, --only,
    --fail-under, --plot, --quiet."""
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="the output folder (created; its parent must exist, or be runs/, which is made)",
    )
    p.add_argument(
        "--save",
        choices=("failures", "all", "none"),
        default="failures",
        help="which scenarios to record as MCAP (default failures: DIR/failures/scenario-<i>.mcap; "
        "all: also DIR/scenarios/scenario-<i>.mcap)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue a sweep that was stopped or killed: run only the scenarios missing from "
        "DIR/journal.jsonl (same definition), then write the results as an uninterrupted sweep",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="write over a folder that is not empty (an earlier sweep's results, summary, "
        "definition and journal are replaced, each file atomically; other files stay); without "
        "it such a folder is refused, and the same sweep's folder continues only with --resume",
    )
    p.add_argument(
        "--only",
        type=only_list,
        default=None,
        metavar="I[,J...]",
        help="re-run only these scenarios (recorded per --save; results.parquet is left alone)",
    )
    p.add_argument(
        "--fail-under",
        type=rate,
        default=None,
        metavar="RATE",
        help="exit 1 when the success rate is below RATE (0..1, or 95%%): a CI gate",
    )
    p.add_argument(
        "--plot",
        action="store_true",
        help="also write DIR/sweep.png: each scenario over the two varied keys "
        "that matter most and the placement error's distribution (needs "
        "matplotlib: twin[plot])",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar; only the summary")


def sweep_spec(args: argparse.Namespace):
    """The definition the arguments ask for: TASK.toml's (with --scenarios/--seed overriding it), or
    one built from --robot, --scenarios, --seed, --vary and --param."""
    from twin.sweep.spec import SweepSpec, load_spec, parse_vary

    if args.task.endswith(".toml"):
        if args.vary or args.param or args.robot or args.rate_hz or args.timeout is not None:
            raise ConfigError(
                f"{args.task} defines the sweep; --vary, --param, --robot, --rate-hz and --timeout "
                "go into the file (only --scenarios and --seed override it)"
            )
        spec = load_spec(args.task)
        overrides = {
            k: v for k, v in (("scenarios", args.scenarios), ("seed", args.seed)) if v is not None
        }
        return SweepSpec(**{**spec.__dict__, **overrides}) if overrides else spec
    if args.scenarios is None:
        raise ConfigError("--scenarios N is missing; expected how many scenarios to run")
    return SweepSpec(
        task=args.task,
        scenarios=args.scenarios,
        robot=args.robot or "mtb",
        seed=args.seed or 0,
        vary=parse_vary(args.vary),
        params=params_dict(args.param),
        rate_hz=args.rate_hz or 240.0,
        timeout_s=args.timeout,
    )


def cmd_sweep(args: argparse.Namespace) -> int:
    from twin.jobs.executors import make_executor
    from twin.sweep import folder
    from twin.sweep.journal import JOURNAL
    from twin.sweep.spec import prepare

    spec = sweep_spec(args)
    prepare(spec)  # every key, distribution and parameter checked before anything runs
    if args.plot:
        if args.only is not None:
            raise ConfigError("--plot draws a whole sweep; expected it without --only")
        plot_target("sweep.png")  # matplotlib is there, before anything runs
    the_plan = folder.plan(
        spec, args.out, only=args.only, resume=args.resume, force=args.force
    )
    out = the_plan.out
    if the_plan.resumed:
        print(
            f"resuming: {the_plan.resumed} of {spec.scenarios} scenarios are in {out / JOURNAL}",
            file=sys.stderr,
        )
    jobs = max(1, min(args.jobs, the_plan.count)) if args.executor == "local" else args.jobs
    executor = make_executor(
        args.executor,
        jobs,
        args.scheduler,
        dashboard=args.dashboard,
        preload=("twin.sweep.worker",),
    )
    if getattr(executor, "dashboard_url", None):
        print(f"Dask dashboard: {executor.dashboard_url}", file=sys.stderr)
    progress = Progress(the_plan.count, quiet=args.quiet)
    try:
        done = folder.run(
            spec,
            the_plan,
            executor,
            save=args.save,
            batch_size_n=args.batch,
            scenario_timeout_s=args.scenario_timeout,
            on_row=progress,
        )
    finally:
        progress.close()
        executor.close()
    summary = folder.finish(spec, the_plan, done)
    _print_outcome(args=args, spec=spec, summary=summary, done=done, executor=executor, out=out)
    if done.stopped_by is not None:
        print(
            f"stopped part-way: `twin sweep {out / 'sweep.toml'} --out {out} --resume` "
            f"runs the rest",
            file=sys.stderr,
        )
        # 130 (Ctrl-C) or 128 + the signal, after the results so far are written
        raise done.stopped_by
    rate_now = summary["success_rate"] if summary is not None else None
    if rate_now is not None and args.fail_under is not None and rate_now < args.fail_under:
        raise BelowThreshold(
            f"success rate {rate_now:.4f} is under --fail-under {args.fail_under:g}"
        )
    return 0


def _print_outcome(args, spec, summary: dict | None, done, executor, out: Path) -> None:
    """What a sweep prints when it ends: --only's scenarios, or the summary and the files."""
    if summary is None:
        _print_only(done.rows, out, args.save)
        return
    for line in summary_lines(
        spec=spec,
        summary=summary,
        done=done,
        executor=executor,
        out=out,
        save=args.save,
    ):
        print(line)
    print(f"wrote {out / 'results.parquet'}, {out / 'summary.json'}, {out / 'sweep.toml'}")
    if args.plot and done.rows:
        from twin.sweep.paired import read_side

        plot_run(
            read_side(out / "results.parquet", str(out)), str(out / "sweep.png"), spec, str(out)
        )


def _print_only(rows: list[dict], out: Path, save: str) -> None:
    from twin.sweep.worker import FAILURES, SCENARIOS, scenario_path

    for r in rows:
        placed = (
            ""
            if r["placement_error_mm"] is None
            else f", placement error {r['placement_error_mm']:.2f} mm"
        )
        print(
            f"scenario {r['scenario']}: "
            f"{r['outcome']}{': ' + r['error'] if r['error'] else ''}{placed}"
        )
        folder = (
            SCENARIOS
            if save == "all"
            else FAILURES
            if r["outcome"] != "ok" and save != "none"
            else None
        )
        if folder is not None:
            print(f"recorded {scenario_path(out, folder, r['scenario'])}")
        elif save == "none":
            print(f"scenario {r['scenario']} not recorded (--save none)")
        else:  # a passing scenario under --save failures
            print(
                f"scenario {r['scenario']} not recorded: it passed, and --save failures records "
                "failing scenarios only (--save all records it)"
            )


def summary_lines(spec, summary: dict, done, executor, out: Path, save: str) -> list[str]:
    """The text summary printed at the end."""
    n, wall = summary["scenarios"], done.wall_s
    head = f"sweep {spec.task} on {spec.robot}: {n} scenarios"
    if summary.get("interrupted"):
        head += f" of {summary['planned']} (stopped part-way)"
    lines = [
        (
            f"{head}, seed {spec.seed}, {executor.jobs} jobs ({executor.name}), wall {wall:.1f} s, "
            f"{n / wall if wall > 0 else 0:.1f} scenarios/s"
        )
    ]
    lo, hi = summary["wilson95"]
    lines.append(
        f"ok {summary['ok']}, failed {summary['failed']}: success rate "
        f"{100 * summary['success_rate']:.1f} % "
        f"(Wilson 95 %: {100 * lo:.1f}-{100 * hi:.1f} %)"
    )
    pe = summary["placement_error_mm"]
    if pe["count"]:
        lines.append(
            f"placement error: p50 {pe['p50']:.2f} mm, p95 {pe['p95']:.2f} mm, max "
            f"{pe['max']:.2f} mm "
            f"(over {pe['count']} scenarios that placed)"
        )
    if summary["failures_by_reason"]:
        lines.append("failures by reason:")
        lines += [f"  {count:6d}  {why}" for why, count in summary["failures_by_reason"].items()]
        if save != "none":
            recorded = [
                r["scenario"]
                for r in done.rows
                if r["outcome"] != "ok"
                and (out / "failures" / f"scenario-{r['scenario']}.mcap").exists()
            ]
            if recorded:
                lines.append(
                    f"failures recorded in {out / 'failures'}/ (e.g. twin replay "
                    f"{out / 'failures' / f'scenario-{recorded[0]}.mcap'})"
                )
        lost = [r for r in done.rows if r["outcome"] != "ok" and r["error"].startswith(NO_RESULT)]
        # the scenarios that killed their process or hung: named, with their recording
        for r in lost[:5]:
            cut = out / "failures" / f"scenario-{r['scenario']}.mcap.partial"
            hint = (
                f"; its recording was cut short as {cut} (`twin recover "
                f"{cut.with_suffix('')}` restores it)"
                if cut.exists()
                else ""
            )
            lines.append(f"scenario {r['scenario']}: {r['error']}{hint}")
        if len(lost) > 5:
            lines.append(
                f"... and {len(lost) - 5} more such scenarios (results.parquet names them)"
            )
    return lines


class Progress:
    """The progress on stderr: a tqdm bar on a terminal (scenarios done, ETA, running success rate);
    elsewhere (CI logs) a plain line at most once a second and at the end; nothing with --quiet."""

    def __init__(self, total: int, *, quiet: bool, stream=None) -> None:
        self.total, self.done, self.ok = total, 0, 0
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self._bar = None
        self._last = -1e9
        self._t0 = time.perf_counter()
        if not quiet and self.stream.isatty():
            from tqdm import tqdm

            self._bar = tqdm(
                total=total, file=self.stream, unit="scenario", dynamic_ncols=True, leave=True
            )

    def __call__(self, row: dict) -> None:
        self.done += 1
        self.ok += row["outcome"] == "ok"
        text = f"ok {100 * self.ok / self.done:.1f} %"
        if self._bar is not None:
            self._bar.set_postfix_str(text, refresh=False)
            self._bar.update(1)
        elif not self.quiet and (
            time.perf_counter() - self._last >= 1.0 or self.done == self.total
        ):
            self._last = time.perf_counter()
            elapsed = self._last - self._t0
            eta = elapsed / self.done * (self.total - self.done)
            self.stream.write(
                f"sweep: {self.done}/{self.total} scenarios, {text}, ETA {eta:.0f} s\n"
            )
            self.stream.flush()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
