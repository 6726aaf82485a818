"""The commands' handlers, by name: each imports the library it needs only when it runs."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import logging
import math
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from spm_opt.base.errors import InputError
from spm_opt.base.output_paths import check_output_directory, check_output_file
from spm_opt.cli.parser import PLAN_MAX_RATE_HZ

if TYPE_CHECKING:
    from spm_opt.execution import ExecutionResult, ExecutionSettings
    from spm_opt.judge.report import Report
    from spm_opt.model.params import Robot
    from spm_opt.problem.problem import Problem
    from spm_opt.problem.trajectory import Trajectory
    from spm_opt.verify.predicted_cut import PredictedCut

_LOG = logging.getLogger("spm_opt.cli")  # the command line's logger, whichever module logs
_Loaded = TypeVar("_Loaded")


def _from_option(option: str, load: Callable[[Path], _Loaded], path: Path) -> _Loaded:
    """``load(path)``; an input error in the file names ``option``, the flag that gave it."""
    try:
        return load(path)
    except InputError as error:
        raise InputError(f"{option} {error}") from None


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
    from spm_opt.problem.problem import load_problem
    from spm_opt.problem.trajectory import Trajectory

    settings = _settings(
        ExecutionSettings,
        rate_hz=args.rate,
        approach=args.approach,
        feed=args.feed,
        max_feed=max(ExecutionSettings.max_feed, args.feed),
        max_hold_s=args.max_hold,
        other_problem=args.other_problem,
        tracking=args.tracking,
        current_reads_per_cycle=_current_reads(args),
    )
    if args.trace is not None and (args.backend != "sim" or args.trace.suffix != ".npz"):
        raise InputError(
            f"--trace {args.trace}: expected a file name ending in .npz, with --backend sim "
            "(the emulator's own --trace records the plant behind the Dynamixel backend)"
        )
    if args.plant_robot is not None and args.backend != "sim":
        raise InputError("--plant-robot: only with --backend sim (the real robot is the plant)")
    check_output_file(args.log, "--log")
    if args.trace is not None:
        check_output_file(args.trace, "--trace")
    problem = _from_option("--problem", load_problem, args.problem)
    plant = (
        None
        if args.plant_robot is None
        else _from_option("--plant-robot", load_robot, args.plant_robot)
    )
    trajectory = Trajectory.from_csv(args.plan)
    _check_predicted_cut(problem, trajectory, settings, args)
    keys = _keys_terminal(args.interactive)
    if args.backend == "sim":
        start = trajectory.position(trajectory.start_time)
        if args.start_deg is not None:
            start = np.radians(_pair(args.start_deg, "--start-deg", float))
        realtime = args.realtime or keys is not None or args.igtl is not None  # the wall clock
        backend = SimulatedRobot(
            problem.robot, start_rad=start, realtime=realtime, plant_robot=plant
        )
    else:
        from spm_opt.execution.dynamixel import DynamixelRobot

        if args.port is None:
            raise InputError("--port: required with --backend dynamixel (e.g. /dev/ttyUSB0)")
        ids = _pair(args.ids, "--ids", int)
        backend = DynamixelRobot(problem.robot.actuator, args.port, args.baud, ids)
    executor = Executor(problem, backend, settings)
    with contextlib.ExitStack() as stack:
        link = None
        if args.igtl is not None:
            from spm_opt.navigation.link import NavigationLink

            link = NavigationLink(problem, trajectory, executor, args.igtl_host, args.igtl)
            stack.enter_context(link)
            print(f"OpenIGTLink server on {args.igtl_host}:{link.server.port}", file=sys.stderr)
        with console(executor, problem, trajectory, sys.stderr, keys):
            result = executor.run(trajectory, args.log)
        if link is not None:
            link.finished(result)
    if args.trace is not None:
        backend.trace.save(args.trace)
    loop = result.statistics
    print(
        f"{args.log}: {result.samples} samples, {loop.achieved_rate_hz:.1f} Hz achieved, "
        f"period error p99 {loop.period_error_p99_ms:.3f} ms, {loop.overruns} overruns"
    )
    if not result.succeeded:
        raise GateFailed(_outcome(result))


def _navigate(args: argparse.Namespace) -> None:
    import numpy as np

    from spm_opt.navigation.flap import plan_flap
    from spm_opt.navigation.link import NavigationLink, ReceivedFlap
    from spm_opt.problem.problem import load_problem

    problem = _from_option("--problem", load_problem, args.problem)
    check_output_directory(args.out, "--out")

    def plan(
        flap: ReceivedFlap, planner: str, command_id: str, image_to_robot: np.ndarray
    ) -> tuple[Problem, Trajectory]:
        return plan_flap(problem, flap, planner, command_id, image_to_robot, args.out)

    port = 18944 if args.igtl is None else args.igtl
    with NavigationLink(problem, host=args.igtl_host, port=port, plan=plan) as link:
        args.out.mkdir(parents=True, exist_ok=True)
        print(
            f"OpenIGTLink server on {args.igtl_host}:{link.server.port}: send a POINT list "
            "and CMD_<id> 'PLAN [planner]' from 3D Slicer; Ctrl-C ends",
            file=sys.stderr,
        )
        try:
            threading.Event().wait()
        except KeyboardInterrupt:
            print("navigate: ended", file=sys.stderr)


def _check_predicted_cut(
    problem: Problem, trajectory: Trajectory, settings: ExecutionSettings, args: argparse.Namespace
) -> None:
    """Pre-flight's prediction: run ``trajectory`` through the closed-loop model of the
    problem's robot. A predicted cut outside the tube (with a contour tolerance) or a
    predicted run that does not complete refuses the run, or with
    ``--predicted-outside warn`` is said and run; a robot limit the predicted run breaks is
    said, or with ``--predicted-limits refuse`` refuses it."""
    from spm_opt.base.errors import PreflightError
    from spm_opt.verify.predicted_cut import predict_cut

    if trajectory.metadata.get("ignores_contour"):
        return
    _LOG.info("pre-flight: predicting the run on the closed-loop model of %s", problem.robot.name)
    predicted = predict_cut(problem, trajectory, settings=settings)
    if predicted.inside:
        _LOG.info("pre-flight: %s", predicted.summary())
    elif args.predicted_outside == "warn":
        _LOG.warning("%s; run all the same (--predicted-outside warn)", predicted.summary())
    else:
        raise PreflightError(
            f"plan refused: {predicted.summary()} (spm-opt predict --highest-feed finds the "
            "highest feed that keeps it inside; --predicted-outside warn runs it all the same)"
        )
    limits = predicted.limits_line()
    if limits and args.predicted_limits == "refuse":
        raise PreflightError(
            f"plan refused: {limits} (--predicted-limits warn runs it all the same)"
        )
    if limits:
        _LOG.warning(
            "%s; run all the same (--predicted-limits refuse refuses it; spm-opt "
            "slow-breakaways slows the plan where its joints break away)",
            limits,
        )


def _predict(args: argparse.Namespace) -> None:
    from spm_opt.model.params import load_robot
    from spm_opt.problem.problem import load_problem
    from spm_opt.problem.trajectory import Trajectory
    from spm_opt.verify.predicted_cut import predict_cut

    settings = _model_run_settings(args)
    problem = _from_option("--problem", load_problem, args.problem)
    robot = None if args.robot is None else _from_option("--robot", load_robot, args.robot)
    trajectory = Trajectory.from_csv(args.plan)
    if args.highest_feed:
        predicted = _report_highest_feed(problem, trajectory, robot, settings)
    else:
        predicted = predict_cut(problem, trajectory, robot, settings)
    if args.json:
        summary = {"summary": predicted.summary(), "limits": predicted.limits_line()}
        print(json.dumps(summary | predicted.report.to_dict(), indent=2))
    else:
        limits = predicted.limits_line()
        headline = predicted.summary() + (f"\n{limits}" if limits else "")
        print(f"{headline}\n\n{predicted.report.to_markdown()}", end="")
    fault = _faults("predicted", predicted.report)
    if fault or not predicted.inside:
        raise GateFailed(fault or predicted.summary())


def _compensate(args: argparse.Namespace) -> None:
    from spm_opt.model.params import load_robot
    from spm_opt.problem.problem import load_problem
    from spm_opt.problem.provenance import check_plan_made_for
    from spm_opt.problem.trajectory import Trajectory
    from spm_opt.verify.compensation import compensate, compensate_from_run

    if args.out.suffix != ".csv":
        raise InputError(f"--out {args.out}: expected a file name ending in .csv")
    if args.iterations < 1:
        raise InputError(f"--iterations {args.iterations}: expected a whole number of at least 1")
    if args.dry_run is not None and args.robot is not None:
        raise InputError("--robot: not with --dry-run (the dry run's robot is the model)")
    settings = _model_run_settings(args)
    check_output_file(args.out, "--out")
    problem = _from_option("--problem", load_problem, args.problem)
    trajectory = Trajectory.from_csv(args.plan)
    check_plan_made_for(problem, trajectory, args.other_problem)
    if args.dry_run is not None:
        compensation = compensate_from_run(problem, trajectory, args.dry_run)
    else:
        robot = None if args.robot is None else _from_option("--robot", load_robot, args.robot)
        compensation = compensate(problem, trajectory, robot, settings, args.iterations)
    for k, iteration in enumerate(compensation.iterations):
        cut = "" if iteration.deviation_mm is None else f"cut {iteration.deviation_mm:.3f} mm, "
        print(
            f"{'plan' if k == 0 else f'correction {k}'}: {cut}largest joint error "
            f"{math.degrees(iteration.largest_error_rad):.3f} deg"
        )
    compensation.plan.to_csv(args.out)
    scale = compensation.plan.metadata["compensation"]["scale"]
    kept = f"{compensation.kept} correction(s) kept" + (
        f", scaled by {scale:g} to keep the robot's limits" if scale != 1.0 else ""
    )
    predicted = "" if compensation.predicted is None else f"; {compensation.predicted.summary()}"
    print(f"{args.out}: {kept}{predicted}")


def _slow_breakaways(args: argparse.Namespace) -> None:
    from spm_opt.model.params import load_robot
    from spm_opt.problem.problem import load_problem
    from spm_opt.problem.provenance import check_plan_made_for
    from spm_opt.problem.trajectory import Trajectory
    from spm_opt.verify.breakaway import HALF_WIDTH_S, Slowed, slowed_for_breakaways

    if args.out.suffix != ".csv":
        raise InputError(f"--out {args.out}: expected a file name ending in .csv")
    if not (math.isfinite(args.half_width_s) and 0.1 <= args.half_width_s <= 10.0):
        raise InputError(
            f"--half-width-s {args.half_width_s:g}: expected a number of seconds from 0.1 to "
            f"10 (default {HALF_WIDTH_S:g})"
        )
    settings = _model_run_settings(args)
    check_output_file(args.out, "--out")
    problem = _from_option("--problem", load_problem, args.problem)
    trajectory = Trajectory.from_csv(args.plan)
    check_plan_made_for(problem, trajectory, args.other_problem)
    if "slowed" in trajectory.metadata:
        raise InputError(
            f"{args.plan}: already slowed (at its breakaways or throughout): slow the plan itself"
        )
    if "compensation" in trajectory.metadata:
        raise InputError(f"{args.plan}: compensated: slow the plan first, then compensate it")
    robot = None if args.robot is None else _from_option("--robot", load_robot, args.robot)

    def tried(slowed: Slowed) -> None:
        line = slowed.predicted.limits_line() or "keeps the robot's limits"
        print(f"pace {slowed.feed:.2f} {slowed.where}: {line}", file=sys.stderr, flush=True)

    slowed = slowed_for_breakaways(
        problem, trajectory, robot, settings, tried, half_width_s=args.half_width_s
    )
    slowed.trajectory.to_csv(args.out)
    print(
        f"{args.out}: pace {slowed.feed:.2f} {slowed.where}, {slowed.trajectory.duration:.2f}"
        f" s (the plan {trajectory.duration:.2f} s); {slowed.predicted.summary()}"
    )
    if not slowed.keeps_limits:
        raise GateFailed(slowed.predicted.limits_line() or slowed.predicted.summary())


def _model_run_settings(args: argparse.Namespace) -> ExecutionSettings:
    """The executor's settings a run on the closed-loop model takes from ``predict``'s and
    ``compensate``'s options."""
    from spm_opt.execution import ExecutionSettings

    return _settings(
        ExecutionSettings,
        rate_hz=args.rate,
        feed=args.feed,
        max_feed=max(ExecutionSettings.max_feed, args.feed),
        other_problem=args.other_problem,
        tracking=args.tracking,
    )


def _report_highest_feed(
    problem: Problem, trajectory: Trajectory, robot: Robot | None, settings: ExecutionSettings
) -> PredictedCut:
    """``predict --highest-feed``: the highest feed whose predicted cut stays in the tube,
    each feed tried on stderr; returns the prediction at ``settings``' feed."""
    from spm_opt.verify.predicted_cut import highest_feed_inside

    predictions: dict[float, PredictedCut] = {}

    def tried(feed: float, predicted: PredictedCut) -> None:
        predictions[feed] = predicted
        print(f"feed {feed:.2f}: {predicted.summary()}", file=sys.stderr, flush=True)

    found = highest_feed_inside(problem, trajectory, robot, settings, tried)
    if found is None:
        print("no feed down to 0.1 keeps the predicted cut in the tube", file=sys.stderr)
    else:
        print(
            f"highest feed that keeps the predicted cut in the tube: {found[0]:.2f}",
            file=sys.stderr,
        )
    return predictions[settings.feed]


SIMULATED_CURRENT_READS = 10
"""``execute --current-reads`` on the simulated robot by default: one read in each 1 ms
step of the plant at 100 Hz, whose mean is the period's current; reads there cost no bus
time."""


def _current_reads(args: argparse.Namespace) -> int:
    """``--current-reads``, or its default for the backend (sim: every step of the plant's
    at 100 Hz, fewer at higher rates; dynamixel: 0, the bus's time kept for the loop)."""
    if args.current_reads is not None:
        return args.current_reads
    if args.backend != "sim" or not args.rate > 0:
        return 0
    from spm_opt.execution.plant import PlantSettings

    return max(0, min(SIMULATED_CURRENT_READS, int(1.0 / (args.rate * PlantSettings.step_s))))


_SETTING_OPTIONS = {
    "current_reads_per_cycle": "--current-reads",
    "rate_hz": "--rate",
    "feed": "--feed",
    "max_feed": "--feed",
    "max_hold_s": "--max-hold",
    "tracking": "--tracking",
}
"""The execute option that sets each :class:`~spm_opt.execution.ExecutionSettings` field."""


def _settings(kind: type[ExecutionSettings], **values: object) -> ExecutionSettings:
    """The executor's settings from the options; a bad one named by its option."""
    try:
        return kind(**values)
    except InputError as error:  # name the option the user gave, not the setting
        setting = str(error).split(" = ")[0]
        raise InputError(f"{_SETTING_OPTIONS.get(setting, setting)}: {error}") from None


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
    from spm_opt.problem.problem import load_problem

    if args.plant_robot is not None:
        robot = _from_option("--plant-robot", load_robot, args.plant_robot)
    else:
        robot = _from_option("--problem", load_problem, args.problem).robot
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
    from spm_opt.studies.sweep.results import write_sweep_report
    from spm_opt.studies.sweep.runner import run_sweep
    from spm_opt.studies.sweep.spec import load_sweep_spec

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
    from spm_opt.studies.reproduce import reproduce

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
    from spm_opt.problem.problem import load_problem

    if args.out.suffix != ".csv":
        raise InputError(f"--out {args.out}: expected a file name ending in .csv")
    if args.rate is not None and not 0.0 < args.rate <= PLAN_MAX_RATE_HZ:
        raise InputError(
            f"--rate {args.rate}: expected a rate in Hz with 0 < rate <= {PLAN_MAX_RATE_HZ:g}"
        )
    check_output_file(args.out, "--out")
    get_planner(args.planner)
    problem = load_problem(args.problem)
    if args.predicted_reserve is None:
        trajectory = plan(problem, args.planner)
    else:
        trajectory = _plan_within_prediction(problem, args.planner, args.predicted_reserve)
    trajectory.to_csv(args.out, rate_hz=args.rate)
    print(f"{args.out}: {args.planner} plan, {trajectory.duration:.3f} s")


def _plan_within_prediction(problem: Problem, planner: str, robot_path: str) -> Trajectory:
    """``plan --predicted-reserve``: the plan, re-planned once with the reserve its
    predicted cut asks for if that cut leaves the tube; each prediction on stdout."""
    from spm_opt.model.params import load_robot
    from spm_opt.verify.predicted_reserve import plan_within_prediction

    robot = (
        _from_option("--predicted-reserve", load_robot, Path(robot_path)) if robot_path else None
    )
    kept = plan_within_prediction(problem, planner, robot)
    print(f"first plan: {kept.first.summary()}")
    if kept.replanned:
        print(
            f"re-planned keeping {kept.reserve_mm:.3f} mm for execution: {kept.predicted.summary()}"
        )
    elif not kept.first.inside:
        print(
            "not re-planned: the plan's own distance from the contour, not execution, "
            "takes the tube"
        )
    return kept.plan


def _evaluate(args: argparse.Namespace) -> None:
    from spm_opt.judge.evaluate import evaluate
    from spm_opt.problem.problem import load_problem
    from spm_opt.verify.executed_cut import evaluate_log, is_execution_log

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
    from spm_opt.base.files import write_atomically
    from spm_opt.problem.problem import load_problem
    from spm_opt.report.review_inputs import review_inputs
    from spm_opt.report.review_page import review_page
    from spm_opt.report.review_png import review_png
    from spm_opt.skull.surface import Skull

    check_output_directory(args.out, "--out")
    problem = load_problem(args.problem)
    predict_on = None
    if args.predict is not None:
        from spm_opt.model.params import load_robot

        predict_on = (
            problem.robot
            if args.predict == ""
            else _from_option("--predict", load_robot, Path(args.predict))
        )
    given = review_inputs(problem, args.plan, args.log, args.other_problem, args.trace, predict_on)
    skull = problem.skull if problem.skull is not None else Skull(surface=problem.surface)
    files = {
        args.out / "review.html": review_page(problem, skull, given),
        args.out / "review.png": review_png(problem, skull, given),
    }
    write_atomically(files)
    for path in files:
        print(path)


SINGLE_READ_WARNING = (
    "{logs}: the current is one read a control period, which aliases the velocity loop's "
    "answer to each goal step (at 100 Hz, as viscous friction of about -0.1 N·m·s/rad); "
    "log the runs to identify from with spm-opt execute --current-reads"
)
"""What ``identify`` says of logs read once a period (stderr and the report)."""


def _identify(args: argparse.Namespace) -> None:
    from spm_opt.base.files import write_atomically
    from spm_opt.identify.estimate import identify
    from spm_opt.identify.loop import estimate_loops, goal_rms
    from spm_opt.identify.report import prediction_figure, report_markdown
    from spm_opt.identify.robot_file import robot_file_text
    from spm_opt.identify.samples import check_log_rows, log_samples
    from spm_opt.identify.validate import (
        check_holdout,
        hold_out,
        joined,
        plan_period,
        prediction_rms,
    )
    from spm_opt.identify.velocity_replay import replay_bandwidth
    from spm_opt.problem.problem import load_problem
    from spm_opt.report.plots import to_png

    if args.out.suffix != ".toml":
        raise InputError(f"--out {args.out}: expected a robot file name ending in .toml")
    check_holdout(args.holdout)
    check_output_file(args.out, "--out")
    problem = _from_option("--problem", load_problem, args.problem)
    check_log_rows(args.logs)
    decimation, stretches, single_read = args.decimation, [], []
    for path in args.logs:
        samples = log_samples([path], args.cutoff_hz, decimation, args.min_speed)
        decimation = samples.decimation  # every log's as the first's
        single_read += samples.single_read_logs
        fitted, held = hold_out(samples, args.holdout, plan_period(path))
        stretches += [(fitted, False)] + ([(held, True)] if held is not None else [])
    fit = joined([part for part, held in stretches if not held])
    held_parts = [part for part, held in stretches if held]
    _LOG.info("identify: %d samples from %d logs; fitting", len(fit.q), len(args.logs))
    identification = identify(problem.robot, fit)
    loops = estimate_loops(args.logs, problem.robot)
    checked = [(f"fitted ({fit.duration_s:.1f} s)", fit)]
    if held_parts:
        held = joined(held_parts)
        if len(held) == 0:
            raise InputError(
                f"--holdout {args.holdout:g}: the held-out stretches have no sample where both "
                "joints move; hold out more, or 0"
            )
        checked.append((f"held out ({held.duration_s:.1f} s, not fitted)", held))
    if args.validate is not None:
        validation = log_samples([args.validate], args.cutoff_hz, decimation, args.min_speed)
        checked.append((f"{args.validate.name} (not fitted)", validation))
    _LOG.info("identify: replaying the logs through the identified model for the velocity loops")
    replay = replay_bandwidth(args.logs, loops.robot(identification.robot))
    loops = dataclasses.replace(loops, replay=replay)
    predictions = [
        (label, prediction_rms(problem.robot, part), prediction_rms(identification.robot, part))
        for label, part in checked
    ]
    figure = prediction_figure(problem.robot, identification.robot, stretches)
    on = "the fitted logs" if args.validate is None else f"{args.validate.name} (not fitted)"
    goal_logs = args.logs if args.validate is None else [args.validate]
    goals = [goal_rms(goal_logs, robot) for robot in (problem.robot, loops.robot(problem.robot))]
    actuator = problem.robot.actuator
    unit = actuator.current_unit_a  # one Present Current unit, A
    report = report_markdown(
        identification, problem.robot, predictions, float(actuator.current_map.torque(unit))
    )
    aliased = [SINGLE_READ_WARNING.format(logs=", ".join(single_read))] if single_read else []
    files = {
        args.out: robot_file_text(identification, loops, args.out.stem),
        args.out.with_suffix(".md"): "\n".join([report, *loops.markdown(*goals, on), *aliased, ""]),
        args.out.with_suffix(".png"): to_png(figure),
    }
    write_atomically(files)
    for path in files:
        print(path)
    for label, prior, identified in predictions:
        print(
            f"torque prediction RMS, {label}: prior {prior[0]:.4f}, {prior[1]:.4f} N·m; "
            f"identified {identified[0]:.4f}, {identified[1]:.4f} N·m",
            file=sys.stderr,
        )
    print(loops.summary(), file=sys.stderr)
    for line in aliased:
        _LOG.warning(line)


def _check_range(value: float, option: str, low: float, high: float) -> None:
    if not low <= value <= high:
        raise InputError(f"{option} {value:g}: allowed {low:g} to {high:g}")


def _calibrate(args: argparse.Namespace) -> None:
    import numpy as np

    from spm_opt.base.files import write_atomically
    from spm_opt.calibration.plan import calibration_plan
    from spm_opt.calibration.report import report_markdown, residual_figure
    from spm_opt.calibration.run import (
        CalibrationSettings,
        calibrate,
        choose_poses,
        logged_readings_raw,
        measurements,
    )
    from spm_opt.calibration.simulate import simulated_run
    from spm_opt.calibration.simulated_tracker import SimulatedTracker
    from spm_opt.execution.log import read_execution_log
    from spm_opt.model.params import load_robot, robot_toml
    from spm_opt.problem.problem import load_problem
    from spm_opt.report.plots import to_png
    from spm_opt.verify.motion_capture import read_capture_csv

    _check_range(args.poses, "--poses", 6, 400)
    _check_range(args.held_out, "--held-out", 1, 100)
    _check_range(args.marker_distance_mm, "--marker-distance-mm", 50.0, 1000.0)
    _check_range(args.tracker_fle_mm, "--tracker-fle-mm", 0.0, 5.0)
    _check_range(args.tracker_bias_mm, "--tracker-bias-mm", 0.0, 5.0)
    lab = args.log is not None or args.tracker is not None
    if lab and (args.log is None or args.tracker is None):
        raise InputError("--log and --tracker: give both (a lab's run), or neither (simulated)")
    if lab and args.plant_robot is not None:
        raise InputError("--plant-robot: only for a simulated calibration (without --log)")
    if args.write_plan is None and args.out is None:
        raise InputError("--out: required (the calibrated robot TOML), unless --write-plan")
    if args.out is not None and args.out.suffix != ".toml":
        raise InputError(f"--out {args.out}: expected a robot file name ending in .toml")
    for option, path in (("--out", args.out), ("--write-plan", args.write_plan)):
        if path is not None:
            check_output_file(path, option)
    problem = _from_option("--problem", load_problem, args.problem)
    settings = CalibrationSettings(
        poses=args.poses,
        held_out=args.held_out,
        marker_distance_mm=args.marker_distance_mm,
        seed=args.seed,
    )
    if args.write_plan is not None or not lab:
        poses, held = choose_poses(problem.robot, settings)
        plan = calibration_plan(problem, poses, held, settings.dwell_s, settings.settle_s)
    if args.write_plan is not None:
        if args.write_plan.suffix != ".csv":
            raise InputError(f"--write-plan {args.write_plan}: expected a name ending in .csv")
        plan.to_csv(args.write_plan)
        print(args.write_plan)
        return
    if lab:
        from spm_opt.calibration.tracker_files import read_tracker_file

        table, header = read_execution_log(args.log)
        track = read_tracker_file(args.tracker, body=args.body)
        tracker = f"{args.tracker.name}"
        data = args.log.read_bytes() + args.tracker.read_bytes()
    else:
        plant = (
            problem.robot
            if args.plant_robot is None
            else _from_option("--plant-robot", load_robot, args.plant_robot)
        )
        simulated = SimulatedTracker(
            marker_distance_mm=args.marker_distance_mm,
            fle_mm=args.tracker_fle_mm,
            bias_mm=args.tracker_bias_mm,
            seed=args.seed,
        )
        log_path = args.out.with_name(f"{args.out.stem}_run.csv")
        check_output_file(log_path, "--out")
        _LOG.info("calibrate: running %d poses on the simulated %s", len(poses), plant.name)
        table, header, text = simulated_run(problem, plan, plant, simulated, log_path)
        tracker_path = args.out.with_name(f"{args.out.stem}_tracker.csv")
        write_atomically({tracker_path: text})
        track = read_capture_csv(tracker_path)
        tracker = f"simulated (FLE {simulated.fle_mm:g} mm, bias {simulated.bias_mm:g} mm)"
        data = log_path.read_bytes() + text.encode()
    plan_record = header.get("plan", {}).get("calibration")
    if plan_record is None:
        raise InputError(f"log {args.log}: not a calibration run (its plan has no calibration)")
    table = logged_readings_raw(table, header)
    source = str(args.tracker or "tracker")
    fitted, tested = measurements(table, plan_record, track, args.marker_distance_mm * 1e-3, source)
    calibration = calibrate(fitted, tested, args.marker_distance_mm * 1e-3, tracker, data)
    robot = calibration.calibrated(problem.robot)
    files = {
        args.out: robot_toml(robot, args.out.stem, f"{problem.robot.name}, calibrated"),
        args.out.with_suffix(".md"): report_markdown(calibration, problem.robot.name),
        args.out.with_suffix(".png"): to_png(residual_figure(calibration)),
    }
    write_atomically(files)
    for path in files:
        print(path)
    zeros = np.degrees(calibration.result.geometry.encoder_zero)
    fitted_mm, held_mm = calibration.result.residual_rms_m * 1e3, calibration.held_out.rms_m * 1e3
    print(
        f"encoder zeros {zeros[0]:.4f}, {zeros[1]:.4f} deg; fit {fitted_mm:.4f} mm RMS, "
        f"held out {held_mm:.4f} mm RMS",
        file=sys.stderr,
    )


def _compare(args: argparse.Namespace) -> None:
    from spm_opt.problem.problem import load_problem
    from spm_opt.studies.comparison import progress_line, run_planners, write_comparison

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


COMMANDS: dict[str, Callable[[argparse.Namespace], None]] = {
    "reproduce": _reproduce,
    "plan": _plan,
    "compare": _compare,
    "evaluate": _evaluate,
    "identify": _identify,
    "calibrate": _calibrate,
    "review": _review,
    "execute": _execute,
    "navigate": _navigate,
    "predict": _predict,
    "compensate": _compensate,
    "slow-breakaways": _slow_breakaways,
    "emulate": _emulate,
    "sweep": _sweep,
    "cache": _cache,
}
"""Each command's handler, by the command's name."""


def optional_modules(args: argparse.Namespace) -> list[tuple[str, str]]:
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
