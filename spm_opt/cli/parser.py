"""The command line's argument parser: its commands, options and help.

Light to build: it imports none of the library but :mod:`spm_opt.base`'s names and version.
"""

from __future__ import annotations

import argparse
import textwrap
from pathlib import Path
from typing import NoReturn

from spm_opt.base.choices import (
    CONTOUR_PLANNER_NAMES,
    DEFAULT_MAX_TASKS,
    PLANNER_NAMES,
    PREDICTION_ACTIONS,
    TRACKING_MODES,
)
from spm_opt.base.version import package_version

PAPER_PROBLEM = "problems/craniotomy_bone_flap.toml"
_VERBOSE = "show the library's info lines on stderr (-vv: debug lines too)"

EXIT_STATUSES = {
    0: "success",
    1: "the plan or run breaks a limit (evaluate), the predicted run does (predict), a "
    "planner failed (plan, compare), or the run ended in a safe stop (execute)",
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


PLAN_MAX_RATE_HZ = 1e5
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


# The options several commands take, each written once; the help is each command's own.


def _verbose(parser: argparse.ArgumentParser, default: object) -> None:
    parser.add_argument("-v", "--verbose", action="count", default=default, help=_VERBOSE)


def _problem_file(command: argparse.ArgumentParser) -> None:
    command.add_argument("problem", type=Path, help="problem TOML file")


def _plan_file(command: argparse.ArgumentParser) -> None:
    command.add_argument("plan", type=Path, help="trajectory CSV file (spm-opt plan --out)")


def _problem_option(command: argparse.ArgumentParser, text: str, *, paper: bool) -> None:
    """``--problem``: the paper's by default (said in the help), or required."""
    if paper:
        command.add_argument(
            "--problem", default=PAPER_PROBLEM, type=Path, help=f"{text} (default: {PAPER_PROBLEM})"
        )
    else:
        command.add_argument("--problem", required=True, type=Path, help=text)


def _out(command: argparse.ArgumentParser, text: str) -> None:
    command.add_argument("--out", required=True, type=Path, help=text)


def _rate(command: argparse.ArgumentParser, default: float | None, text: str) -> None:
    command.add_argument("--rate", type=float, default=default, metavar="HZ", help=text)


def _other_problem(command: argparse.ArgumentParser, text: str) -> None:
    command.add_argument("--other-problem", action="store_true", help=text)


def _plant_robot(command: argparse.ArgumentParser, text: str) -> None:
    command.add_argument("--plant-robot", type=Path, metavar="FILE", help=text)


def _trace(command: argparse.ArgumentParser, text: str) -> None:
    command.add_argument("--trace", type=Path, metavar="FILE", help=text)


def _json(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--json", action="store_true", help="print the report as JSON (default: markdown)"
    )


def _tracking(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--tracking",
        choices=TRACKING_MODES,
        default="lead",
        help="lead: each goal leads the plan by the position loop's lag (the robot file's "
        "loop parameters); none: the goal is the plan (default lead)",
    )


def _feed(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--feed",
        type=float,
        default=1.0,
        metavar="F",
        help="start at this fraction of the planned pace, 0.1 to 4 (default 1)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser; light to build: it imports none of the library."""
    parser = _Parser(
        prog="spm-opt",
        description=_DESCRIPTION,
        epilog=_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"spm-opt {package_version()}")
    _verbose(parser, 0)
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    reproduce = _command(
        commands,
        "reproduce",
        "reproduce the paper with its cubic baseline: Tables III and IV, Figs. 8, 13 and 14",
        "Writes each table as markdown and CSV, each figure as PNG, the baseline's "
        "evaluation report (markdown and JSON) and its trajectory CSV; Table III is compared "
        "value by value with the printed one.",
    )
    _out(reproduce, "directory for the tables and figures (made if missing)")
    _problem_option(reproduce, "the paper's problem file", paper=True)

    plan = _command(
        commands,
        "plan",
        "plan a problem with one planner and write the trajectory CSV and its sidecar",
        "The CSV samples the plan at --rate; the JSON sidecar beside it records the "
        "planner, the problem and the planner's statistics. Exits 1 if the planner fails.",
    )
    _problem_file(plan)
    plan.add_argument(
        "--planner",
        default="cubic",
        metavar="NAME",
        help=f"one of {', '.join(PLANNER_NAMES)} (default: cubic)",
    )
    _out(plan, "trajectory CSV to write; its sidecar (.json) goes beside it")
    _rate(
        plan,
        None,
        f"how densely the CSV samples the plan, Hz, 0 < HZ <= {PLAN_MAX_RATE_HZ:g} "
        "(default 100, breakpoints included); not the control loop's rate: execute "
        "interpolates the CSV at its own --rate",
    )
    plan.add_argument(
        "--predicted-reserve",
        nargs="?",
        const="",
        default=None,
        metavar="ROBOT",
        help="predict the plan's cut on the closed-loop model of ROBOT (a robot TOML; "
        "without one, the problem's robot), as spm-opt predict does, and when it leaves the "
        "tube re-plan once keeping for execution what the prediction says it takes, plus "
        "0.01 mm (default: the problem's execution_reserve_mm)",
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
    _problem_file(compare)
    compare.add_argument(
        "--planners",
        default=None,
        metavar="NAMES",
        help="comma-separated planner names, any that plan --planner takes (default: every "
        f"one but {', '.join(_NOT_COMPARED)})",
    )
    _out(compare, "directory for the table and figures (made if missing)")

    review = _command(
        commands,
        "review",
        "show a plan (and its run) in 3-D on the skull with the robot, beside the judge's "
        "verdicts: review.html and review.png",
        "Each cut is judged as spm-opt evaluate judges it, in its own tube (the plan's: the "
        "contour tolerance less the execution reserve; the executed cut's: the whole), and "
        "each violation is listed and marked on the cut.",
    )
    _problem_file(review)
    _plan_file(review)
    review.add_argument(
        "--log",
        type=Path,
        default=None,
        help="execution log CSV (spm-opt execute --log) whose measured cut is drawn and "
        "judged too, as spm-opt evaluate judges it (default: only the plan)",
    )
    _trace(
        review,
        "the plant's true state over the logged run (spm-opt execute --trace; only with "
        "--log): its true cut is judged too (default: not judged)",
    )
    _other_problem(
        review,
        "draw a plan or a log made for another problem (or recording none) under PROBLEM "
        "(default: refused)",
    )
    review.add_argument(
        "--predict",
        nargs="?",
        const="",
        default=None,
        metavar="ROBOT",
        help="also draw and judge the plan's cut predicted on the closed-loop model of ROBOT "
        "(a robot TOML; without one, the problem's robot), as spm-opt predict judges it "
        "(default: not predicted)",
    )
    _out(review, "directory for review.html and review.png (made if missing)")

    _execute_parser(commands)
    _navigate_parser(commands)
    _predict_parser(commands)
    _compensate_parser(commands)
    _slow_breakaways_parser(commands)
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
    _out(sweep, "directory for the results (made if missing; a second run resumes there)")
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
    _problem_option(identify, "problem TOML whose robot is the prior", paper=False)
    _out(identify, "robot TOML to write (.md and .png beside it)")
    identify.add_argument(
        "--validate",
        type=Path,
        metavar="LOG",
        help="judge the fit on this log too, not used for it (default: on the fitted "
        "samples and the held-out stretches)",
    )
    identify.add_argument(
        "--holdout",
        type=float,
        default=0.2,
        metavar="FRACTION",
        help="share of each log kept out of the fit, its end (whole periods of a periodic "
        "plan), on which the torque prediction is judged, 0 to 0.5 (default 0.2; 0: fit all)",
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

    calibrate = _command(
        commands,
        "calibrate",
        "calibrate the robot's encoder zeros and geometry from a tracker's measurements",
        "Chooses the poses (a D-optimal design), runs them as a plan through the executor, "
        "pairs the log's readings with the tracker's still windows, fits the registration "
        "and the robot's error angles, judges the fit at held-out poses, and writes the "
        "robot file with its [calibration] (.md report and .png residuals beside it). "
        "Without --log and --tracker it runs on the simulated robot with a simulated "
        "tracker; with --write-plan it only writes the plan, for spm-opt execute.",
    )
    _problem_option(calibrate, "problem TOML whose robot is calibrated", paper=False)
    calibrate.add_argument(
        "--out",
        type=Path,
        help="robot TOML to write (.md and .png beside it; required unless --write-plan)",
    )
    calibrate.add_argument(
        "--write-plan",
        type=Path,
        metavar="CSV",
        help="only write the calibration plan here, for spm-opt execute (default: plan, run "
        "and fit)",
    )
    calibrate.add_argument(
        "--log",
        type=Path,
        help="execution log of the calibration plan's run, with --tracker (default: run it "
        "on the simulated robot)",
    )
    calibrate.add_argument(
        "--tracker",
        type=Path,
        metavar="FILE",
        help="the tracker's export of that run: point CSV, pose CSV or OptiTrack Motive CSV "
        "(default: the simulated tracker's)",
    )
    calibrate.add_argument(
        "--body", help="rigid body or marker to read from a Motive export (default: its only one)"
    )
    calibrate.add_argument(
        "--poses", type=int, default=40, metavar="N", help="poses fitted (default 40)"
    )
    calibrate.add_argument(
        "--held-out", type=int, default=8, metavar="N", help="poses never fitted (default 8)"
    )
    calibrate.add_argument(
        "--marker-distance-mm",
        type=float,
        default=200.0,
        metavar="MM",
        help="the marker's distance from the isocenter along the tool, nominal (default 200)",
    )
    calibrate.add_argument(
        "--tracker-fle-mm",
        type=float,
        default=0.2,
        metavar="MM",
        help="simulated tracker: localisation error per sample, 3-D RMS (default 0.2)",
    )
    calibrate.add_argument(
        "--tracker-bias-mm",
        type=float,
        default=0.0,
        metavar="MM",
        help="simulated tracker: error per pose that averaging keeps, 3-D RMS (default 0)",
    )
    calibrate.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the held-out draw and the simulated tracker (default 0)",
    )
    _plant_robot(
        calibrate, "robot TOML the simulated robot is built as (default: the problem's robot)"
    )

    evaluate = _command(
        commands,
        "evaluate",
        "judge a trajectory CSV, or the run an execution log records, by a problem's limits",
        "Prints the report (markdown, or JSON with --json); exits 1 if the plan or the run "
        "breaks a limit.",
    )
    _problem_file(evaluate)
    evaluate.add_argument(
        "trajectory", type=Path, help="trajectory CSV file, or execution log CSV (spm-opt execute)"
    )
    _json(evaluate)
    _trace(
        evaluate,
        "the plant's true state over the logged run (.npz, from spm-opt execute --backend "
        "sim --trace or spm-opt emulate --trace): the true cut is judged too (default: only the "
        "logged one)",
    )
    _other_problem(
        evaluate,
        "judge a plan or a log under PROBLEM though it was made for (ran under) another, "
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
        _verbose(command, argparse.SUPPRESS)  # -v after the command too; keeps one given before
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
    _plan_file(execute)
    _problem_option(execute, "problem TOML whose robot and limits apply", paper=False)
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
    _plant_robot(
        execute, "sim: robot TOML the simulated robot integrates (default: the problem's robot)"
    )
    _rate(
        execute,
        100.0,
        "the control loop's rate, Hz, 1 <= HZ <= 2000 (default 100): each cycle reads "
        "and writes both actuators over their serial bus (sim: the same loop); not the plan "
        "CSV's sampling rate (plan --rate): the loop interpolates the plan between its "
        "samples",
    )
    execute.add_argument(
        "--approach",
        action="store_true",
        help="first move to the plan's start if away from it (default: refuse to start away)",
    )
    _other_problem(
        execute,
        "run a plan made for another problem (or with no sidecar) under --problem's limits "
        "(default: refused)",
    )
    _tracking(execute)
    execute.add_argument(
        "--current-reads",
        type=int,
        default=None,
        metavar="N",
        help="read Present Current N times while each goal is held (one at a random "
        "instant in each of N equal parts of the hold) and log their mean: a log to "
        "identify the robot from needs it, since one read a period aliases the velocity "
        "loop's answer to each goal step; each read is a bus transaction, 0 to 20 "
        "(default: sim 10, dynamixel 0)",
    )
    execute.add_argument(
        "--realtime", action="store_true", help="sim: run on the wall clock (default: fast)"
    )
    _trace(
        execute,
        "sim: save the plant's true state here (.npz; spm-opt evaluate --trace reads it; "
        "default: not saved)",
    )
    execute.add_argument(
        "--start-deg",
        default=None,
        metavar="A,B",
        help="sim: where the simulated robot rests at the start, deg (default: the plan's start)",
    )
    _feed(execute)
    execute.add_argument(
        "--predicted-outside",
        choices=PREDICTION_ACTIONS,
        default="refuse",
        help="the plan first runs through the closed-loop model of the problem's robot "
        "(spm-opt predict): refuse: with a contour tolerance, a predicted cut outside the "
        "tube, or a predicted run that does not complete, refuses the run; warn: says so "
        "and runs (default refuse)",
    )
    execute.add_argument(
        "--predicted-limits",
        choices=PREDICTION_ACTIONS,
        default="warn",
        help="warn: a predicted run that breaks a robot limit (joint speed, acceleration, "
        "jerk, torque, current), or takes a joint's speed past 95 %% of its limit or its "
        "acceleration or jerk past 90 %% (the margin for what the model does not see), is "
        "said on stderr and run; refuse: refuses the run "
        "(default warn: the stick-slip of the robot's friction breaks the jerk limit at "
        "the stops of time-optimal plans)",
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
    _igtl(
        execute,
        "show the run in 3D Slicer: an OpenIGTLink server on PORT (default 18944, Slicer's) "
        "streams the tool's pose (ToolToRAS), the plan, the executed cut and the run's state, "
        "and takes STOP, HOLD and RESUME (never a start); sim: runs on the wall clock "
        "(default: no server)",
    )


def _navigate_parser(commands: argparse._SubParsersAction) -> None:
    navigate = _command(
        commands,
        "navigate",
        "plan flaps drawn in 3D Slicer, over OpenIGTLink, and send the planned cut back",
        "Serves an OpenIGTLink server until Ctrl-C: a POINT list from Slicer is the flap (in "
        "the image's RAS, mm), STRING CMD_<id> 'PLAN [planner]' writes it to --out as a "
        "markups file and a problem file based on --problem, plans it there and sends the "
        "planned cut back as the PlannedCut model; a TRANSFORM RASToRobot is the registration "
        "from then on. Nothing moves: run the files with spm-opt execute.",
    )
    _problem_option(
        navigate, "problem TOML the flaps are planned on (its robot, skull, limits)", paper=False
    )
    _out(navigate, "directory for each flap's markups, problem and plan files (made if missing)")
    _igtl(navigate, "the OpenIGTLink server's port (default 18944, Slicer's)")


def _igtl(command: argparse.ArgumentParser, help_text: str) -> None:
    """``--igtl [PORT]`` and ``--igtl-host``: the navigation link's server."""
    command.add_argument(
        "--igtl",
        type=_igtl_port,
        nargs="?",
        const=18944,
        default=None,
        metavar="PORT",
        help=help_text,
    )
    command.add_argument(
        "--igtl-host",
        default="127.0.0.1",
        metavar="ADDRESS",
        help="the address the OpenIGTLink server listens on (default 127.0.0.1: this "
        "machine only; 0.0.0.0: every interface)",
    )


def _igtl_port(text: str) -> int:
    """A TCP port, 1 to 65535 (0: any free one, said in the log)."""
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a TCP port, 0 to 65535")
    return port


def _model_robot(command: argparse.ArgumentParser) -> None:
    """``--robot``: the robot file the closed-loop model is."""
    command.add_argument(
        "--robot",
        type=Path,
        metavar="FILE",
        help="robot TOML the model is, e.g. spm-opt identify's (default: the problem's robot)",
    )


def _model_run(command: argparse.ArgumentParser) -> None:
    """The executor's settings for a run on the model: ``--rate``, ``--tracking``, ``--feed``."""
    _rate(command, 100.0, "the control loop's rate, Hz, as for execute (default 100)")
    _tracking(command)
    _feed(command)


def _predict_parser(commands: argparse._SubParsersAction) -> None:
    predict = _command(
        commands,
        "predict",
        "predict the cut a trajectory CSV makes on the robot, before it moves",
        "Runs the plan through the closed-loop model of --robot (its dynamics, friction, "
        "actuator loops and limits) as spm-opt execute would run it, and judges the model's "
        "true cut as a run's; prints the report (markdown, or JSON with --json); exits 1 if "
        "the predicted run breaks a limit, leaves the tube or does not complete.",
    )
    _plan_file(predict)
    _problem_option(predict, "problem TOML whose robot and limits apply", paper=False)
    _model_robot(predict)
    _model_run(predict)
    predict.add_argument(
        "--highest-feed",
        action="store_true",
        help="when the predicted cut leaves the tube, find the highest feed that keeps it "
        "inside, within 0.05 by bisection (each feed tried is a prediction; the lines go to "
        "stderr; default: not searched)",
    )
    _json(predict)
    _other_problem(
        predict,
        "predict a plan made for another problem (or with no sidecar) under --problem's "
        "limits (default: refused)",
    )


def _compensate_parser(commands: argparse._SubParsersAction) -> None:
    compensate = _command(
        commands,
        "compensate",
        "correct a plan's goals for what its runs repeat, learned on the robot's model or a "
        "dry run",
        "Iterative learning control: the plan's stream is run (on the closed-loop model of "
        "--robot, as spm-opt predict runs it, or read from --dry-run's log), its joints' "
        "error against the plan filtered and taken off the next stream; the stream whose "
        "predicted cut is nearest the contour is written to --out as a plan, its sidecar "
        "saying what it was learned from. Run the written plan with spm-opt execute, "
        "predict or review like any other.",
    )
    _plan_file(compensate)
    _problem_option(compensate, "problem TOML whose robot and limits apply", paper=False)
    _out(compensate, "the compensated plan's CSV (its JSON sidecar beside it)")
    _model_robot(compensate)
    compensate.add_argument(
        "--iterations",
        type=int,
        default=3,
        metavar="N",
        help="corrections learned on the model, at least 1 (default 3; the first is the "
        "load's deflection fed forward)",
    )
    compensate.add_argument(
        "--dry-run",
        type=Path,
        metavar="LOG",
        help="learn one correction from this execution log of PLAN, or of a plan compensated "
        "from it, run with the tool retracted (default: learn on the model)",
    )
    _model_run(compensate)
    _other_problem(
        compensate,
        "compensate a plan made for another problem (or with no sidecar) under --problem's "
        "limits (default: refused)",
    )


def _slow_breakaways_parser(commands: argparse._SubParsersAction) -> None:
    slow = _command(
        commands,
        "slow-breakaways",
        "slow a plan where the robot's joints break away from rest, until its predicted run "
        "keeps the robot's limits",
        "A joint at rest sticks on its friction and breaks away late, faster than the plan: "
        "the run breaks acceleration and jerk limits the plan keeps. This lowers the pace "
        "around each instant a joint starts from rest (the start, landmark stops, "
        "reversals) to the highest pace, within 0.05, whose predicted run on --robot keeps "
        "every robot limit, the joints' speed within 95 % and acceleration and jerk within "
        "90 % of theirs (each pace tried is a prediction; the lines go to stderr), or, where "
        "no dip does, the whole plan to the highest uniform pace that does, and "
        "writes that plan to --out with its sidecar. Exits 1 if even a pace of 0.1 does not "
        "keep them (the slowest plan is written all the same).",
    )
    _plan_file(slow)
    _problem_option(slow, "problem TOML whose robot and limits apply", paper=False)
    _out(slow, "the slowed plan's CSV (its JSON sidecar beside it)")
    _model_robot(slow)
    slow.add_argument(
        "--half-width-s",
        type=float,
        default=1.5,
        metavar="S",
        help="plan time on each side of a breakaway over which the pace is lowered, s "
        "(default 1.5)",
    )
    _model_run(slow)
    _other_problem(
        slow,
        "slow a plan made for another problem (or with no sidecar) under --problem's limits "
        "(default: refused)",
    )


def _emulate_parser(commands: argparse._SubParsersAction) -> None:
    emulate = _command(
        commands,
        "emulate",
        "serve two emulated L54 actuators (Protocol 2.0) on a pseudo-terminal",
        "Prints the pseudo-terminal's path, for execute --backend dynamixel --port, and "
        "serves until Ctrl-C or SIGTERM; the actuators drive a simulated robot.",
    )
    _problem_option(emulate, "problem TOML whose robot is emulated", paper=True)
    _plant_robot(emulate, "robot TOML the emulated actuators drive (default: the problem's robot)")
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
    _trace(
        emulate,
        "save the plant's true state here (.npz) when serving ends (default: not saved)",
    )
