"""The ``spm-opt`` command line, thin over the library.

A user's mistake prints one line, ``spm-opt: error: ...``, and exits with status 2; so
does a missing optional package, naming the extra that installs it. The library's
warnings reach stderr as ``spm-opt: warning: ...``; ``-v`` adds its info lines, ``-vv``
its debug lines. :data:`EXIT_STATUSES` lists what each exit status means.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import textwrap
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from spm_opt.choices import (
    CONTOUR_PLANNER_NAMES,
    DEFAULT_MAX_TASKS,
    PLANNER_NAMES,
    TRACKING_MODES,
)
from spm_opt.errors import InputError, PlanningError, RunInterrupted, SpmOptError, require
from spm_opt.output_paths import check_output_directory, check_output_file
from spm_opt.version import package_version

if TYPE_CHECKING:
    from spm_opt.evaluate import Report
    from spm_opt.execution import ExecutionResult

PAPER_PROBLEM = "problems/craniotomy_bone_flap.toml"
_LOG = logging.getLogger("spm_opt.cli")  # also when run as __main__
_VERBOSE = "show the library's info lines on stderr (-vv: debug lines too)"

EXIT_STATUSES = {
    0: "success",
    1: "the plan or run breaks a limit (evaluate), a planner failed (plan, compare), or the "
    "run ended in a safe stop (execute)",
    2: "bad input: one line 'spm-opt: error: ...' names the field and what is allowed "
    "(a missing optional package too); nothing is written",
    130: "interrupted by Ctrl-C (SIGINT): one line, and nothing is written (unless the "
    "command had written its output and waited for a background compile: the line says so)",
}
"""Every exit status of ``spm-opt`` and what it means."""

_DESCRIPTION = """\
Plan, judge and execute trajectories for the spherical parallel manipulator for
brain surgery. 'spm-opt COMMAND --help' describes each command."""


def _epilog() -> str:
    lines = [
        textwrap.fill(meaning, 78, initial_indent=f"  {status:<5}", subsequent_indent=" " * 7)
        for status, meaning in EXIT_STATUSES.items()
    ]
    return "exit statuses:\n" + "\n".join(lines)


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage mistake is one line and status 2 like every other error."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"spm-opt: error: {message} (see {self.prog} --help)\n")


_PLAN_MAX_RATE_HZ = 1e5
"""The highest plan --rate, Hz: how densely the CSV may sample the plan."""
_NOT_COMPARED = tuple(name for name in PLANNER_NAMES if name not in CONTOUR_PLANNER_NAMES)
"""The planners compare leaves out unless named: their plans cut no contour."""


def _command(
    commands: argparse._SubParsersAction, name: str, summary: str, details: str
) -> argparse.ArgumentParser:
    """A sub-command whose ``summary`` (a phrase) is its line in ``spm-opt --help`` and,
    followed by ``details``, the description atop ``spm-opt NAME --help``."""
    return commands.add_parser(
        name, help=summary, description=f"{summary[0].upper()}{summary[1:]}. {details}"
    )


def _parser() -> argparse.ArgumentParser:
    """The command line's parser; light to build: it imports none of the library."""
    parser = _Parser(
        prog="spm-opt",
        description=_DESCRIPTION,
        epilog=_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"spm-opt {package_version()}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help=_VERBOSE)
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    reproduce = _command(
        commands,
        "reproduce",
        "reproduce the paper with its cubic baseline: Tables III and IV, Figs. 8, 13 and 14",
        "Writes each table as markdown and CSV, each figure as PNG, the baseline's "
        "evaluation report (markdown and JSON) and its trajectory CSV; Table III is compared "
        "value by value with the printed one.",
    )
    reproduce.add_argument(
        "--out",
        required=True,
        type=Path,
        help="directory for the tables and figures (made if missing)",
    )
    reproduce.add_argument(
        "--problem",
        default=PAPER_PROBLEM,
        type=Path,
        help=f"the paper's problem file (default: {PAPER_PROBLEM})",
    )

    plan = _command(
        commands,
        "plan",
        "plan a problem with one planner and write the trajectory CSV and its sidecar",
        "The CSV samples the plan at --rate; the JSON sidecar beside it records the "
        "planner, the problem and the planner's statistics. Exits 1 if the planner fails.",
    )
    plan.add_argument("problem", type=Path, help="problem TOML file")
    plan.add_argument(
        "--planner",
        default="cubic",
        metavar="NAME",
        help=f"one of {', '.join(PLANNER_NAMES)} (default: cubic)",
    )
    plan.add_argument(
        "--out",
        required=True,
        type=Path,
        help="trajectory CSV to write; its sidecar (.json) goes beside it",
    )
    plan.add_argument(
        "--rate",
        type=float,
        default=None,
        metavar="HZ",
        help=f"how densely the CSV samples the plan, Hz, 0 < HZ <= {_PLAN_MAX_RATE_HZ:g} "
        "(default 100, breakpoints included); not the control loop's rate: execute "
        "interpolates the CSV at its own --rate",
    )

    compare = _command(
        commands,
        "compare",
        f"plan a problem with every planner but {', '.join(_NOT_COMPARED)} and compare them: "
        "a table and figures",
        f"Each plan is judged by the problem's limits; {', '.join(_NOT_COMPARED)} plans no "
        "cut (a motion for identify) and runs only when --planners names it. Exits 1 if a "
        "planner fails; the others' table and figures are written all the same.",
    )
    compare.add_argument("problem", type=Path, help="problem TOML file")
    compare.add_argument(
        "--planners",
        default=None,
        metavar="NAMES",
        help="comma-separated planner names, any that plan --planner takes (default: every "
        f"one but {', '.join(_NOT_COMPARED)})",
    )
    compare.add_argument(
        "--out",
        required=True,
        type=Path,
        help="directory for the table and figures (made if missing)",
    )

    review = _command(
        commands,
        "review",
        "show a plan (and its run) in 3-D on the skull with the robot, beside the judge's "
        "verdicts: review.html and review.png",
        "Each cut is judged as spm-opt evaluate judges it, in its own tube (the plan's: the "
        "contour tolerance less the execution reserve; the executed cut's: the whole), and "
        "each violation is listed and marked on the cut.",
    )
    review.add_argument("problem", type=Path, help="problem TOML file")
    review.add_argument("plan", type=Path, help="trajectory CSV file (spm-opt plan --out)")
    review.add_argument(
        "--log",
        type=Path,
        default=None,
        help="execution log CSV (spm-opt execute --log) whose measured cut is drawn and "
        "judged too, as spm-opt evaluate judges it (default: only the plan)",
    )
    review.add_argument(
        "--trace",
        type=Path,
        default=None,
        metavar="FILE",
        help="the plant's true state over the logged run (spm-opt execute --trace; only with "
        "--log): its true cut is judged too (default: not judged)",
    )
    review.add_argument(
        "--other-problem",
        action="store_true",
        help="draw a plan or a log made for another problem (or recording none) under PROBLEM "
        "(default: refused)",
    )
    review.add_argument(
        "--out",
        required=True,
        type=Path,
        help="directory for review.html and review.png (made if missing)",
    )

    _execute_parser(commands)
    _emulate_parser(commands)

    sweep = _command(
        commands,
        "sweep",
        "run a parameter sweep, resumable, on a process pool or a Dask cluster",
        "Plans every task of the specification (its grid, random samples and flaps, each "
        "with each of its planners) and writes each task's result, a table, a summary and "
        "figures to --out; a second run there resumes, skipping the tasks done (see "
        "--retry-failed).",
    )
    sweep.add_argument("spec", type=Path, help="sweep specification TOML (problems/sweeps/)")
    sweep.add_argument(
        "--out",
        required=True,
        type=Path,
        help="directory for the results (made if missing; a second run resumes there)",
    )
    sweep.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    sweep.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="Dask scheduler tcp://host:port, or 'local' for a Dask cluster on this machine "
        "(default: a process pool of --workers)",
    )
    sweep.add_argument(
        "--max-tasks",
        type=int,
        default=DEFAULT_MAX_TASKS,
        metavar="N",
        help=f"refuse a sweep of more tasks than this (default {DEFAULT_MAX_TASKS:,})",
    )
    sweep.add_argument(
        "--retry-failed",
        action="store_true",
        help="run every failed task again (default: only those that failed for the machine's "
        "reasons: a worker killed, a lost connection, a timeout)",
    )

    identify = _command(
        commands,
        "identify",
        "identify the robot's parameters and its actuators' loops from execution logs",
        "Fits them to the logs with the problem's robot as the prior, and writes the "
        "identified robot file (TOML) with its report (.md) and a figure of the torques "
        "predicted (.png) beside it.",
    )
    identify.add_argument("logs", nargs="+", type=Path, help="execution log CSV files")
    identify.add_argument(
        "--problem", required=True, type=Path, help="problem TOML whose robot is the prior"
    )
    identify.add_argument(
        "--out", required=True, type=Path, help="robot TOML to write (.md and .png beside it)"
    )
    identify.add_argument(
        "--validate",
        type=Path,
        metavar="LOG",
        help="judge the fit on this log, not used for it (default: on the fitted logs)",
    )
    identify.add_argument(
        "--cutoff-hz",
        type=float,
        default=2.0,
        metavar="HZ",
        help="cutoff of the zero-phase low-pass filter, Hz (default 2)",
    )
    identify.add_argument(
        "--decimation",
        type=int,
        default=None,
        metavar="N",
        help="keep one sample in N (default: 5 samples a cutoff period)",
    )
    identify.add_argument(
        "--min-speed",
        type=float,
        default=0.02,
        metavar="RAD_S",
        help="samples slower than this are left out, rad/s (default 0.02)",
    )

    evaluate = _command(
        commands,
        "evaluate",
        "judge a trajectory CSV, or the run an execution log records, by a problem's limits",
        "Prints the report (markdown, or JSON with --json); exits 1 if the plan or the run "
        "breaks a limit.",
    )
    evaluate.add_argument("problem", type=Path, help="problem TOML file")
    evaluate.add_argument(
        "trajectory", type=Path, help="trajectory CSV file, or execution log CSV (spm-opt execute)"
    )
    evaluate.add_argument(
        "--json", action="store_true", help="print the report as JSON (default: markdown)"
    )
    evaluate.add_argument(
        "--trace",
        type=Path,
        metavar="FILE",
        help="the plant's true state over the logged run (.npz, from spm-opt execute --backend "
        "sim --trace or spm-opt emulate --trace): the true cut is judged too (default: only the "
        "logged one)",
    )
    evaluate.add_argument(
        "--other-problem",
        action="store_true",
        help="judge a plan or a log under PROBLEM though it was made for (ran under) another, "
        "or records none (default: refused)",
    )
    cache = _command(
        commands,
        "cache",
        "show what the cache of compiled libraries holds, or clear it",
        "The dynamics and the optimal-control planners compile their functions to C once "
        "per machine and keep them there.",
    )
    cache.add_argument(
        "action",
        choices=("info", "clear"),
        help="info: its folder, entries, total size and size bound; clear: remove every "
        "entry but the builds in progress",
    )
    for command in commands.choices.values():
        # -v after the command as well; SUPPRESS keeps a -v given before it
        command.add_argument(
            "-v", "--verbose", action="count", default=argparse.SUPPRESS, help=_VERBOSE
        )
    return parser


def _execute_parser(commands: argparse._SubParsersAction) -> None:
    execute = _command(
        commands,
        "execute",
        "run a trajectory CSV on the simulated robot or the Dynamixel actuators, and log it",
        "Checks the plan against --problem's limits first, then follows it in a control "
        "loop at --rate and writes the execution log (CSV); exits 1 if the run ends in a "
        "safe stop.",
    )
    execute.add_argument("plan", type=Path, help="trajectory CSV file (spm-opt plan --out)")
    execute.add_argument(
        "--problem", required=True, type=Path, help="problem TOML whose robot and limits apply"
    )
    execute.add_argument(
        "--backend",
        required=True,
        choices=("sim", "dynamixel"),
        help="sim: the simulated robot; dynamixel: the actuators on --port",
    )
    execute.add_argument("--log", required=True, type=Path, help="CSV log to write")
    execute.add_argument(
        "--port", help="serial device of the actuators, e.g. /dev/ttyUSB0 (dynamixel: required)"
    )
    execute.add_argument(
        "--baud", type=int, default=1_000_000, help="baud rate (dynamixel; default 1000000)"
    )
    execute.add_argument(
        "--ids", default="1,2", help="actuator ids of theta1,theta2 (dynamixel; default 1,2)"
    )
    execute.add_argument(
        "--plant-robot",
        type=Path,
        metavar="FILE",
        help="sim: robot TOML the simulated robot integrates (default: the problem's robot)",
    )
    execute.add_argument(
        "--rate",
        type=float,
        default=100.0,
        metavar="HZ",
        help="the control loop's rate, Hz, 1 <= HZ <= 2000 (default 100): each cycle reads "
        "and writes both actuators over their serial bus (sim: the same loop); not the plan "
        "CSV's sampling rate (plan --rate): the loop interpolates the plan between its "
        "samples",
    )
    execute.add_argument(
        "--approach",
        action="store_true",
        help="first move to the plan's start if away from it (default: refuse to start away)",
    )
    execute.add_argument(
        "--other-problem",
        action="store_true",
        help="run a plan made for another problem (or with no sidecar) under --problem's limits "
        "(default: refused)",
    )
    execute.add_argument(
        "--tracking",
        choices=TRACKING_MODES,
        default="lead",
        help="lead: each goal leads the plan by the position loop's lag (the robot file's "
        "loop parameters); none: the goal is the plan (default lead)",
    )
    execute.add_argument(
        "--realtime", action="store_true", help="sim: run on the wall clock (default: fast)"
    )
    execute.add_argument(
        "--trace",
        type=Path,
        metavar="FILE",
        help="sim: save the plant's true state here (.npz; spm-opt evaluate --trace reads it; "
        "default: not saved)",
    )
    execute.add_argument(
        "--start-deg",
        default=None,
        metavar="A,B",
        help="sim: where the simulated robot rests at the start, deg (default: the plan's start)",
    )
    execute.add_argument(
        "--feed",
        type=float,
        default=1.0,
        metavar="F",
        help="start at this fraction of the planned pace, 0.1 to 4 (default 1)",
    )
    execute.add_argument(
        "--max-hold",
        type=float,
        default=600.0,
        metavar="S",
        help="a feed hold longer than this ends in the safe stop (s, default 600)",
    )
    execute.add_argument(
        "--interactive",
        action="store_true",
        help="steer from the terminal: space hold/resume, + and - feed 10%%, q stop "
        "(sim: runs on the wall clock; default: no keys)",
    )


def _emulate_parser(commands: argparse._SubParsersAction) -> None:
    emulate = _command(
        commands,
        "emulate",
        "serve two emulated L54 actuators (Protocol 2.0) on a pseudo-terminal",
        "Prints the pseudo-terminal's path, for execute --backend dynamixel --port, and "
        "serves until Ctrl-C or SIGTERM; the actuators drive a simulated robot.",
    )
    emulate.add_argument(
        "--problem",
        default=PAPER_PROBLEM,
        type=Path,
        help=f"problem TOML whose robot is emulated (default: {PAPER_PROBLEM})",
    )
    emulate.add_argument(
        "--plant-robot",
        type=Path,
        metavar="FILE",
        help="robot TOML the emulated actuators drive (default: the problem's robot)",
    )
    emulate.add_argument("--ids", default="1,2", help="actuator ids (default 1,2)")
    emulate.add_argument(
        "--start-deg", default="0,0", metavar="A,B", help="start angles, deg (default 0,0)"
    )
    emulate.add_argument(
        "--fault",
        action="append",
        default=[],
        help="inject a fault (drop, crc, delay, overload, stuck, write), e.g. overload:id=1,at=3 "
        "(repeatable; default none)",
    )
    emulate.add_argument(
        "--seed", type=int, default=0, help="seed of the current noise (default 0)"
    )
    emulate.add_argument(
        "--trace",
        type=Path,
        metavar="FILE",
        help="save the plant's true state here (.npz) when serving ends (default: not saved)",
    )


def _pair(text: str, option: str, kind: type) -> tuple:
    import numpy as np

    parts = text.split(",")
    try:
        values = tuple(kind(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 2 or not all(np.isfinite(values)):
        raise InputError(f"{option} {text!r}: expected two {kind.__name__} values like 1,2")
    return values


def _execute(args: argparse.Namespace) -> None:
    import numpy as np

    from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot
    from spm_opt.execution.console import console
    from spm_opt.model.params import load_robot
    from spm_opt.problem import load_problem
    from spm_opt.trajectory import Trajectory

    try:
        settings = ExecutionSettings(
            rate_hz=args.rate,
            approach=args.approach,
            feed=args.feed,
            max_feed=max(ExecutionSettings.max_feed, args.feed),
            max_hold_s=args.max_hold,
            other_problem=args.other_problem,
            tracking=args.tracking,
        )
    except InputError as error:  # name the option the user gave, not the setting
        setting = str(error).split(" = ")[0]
        raise InputError(f"{_SETTING_OPTIONS.get(setting, setting)}: {error}") from None
    if args.trace is not None and (args.backend != "sim" or args.trace.suffix != ".npz"):
        raise InputError(
            f"--trace {args.trace}: expected a file name ending in .npz, with --backend sim "
            "(the emulator's own --trace records the plant behind the Dynamixel backend)"
        )
    check_output_file(args.log, "--log")
    if args.trace is not None:
        check_output_file(args.trace, "--trace")
    problem = load_problem(args.problem)
    trajectory = Trajectory.from_csv(args.plan)
    keys = _keys_terminal(args.interactive)
    if args.backend == "sim":
        start = trajectory.position(trajectory.start_time)
        if args.start_deg is not None:
            start = np.radians(_pair(args.start_deg, "--start-deg", float))
        plant = None if args.plant_robot is None else load_robot(args.plant_robot)
        realtime = args.realtime or keys is not None  # keys need the wall clock
        backend = SimulatedRobot(
            problem.robot, start_rad=start, realtime=realtime, plant_robot=plant
        )
    else:
        from spm_opt.execution.dynamixel import DynamixelRobot

        if args.plant_robot is not None:
            raise InputError("--plant-robot: only with --backend sim (the real robot is the plant)")

        if args.port is None:
            raise InputError("--port: required with --backend dynamixel (e.g. /dev/ttyUSB0)")
        ids = _pair(args.ids, "--ids", int)
        backend = DynamixelRobot(problem.robot.actuator, args.port, args.baud, ids)
    executor = Executor(problem, backend, settings)
    with console(executor, problem, trajectory, sys.stderr, keys):
        result = executor.run(trajectory, args.log)
    if args.trace is not None:
        backend.trace.save(args.trace)
    loop = result.statistics
    print(
        f"{args.log}: {result.samples} samples, {loop.achieved_rate_hz:.1f} Hz achieved, "
        f"period error p99 {loop.period_error_p99_ms:.3f} ms, {loop.overruns} overruns"
    )
    if not result.succeeded:
        raise GateFailed(_outcome(result))


_SETTING_OPTIONS = {
    "rate_hz": "--rate",
    "feed": "--feed",
    "max_feed": "--feed",
    "max_hold_s": "--max-hold",
    "tracking": "--tracking",
}
"""The execute option that sets each :class:`~spm_opt.execution.ExecutionSettings` field."""


def _outcome(result: ExecutionResult) -> str:
    """A run that did not succeed, in one line: why, after a safe stop how far each joint
    travelled after the fault and when rest was proven, and what a failed log kept."""
    log, kept = result.log, ""
    if log is not None and log.fault:
        failed = "" if log.fault in result.reason else f"log failed: {log.fault}; "
        kept = f"; {failed}{log.summary()}"
    if result.stop is None:
        return result.reason + kept
    stop = result.stop
    line = f"safe stop: {result.reason}"
    if stop.travel_deg is not None:
        line += "; travel after the fault " + ", ".join(
            f"theta{j + 1} {travel:.2f} deg" for j, travel in enumerate(stop.travel_deg)
        )
    if stop.duration_s is not None:
        return f"{line}; at rest {stop.duration_s:.2f} s after it{kept}"
    return f"{line}; rest {stop.rest}{kept}"


def _keys_terminal(interactive: bool) -> int | None:
    """The terminal the keys are read from: stdin's, with --interactive, if it is one."""
    if not interactive:
        return None
    if not sys.stdin.isatty():
        _LOG.warning("--interactive: stdin is not a terminal, so the keys are off")
        return None
    return sys.stdin.fileno()


class GateFailed(Exception):
    """The command did its work, but the result fails what a script would gate on: a plan
    or run that breaks a limit, a planner that failed, a run that ended in a safe stop or
    without rest proven. The command exits with status 1."""


def _emulate(args: argparse.Namespace) -> None:
    import numpy as np

    from spm_opt.execution.emulator import parse_faults, serve
    from spm_opt.model.params import load_robot
    from spm_opt.problem import load_problem

    if args.plant_robot is not None:
        robot = load_robot(args.plant_robot)
    else:
        robot = load_problem(args.problem).robot
    ids = _pair(args.ids, "--ids", int)
    start = np.radians(_pair(args.start_deg, "--start-deg", float))
    faults = parse_faults(args.fault)
    if args.trace is not None:
        check_output_file(args.trace, "--trace")
    serve(
        robot,
        ids,
        start,
        faults,
        args.seed,
        announce=lambda device: print(device, flush=True),
        trace_path=args.trace,
    )


def _sweep(args: argparse.Namespace) -> None:
    from spm_opt.sweep.results import write_sweep_report
    from spm_opt.sweep.runner import run_sweep
    from spm_opt.sweep.spec import load_sweep_spec

    check_output_directory(args.out, "--out")
    spec = load_sweep_spec(args.spec, max_tasks=args.max_tasks)
    tasks = spec.tasks()
    summary = run_sweep(
        tasks,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        retry_failed=args.retry_failed,
    )
    print(
        f"{spec.name}: {summary.total} tasks, {summary.skipped} already done, "
        f"{summary.done + summary.failed} run ({summary.retried} again, {summary.failed} "
        f"failed) in {summary.seconds:.1f} s",
        file=sys.stderr,
    )
    keys = [task.key for task in tasks]
    for path in write_sweep_report(args.out, title=spec.description or spec.name, keys=keys):
        print(path)


def _reproduce(args: argparse.Namespace) -> None:
    from spm_opt.reproduce import reproduce

    if not args.problem.exists():
        raise InputError(
            f"--problem {args.problem}: no such file (run from the repository's root, or "
            "pass --problem with the path of craniotomy_bone_flap.toml)"
        )
    check_output_directory(args.out, "--out")
    for path in reproduce(args.problem, args.out):
        print(path)


def _plan(args: argparse.Namespace) -> None:
    from spm_opt.planners import get_planner, plan
    from spm_opt.problem import load_problem

    if args.out.suffix != ".csv":
        raise InputError(f"--out {args.out}: expected a file name ending in .csv")
    if args.rate is not None and not 0.0 < args.rate <= _PLAN_MAX_RATE_HZ:
        raise InputError(
            f"--rate {args.rate}: expected a rate in Hz with 0 < rate <= {_PLAN_MAX_RATE_HZ:g}"
        )
    check_output_file(args.out, "--out")
    get_planner(args.planner)
    problem = load_problem(args.problem)
    trajectory = plan(problem, args.planner)
    trajectory.to_csv(args.out, rate_hz=args.rate)
    print(f"{args.out}: {args.planner} plan, {trajectory.duration:.3f} s")


def _evaluate(args: argparse.Namespace) -> None:
    from spm_opt.evaluate import evaluate
    from spm_opt.evaluate_execution import evaluate_log, is_execution_log
    from spm_opt.problem import load_problem

    problem = load_problem(args.problem)
    if is_execution_log(args.trajectory):
        reports = evaluate_log(
            problem, args.trajectory, args.trace, other_problem=args.other_problem
        )
        judged = {"measured": reports.measured, "true": reports.true}
    else:
        if args.trace:
            raise InputError("--trace: only with an execution log, not a trajectory CSV")
        judged = {"planned": evaluate(problem, args.trajectory, other_problem=args.other_problem)}
    judged = {name: report for name, report in judged.items() if report is not None}
    if len(judged) == 1:
        (report,) = judged.values()
        print(json.dumps(report.to_dict(), indent=2) if args.json else report.to_markdown(), end="")
    elif args.json:
        print(json.dumps({name: report.to_dict() for name, report in judged.items()}, indent=2))
    else:
        cuts = [f"## The {name} cut\n\n{report.to_markdown()}" for name, report in judged.items()]
        print("\n".join(cuts), end="")
    faults = [_faults(name, report) for name, report in judged.items()]
    if any(faults):
        raise GateFailed("; ".join(fault for fault in faults if fault))


def _faults(name: str, report: Report) -> str:
    """What fails the gate in one judged cut, in words, or "" if nothing does."""
    rules = sorted({violation.rule for violation in report.violations})
    parts = [f"{len(report.violations)} violations ({', '.join(rules)})"] if rules else []
    if not getattr(report, "completed", True):
        parts.append("the run did not complete")
    return f"the {name} cut: {' and '.join(parts)}" if parts else ""


def _review(args: argparse.Namespace) -> None:
    from spm_opt.files import write_atomically
    from spm_opt.problem import load_problem
    from spm_opt.report.review import review_inputs, review_page
    from spm_opt.report.review_png import review_png
    from spm_opt.skull.surface import Skull

    check_output_directory(args.out, "--out")
    problem = load_problem(args.problem)
    given = review_inputs(problem, args.plan, args.log, args.other_problem, args.trace)
    skull = problem.skull if problem.skull is not None else Skull(surface=problem.surface)
    files = {
        args.out / "review.html": review_page(problem, skull, given),
        args.out / "review.png": review_png(problem, skull, given),
    }
    write_atomically(files)
    for path in files:
        print(path)


def _identify(args: argparse.Namespace) -> None:
    from spm_opt.files import write_atomically
    from spm_opt.identify import (
        identify,
        prediction_figure,
        prediction_rms,
        report_markdown,
        robot_file_text,
    )
    from spm_opt.identify_loop import estimate_loops, goal_rms
    from spm_opt.identify_samples import log_samples
    from spm_opt.plots import to_png
    from spm_opt.problem import load_problem

    if args.out.suffix != ".toml":
        raise InputError(f"--out {args.out}: expected a robot file name ending in .toml")
    check_output_file(args.out, "--out")
    problem = load_problem(args.problem)
    settings = (args.cutoff_hz, args.decimation, args.min_speed)
    samples = log_samples(args.logs, *settings)
    validation = samples if args.validate is None else log_samples([args.validate], *settings)
    _LOG.info("identify: %d samples from %d logs; fitting", len(samples.q), len(args.logs))
    identification = identify(problem.robot, samples)
    loops = estimate_loops(args.logs, problem.robot)
    on = "the fitted logs" if args.validate is None else f"{args.validate.name} (not fitted)"
    prior = prediction_rms(problem.robot, validation)
    identified = prediction_rms(identification.robot, validation)
    figure = prediction_figure(problem.robot, identification.robot, validation)
    goal_logs = args.logs if args.validate is None else [args.validate]
    goals = [goal_rms(goal_logs, robot) for robot in (problem.robot, loops.robot(problem.robot))]
    actuator = problem.robot.actuator
    unit = actuator.current_unit_a  # one Present Current unit, A
    report = report_markdown(
        identification, prior, identified, on, float(actuator.current_map.torque(unit))
    )
    files = {
        args.out: robot_file_text(identification, loops, args.out.stem),
        args.out.with_suffix(".md"): "\n".join([report, *loops.markdown(*goals, on), ""]),
        args.out.with_suffix(".png"): to_png(figure),
    }
    write_atomically(files)
    for path in files:
        print(path)
    print(
        f"torque prediction RMS on {on}: prior {prior[0]:.4f}, {prior[1]:.4f} N·m; "
        f"identified {identified[0]:.4f}, {identified[1]:.4f} N·m",
        file=sys.stderr,
    )
    print(
        f"actuator loops: position_loop_gain_per_s {loops.gain_per_s[0]:.4g}, "
        f"{loops.gain_per_s[1]:.4g}; velocity_loop_bandwidth_per_s "
        f"{loops.bandwidth_per_s[0]:.4g}, {loops.bandwidth_per_s[1]:.4g} (1/s)",
        file=sys.stderr,
    )


def _compare(args: argparse.Namespace) -> None:
    from spm_opt.comparison import progress_line, run_planners, write_comparison
    from spm_opt.problem import load_problem

    names = None
    if args.planners is not None:
        names = [name.strip() for name in args.planners.split(",") if name.strip()]
        if not names:
            raise InputError(f"--planners {args.planners!r}: expected comma-separated names")
    check_output_directory(args.out, "--out")
    problem = load_problem(args.problem)
    outcomes = run_planners(
        problem, names, lambda *call: print(progress_line(*call), file=sys.stderr, flush=True)
    )
    for path in write_comparison(problem, outcomes, args.out):
        print(path)
    failed = [outcome.planner for outcome in outcomes if outcome.error is not None]
    if failed:
        raise GateFailed(f"{len(failed)} of {len(outcomes)} planners failed: {', '.join(failed)}")


def _cache(args: argparse.Namespace) -> None:
    from spm_opt.model import library_cache

    directory = library_cache.cache_directory()
    if directory.exists() and not directory.is_dir():
        raise InputError(f"{library_cache.CACHE_ENV} = {directory}: not a folder")
    if args.action == "clear":
        removed = library_cache.clear()
        size = sum(entry.size for entry in removed) / 1e6
        print(f"{directory}: entries removed: {len(removed)}, {size:.2f} MB")
        return
    bound = library_cache.size_bound() / 1e6
    listed = library_cache.entries()
    size = sum(entry.size for entry in listed) / 1e6
    print(f"folder   {directory}")
    print(f"entries  {len(listed)}, {size:.2f} MB; builds in progress: {library_cache.builds()}")
    print(f"bound    {bound:g} MB (${library_cache.SIZE_ENV}); least recently used go first")
    width = max((len(entry.name) for entry in listed), default=0)
    for entry in reversed(listed):
        used = time.strftime("%Y-%m-%d %H:%M", time.localtime(entry.used))
        print(f"  {entry.name:<{width}}  {entry.size / 1e6:8.2f} MB  used {used}")


_COMMANDS = {
    "reproduce": _reproduce,
    "plan": _plan,
    "compare": _compare,
    "evaluate": _evaluate,
    "identify": _identify,
    "review": _review,
    "execute": _execute,
    "emulate": _emulate,
    "sweep": _sweep,
    "cache": _cache,
}


def _optional_modules(args: argparse.Namespace) -> list[tuple[str, str]]:
    """The optional modules the command needs, each with what needs it; imported before the
    command starts, so a missing one leaves nothing half-written."""
    if args.command == "sweep":
        needed = [("tqdm", "the sweep"), ("pyarrow", "the sweep's results.parquet")]
        if args.scheduler is not None:
            needed.append(("distributed", f"--scheduler {args.scheduler}"))
        return needed
    if args.command == "reproduce":
        return [("mujoco", "reproduce (Table IV's MuJoCo check)")]
    if args.command == "execute" and args.backend == "dynamixel":
        # pyserial first: dynamixel-sdk imports it, and would be blamed for its absence
        return [("serial", "--backend dynamixel"), ("dynamixel_sdk", "--backend dynamixel")]
    return []


class _OneLine(logging.Formatter):
    """A log record as ``spm-opt: warning: message`` (the level in lower case)."""

    def format(self, record: logging.LogRecord) -> str:
        return f"spm-opt: {record.levelname.lower()}: {record.getMessage()}"


def _log_to_stderr(verbosity: int) -> logging.Handler:
    """Send the library's log to stderr, warnings and worse (-v: info, -vv: debug too);
    returns the handler, for :func:`main` to remove."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLine())
    logger = logging.getLogger("spm_opt")
    logger.setLevel({0: logging.WARNING, 1: logging.INFO}.get(verbosity, logging.DEBUG))
    logger.addHandler(handler)
    return handler


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status. A Ctrl-C at any point of it, while
    the command's modules are imported too, ends it with one line and status 130."""
    try:
        args = _parser().parse_args(argv)
        logger = logging.getLogger("spm_opt")
        level = logger.level
        handler = _log_to_stderr(args.verbose)
        try:
            status = _run(args)
            try:
                _wait_for_builds()
            except KeyboardInterrupt:
                return _interrupted(
                    "the command's output stands; the library compiling in the background "
                    "is left for the next run"
                )
            return status
        finally:
            logger.removeHandler(handler)
            logger.setLevel(level)
    except KeyboardInterrupt:
        return _interrupted()


def _run(args: argparse.Namespace) -> int:
    """Run the parsed command; returns the exit status."""
    try:
        for module, needed_by in _optional_modules(args):
            require(module, needed_by)
        _COMMANDS[args.command](args)
    except RunInterrupted as interrupted:
        print(f"spm-opt: interrupted: {interrupted}", file=sys.stderr)
        return 130
    except PlanningError as error:  # a valid problem the planner could not plan
        print(f"spm-opt: failed: {error}", file=sys.stderr)
        return 1
    except SpmOptError as error:
        print(f"spm-opt: error: {error}", file=sys.stderr)
        return 2
    except GateFailed as failed:
        print(f"spm-opt: {failed}", file=sys.stderr)
        return 1
    except OSError as error:  # an output path that cannot be written: the user can fix it
        where = f"{error.filename}: " if error.filename else ""
        print(f"spm-opt: error: {where}cannot write ({error.strerror or error})", file=sys.stderr)
        return 2
    return 0


def _wait_for_builds() -> None:
    """Wait for the libraries a planner compiles in the background, so that a failed
    build's warning reaches stderr (:mod:`spm_opt.planners.ocp.nlp_library`)."""
    library = sys.modules.get("spm_opt.planners.ocp.nlp_library")
    if library is not None:
        library.wait_for_builds()


def _interrupted(what: str = "nothing written") -> int:
    """After a Ctrl-C: the compilers the command started stop (the process need not wait
    for them), and a second Ctrl-C ends the process at once; one line; status 130."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_DFL)
    library_cache = sys.modules.get("spm_opt.model.library_cache")
    if library_cache is not None:
        library_cache.stop_compilers()
    print(f"spm-opt: interrupted: {what}", file=sys.stderr)
    return 130


if __name__ == "__main__":
    sys.exit(main())
