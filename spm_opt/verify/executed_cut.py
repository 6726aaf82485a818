"""The executed cut, judged: an execution log by the same rules as a plan.

:func:`evaluate_log` reads a log of :mod:`spm_opt.execution` (its CSV and the JSON header
beside it) and judges the run with :func:`spm_opt.judge.judge.judge`, the plan's own
judgement, against the problem's full contour tolerance:

- **Which rows.** From the first row of the plan phase to the log's end (the plan, then the
  settle, or the stop and the hold after a fault); the approach is no part of the cut.
  Rows whose read failed (every measured value empty) are left out and counted. A run that
  did not complete, or whose log a crash cut short (a header without an outcome), is
  judged all the same, and the report says so.
- **The cut** from the measured angles: contour deviation, landmark visits (searched on the
  samples, each measured on the straight segments to the nearest sample's neighbours, as
  the log does not know where the cut was between samples), coverage, backtracking. The
  tool speed is judged against the problem's limit times the feed in force, never less
  than 1: in the plan phase the largest feed logged over the last :data:`FEED_SPAN_S`
  (the tool lags the reference a little as the feed falls), outside it (the settle, the
  stop after a fault: no feed is logged) the largest feed logged in the run. A feed below
  1 does not tighten the limit: the problem's limit is what protects the cut, and a robot
  coming to rest in a hold, at a feed near 0, would break any limit scaled by it.
- **The robot** from the measured motion: joint range, speed (the measured velocity),
  acceleration and jerk (the measured velocity's derivatives by Savitzky–Golay filters:
  :mod:`spm_opt.verify.log_estimates`), torque and current (the measured current and the torque
  the current map gives for it), singularity margin. A step in acceleration shows as jerk:
  a log's ``max_acceleration_step_rad_s2`` is None. On the simulated robot driving
  ``prototype_plant.toml`` at 100 Hz (that problem's toppra, ruckig and cubic plans), the
  measured derivatives differ from the same filters on the plant's true velocity by at
  most 0.006 rad/s² and 0.15 rad/s³, RMS 0.002 and 0.04.
- **At the readings' resolution.** The report states how finely the readings resolve each
  judged figure (:class:`~spm_opt.verify.log_estimates.Resolution`: half a unit of the reading,
  carried through the filters and the kinematics). A rule whose limit is not above that
  resolution is not judged, and the report says so; the true state's report has no such
  limit.
- **Tracking:** the measured position less the reference (the plan at the logged plan
  time), its largest magnitude and RMS per joint over the plan phase.

With the plant's true state (``StateTrace``, from ``spm-opt execute --backend sim --trace``
or ``spm-opt emulate --trace``) the same judge runs on the true angles, rates and currents
interpolated at the log's times: the true cut is what the surgeon gets. Its joint speed is
the plant's largest between two rows (the trace's ``peak_speed_rad_s``): each goal is a step
the loops answer within the period, so the speed peaks between reads, at a phase that
depends on when the goal arrived (on the simulated robot driving ``prototype_plant.toml``,
toppra's plan of the hardware problem peaked at 1.454 rad/s between reads, 1.410 at them,
against a limit of 1.435). The true angles
lack the encoder offsets the measured ones carry (the position loops hold the encoders'
reading at the goal, so the measured cut can look better than the true one).

A log is judged under the problem it ran under (the header's ``problem`` fingerprint):
another gives a one-line :class:`~spm_opt.base.errors.InputError` unless ``other_problem``.
"""

from __future__ import annotations

import math
import zipfile
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import (
    MAX_HEADER_CHARS,
    MAX_TRACE_BYTES,
    check_file,
    excerpt,
)
from spm_opt.execution.log import header_path, read_execution_log
from spm_opt.execution.plant import StateTrace
from spm_opt.judge.judge import judge
from spm_opt.judge.limits import ROBOT_RULES, contour_tube, path_tolerance
from spm_opt.judge.motion import Motion
from spm_opt.judge.report import Report, Violation
from spm_opt.model.params import DEG, MM
from spm_opt.problem.problem import Problem
from spm_opt.problem.provenance import check_made_for, log_hint
from spm_opt.verify.log_estimates import (
    ACCELERATION_SPAN_S,
    JERK_SPAN_S,
    Resolution,
    log_resolution,
    smoothed_derivatives,
    unresolved_rules,
)

FEED_SPAN_S = 0.1
"""How long a fall of the feed takes to lower the feed in force, s."""

JOINTS = ("theta1", "theta2")
MEASURED = tuple(
    f"{kind}_{joint}_{unit}"
    for kind, unit in (("position", "rad"), ("velocity", "rad_s"), ("current", "a"))
    for joint in JOINTS
) + tuple(f"torque_{joint}_nm" for joint in JOINTS)
"""The columns a read fills: all empty in a row whose read failed."""

REFERENCE = tuple(f"reference_{joint}_rad" for joint in JOINTS)
LATE_GOAL_REACH_S = JERK_SPAN_S
"""How near a late goal a robot limit's worst instant lies for the judge to name the two
together, s: the jerk filter's span, over which one uneven goal step spreads."""
TIME_TOLERANCE_S = 1e-6
"""How far a trace may fall short of the log's first and last times, s (the log writes
times to the ns)."""


@dataclass(frozen=True)
class ExecutionReport(Report):
    """A :class:`~spm_opt.judge.report.Report` of an executed run, and how it went.

    Attributes
    ----------
    angles : str
        Whose angles were judged: "measured" (the encoders') or "true" (the plant's).
    completed : bool
        The run ran its plan to the end (False after a fault, or a log a crash cut short).
    outcome : str
        The header's reason, or why there is none.
    rows_judged : int
        Rows from the plan's start to the log's end that were judged.
    failed_reads_skipped : int
        Rows in that stretch whose read failed (no measured values): left out.
    max_tracking_error_deg, rms_tracking_error_deg : list of float, deg
        The angles less the reference (the plan at the logged plan time), per joint, over
        the plan phase.
    smoothing_spans_s : list of float, s
        The spans of the filters that gave acceleration and jerk.
    resolution : dict or None
        How finely the readings resolve each judged figure (:class:`Resolution`'s
        fields); None for the plant's true state, which has no rounding.
    not_judged : list of str
        The rules left out because the readings cannot resolve their limits, each with
        why.
    limit_shares : dict of str to float
        Each joint's largest speed, acceleration and jerk over the judged rows as a share of
        its limit, by the judged figures ("theta1 jerk": 0.95); a rule without a limit is
        left out.
    late_goals : int
        Goals that reached the actuators late (the header's ``cycle_timing``:
        :data:`~spm_opt.execution.cycle.LATE_GOAL_S`); ``latest_goal_ms`` the latest, ms.
    after_late_goals : dict of str to str
        The robot limits broken (:data:`~spm_opt.judge.limits.ROBOT_RULES`) whose worst
        instant lies within :data:`LATE_GOAL_REACH_S` of a late goal: where the loop's
        timing, not the plan or the model, is the likely cause; each with the nearest
        such goal.
    """

    angles: str = "measured"
    completed: bool = True
    outcome: str = ""
    rows_judged: int = 0
    failed_reads_skipped: int = 0
    max_tracking_error_deg: list[float] = field(default_factory=list)
    rms_tracking_error_deg: list[float] = field(default_factory=list)
    smoothing_spans_s: list[float] = field(
        default_factory=lambda: [ACCELERATION_SPAN_S, JERK_SPAN_S]
    )
    resolution: dict[str, float] | None = None
    not_judged: list[str] = field(default_factory=list)
    limit_shares: dict[str, float] = field(default_factory=dict)
    late_goals: int = 0
    latest_goal_ms: float = 0.0
    after_late_goals: dict[str, str] = field(default_factory=dict)

    _NOT_IN_TABLE = (
        *Report._NOT_IN_TABLE,
        "resolution",
        "not_judged",
        "limit_shares",
        "after_late_goals",
    )

    @property
    def accepted(self) -> bool:
        """Whether the judge accepts the run: no limit is violated and it completed."""
        return super().accepted and self.completed

    def _notes(self) -> list[str]:
        notes = super()._notes()
        if self.angles == "true":
            notes.append(
                "The plant's true angles: without the encoder offsets the measured ones carry."
            )
        if not self.completed:
            notes.append(f"The run did not complete ({self.outcome}).")
        if self.failed_reads_skipped:
            notes.append(f"{self.failed_reads_skipped} row(s) whose read failed are left out.")
        if self.resolution is not None:
            notes.append(_resolution_line(self.resolution))
        notes += [f"Not judged, {why}." for why in self.not_judged]
        if self.late_goals:
            notes.append(
                f"{self.late_goals} goal(s) reached the actuators late (the latest "
                f"{self.latest_goal_ms:.1f} ms): the control computer's loop lost time"
                + (
                    "; broken near one: "
                    + ", ".join(f"{k} ({v})" for k, v in self.after_late_goals.items())
                    + "."
                    if self.after_late_goals
                    else "."
                )
            )
        return notes


def _resolution_line(resolution: dict[str, float]) -> str:
    """The readings' resolution, as one sentence."""
    r = Resolution(**resolution)
    return (
        "Resolution of the readings (±): "
        f"angle {r.position_deg:.2g} deg, speed {r.speed_rad_s:.2g} rad/s, "
        f"acceleration {r.acceleration_rad_s2:.2g} rad/s^2, jerk {r.jerk_rad_s3:.2g} rad/s^3, "
        f"current {r.current_a * 1000:.3g} mA, torque {r.torque_nm:.2g} N*m, "
        f"tool speed {r.tool_speed_mm_s:.2g} mm/s, cut {r.cut_mm:.2g} mm."
    )


@dataclass(frozen=True)
class LogReports:
    """The judgement of a run: of the measured angles, and of the plant's true ones when
    a trace was given (else None)."""

    measured: ExecutionReport
    true: ExecutionReport | None


@dataclass(frozen=True)
class _Run:
    """The judged rows of a log: times (N,), s; whether each is in the plan phase; the
    references (N, 2), rad; the feed in force (N,); the measured values by column."""

    t: np.ndarray
    in_plan: np.ndarray
    reference: np.ndarray
    feed: np.ndarray
    measured: dict[str, np.ndarray]
    period_s: float
    skipped: int
    header: dict[str, Any]


def is_execution_log(path: str | Path) -> bool:
    """Whether the CSV at ``path`` is an execution log rather than a trajectory: its first
    line names a log's ``time_s`` or ``phase`` column (False if it cannot be read, or is
    no regular file: a pipe's reading could block)."""
    if not Path(path).is_file():
        return False
    try:
        with open(path, encoding="utf-8") as file:
            columns = file.readline(MAX_HEADER_CHARS).strip().split(",")
    except (OSError, UnicodeDecodeError):
        return False
    return "time_s" in columns or "phase" in columns


def evaluate_log(
    problem: Problem,
    log: str | Path,
    trace: str | Path | None = None,
    *,
    other_problem: bool = False,
) -> LogReports:
    """Judge the run an execution log records (see the module's docstring).

    Parameters
    ----------
    problem : Problem
        The problem the run ran under.
    log : path
        The log's CSV; its JSON header lies beside it.
    trace : path, optional
        The plant's true state (``.npz``) over the run: then the true cut is judged too.
    other_problem : bool
        Judge the log under ``problem`` though it ran under another.
    """
    run = _read_run(Path(log), problem, other_problem)
    measured = run.measured
    q = np.column_stack([measured[f"position_{j}_rad"] for j in JOINTS])
    qd = np.column_stack([measured[f"velocity_{j}_rad_s"] for j in JOINTS])
    current = np.column_stack([measured[f"current_{j}_a"] for j in JOINTS])
    torque = np.column_stack([measured[f"torque_{j}_nm"] for j in JOINTS])
    judged = _judge(problem, run, q, qd, current, torque, "measured")
    if trace is None:
        return LogReports(judged, None)
    state = _true_state(Path(trace), run)
    current = state["current_a"]
    torque = problem.robot.actuator.current_map.torque(current)
    true = _judge(
        problem,
        run,
        state["position_rad"],
        state["velocity_rad_s"],
        current,
        torque,
        "true",
        state["peak_speed_rad_s"],
    )
    return LogReports(judged, true)


def tracking_error(angles: np.ndarray, reference: np.ndarray) -> tuple[list[float], list[float]]:
    """The largest magnitude and the RMS, deg, per joint of ``angles`` less ``reference``
    (N, 2), rad."""
    error = (angles - reference) / DEG
    return np.max(np.abs(error), axis=0).tolist(), np.sqrt(np.mean(error**2, axis=0)).tolist()


def _judge(
    problem: Problem,
    run: _Run,
    q: np.ndarray,
    qd: np.ndarray,
    current: np.ndarray,
    torque: np.ndarray,
    angles: str,
    peak_speed: np.ndarray | None = None,
) -> ExecutionReport:
    """One judgement of the run's rows with these angles, rates, currents and torques (and
    the joints' peak speeds between them, where known)."""
    qdd, jerk = smoothed_derivatives(run.t, qd, run.period_s)
    header = run.header
    late = _late_goals(header)
    plan = header.get("plan") or {}
    tube = contour_tube(problem, executed=True)  # the reserve is the executed cut's
    path = path_tolerance(problem, executed=True)
    resolution, unresolved = None, {}
    if angles == "measured":
        resolution = log_resolution(problem, q, run.period_s)
        unresolved = unresolved_rules(resolution, _judged_limits(problem, tube, path))
    motion = Motion(run.t, q, qd, qdd, jerk, torque, current, peak_speed)
    report = judge(
        problem,
        motion,
        tube,
        path,
        planner=plan.get("planner"),
        duration=float(run.t[-1] - run.t[0]),
        feed=run.feed,
        between_samples=True,
        contour_judged=not plan.get("ignores_contour", False),
        unjudged=frozenset(unresolved),
    )
    largest, rms = tracking_error(q[run.in_plan], run.reference[run.in_plan])
    completed = bool(header.get("completed", False))
    if "completed" in header:
        outcome = str(header.get("reason", ""))
    else:
        outcome = "no outcome in its header: the log was cut short, by a crash?"
    return ExecutionReport(
        **{f.name: getattr(report, f.name) for f in fields(Report)},
        angles=angles,
        completed=completed,
        outcome=outcome,
        rows_judged=len(run.t),
        failed_reads_skipped=run.skipped,
        max_tracking_error_deg=largest,
        rms_tracking_error_deg=rms,
        resolution=None if resolution is None else resolution.to_dict(),
        not_judged=list(unresolved.values()),
        limit_shares=joint_limit_shares(problem, motion),
        late_goals=late.count,
        latest_goal_ms=1000.0 * late.latest_s,
        after_late_goals=_after_late_goals(report.violations, late.first),
    )


@dataclass(frozen=True)
class _LateGoals:
    """A log header's ``cycle_timing.late_goals``: how many, the latest (s) and the first
    ones listed as (cycle's time, late by) rows (k, 2), s."""

    count: int
    latest_s: float
    first: np.ndarray


def _late_goals(header: dict[str, Any]) -> _LateGoals:
    """The late goals ``header`` records (none in a log from before they were recorded);
    a damaged entry is an :class:`InputError`."""
    timing = header.get("cycle_timing")
    late = timing.get("late_goals") if isinstance(timing, dict) else None
    if late is None:
        return _LateGoals(0, 0.0, np.zeros((0, 2)))
    try:
        return _LateGoals(
            int(late["count"]),
            float(late["latest_s"]),
            np.asarray(late["first"], dtype=float).reshape(-1, 2),
        )
    except (TypeError, KeyError, ValueError) as error:
        raise InputError(
            f"log header: cycle_timing.late_goals: expected count, latest_s and first "
            f"([time, late] pairs) ({type(error).__name__}: {error})"
        ) from None


def _after_late_goals(violations: list[Violation], goals: np.ndarray) -> dict[str, str]:
    """The robot limits among ``violations`` whose worst instant lies within
    :data:`LATE_GOAL_REACH_S` of one of the late ``goals`` ((k, 2): cycle's time, late by,
    s), each with the nearest such goal: when, from the worst instant, and how late."""
    named = {}
    for violation in violations:
        if violation.rule not in ROBOT_RULES or len(goals) == 0:
            continue
        away = goals[:, 0] - violation.time_s
        nearest = int(np.argmin(np.abs(away)))
        if abs(away[nearest]) <= LATE_GOAL_REACH_S:
            named[violation.limit] = (
                f"a goal {1000 * goals[nearest, 1]:.1f} ms late, {away[nearest]:+.3f} s from "
                "its worst"
            )
    return named


def joint_limit_shares(problem: Problem, motion: Motion) -> dict[str, float]:
    """Each joint's largest speed (``motion.joint_speed()``), acceleration and jerk as a
    share of its limit in ``problem``, keyed as the judge names them ("theta2 jerk"); a
    figure without a limit is left out."""
    limits = problem.limits
    if len(motion.t) == 0:
        return {}
    figures = {
        "speed": (motion.joint_speed(), limits.max_joint_speed),
        "acceleration": (motion.qdd, limits.max_joint_acceleration),
        "jerk": (motion.jerk, limits.max_joint_jerk),
    }
    return {
        f"theta{joint + 1} {figure}": float(np.max(np.abs(values[:, joint]))) / limit
        for figure, (values, limit) in figures.items()
        if limit is not None
        for joint in range(2)
    }


def _judged_limits(problem: Problem, tube: float | None, path: float) -> dict[str, float | None]:
    """The smallest limit of each rule judged on an estimate from the readings, in the
    rule's unit (None: not limited)."""
    limits, actuator = problem.limits, problem.robot.actuator
    tool_speed = limits.max_tool_speed
    return {
        "joint speed": limits.max_joint_speed,
        "joint acceleration": limits.max_joint_acceleration,
        "joint jerk": limits.max_joint_jerk,
        "actuator torque": float(np.min(problem.max_joint_torque)),
        "motor current": actuator.continuous_current_a,
        "tool speed": None if tool_speed is None else tool_speed / MM,
        "contour deviation": None if tube is None else tube / MM,
        "landmark visit": path / MM,
        "coverage": path / MM,
        "backtracking": path / MM,
    }


def _read_run(path: Path, problem: Problem, other_problem: bool) -> _Run:
    """The log's judged rows, each checked; one-line :class:`InputError` on a bad log."""
    table, header = read_log_checked(path)
    check_made_for(
        problem, header, "log", other_problem, refused=f"log {path} refused", hint=log_hint("judge")
    )
    phase = table["phase"].astype(str).to_numpy()
    plan_rows = np.flatnonzero(phase == "plan")
    if plan_rows.size == 0:
        raise InputError(f"log {path}: no plan rows (the run stopped before its plan began)")
    rows = table.iloc[plan_rows[0] :]
    phase = phase[plan_rows[0] :]
    in_plan = phase == "plan"
    lines = rows.index.to_numpy() + 2  # the CSV's line of each row
    t = _numbers(rows, "time_s", path, lines, np.ones(len(rows), bool))
    if np.any(np.diff(t) <= 0.0):
        bad = int(np.argmax(np.diff(t) <= 0.0)) + 1
        raise InputError(f"log {path}: line {lines[bad]}: time_s does not increase")
    feed = _numbers(rows, "feed", path, lines, in_plan)
    reference = np.column_stack([_numbers(rows, c, path, lines, in_plan) for c in REFERENCE])
    values = {c: pd.to_numeric(rows[c], errors="coerce").to_numpy(float) for c in MEASURED}
    empty = np.column_stack([np.isnan(v) for v in values.values()])
    read = ~np.all(empty, axis=1)
    broken = read & np.any(~np.isfinite(np.column_stack(list(values.values()))), axis=1)
    if np.any(broken):
        row = int(np.argmax(broken))
        column = next(c for c in MEASURED if not np.isfinite(values[c][row]))
        raise InputError(
            f"log {path}: line {lines[row]}: {column} is {_shown(rows[column].iloc[row])} "
            "though the row's read did not fail (its other measured values are there)"
        )
    if np.sum(read) < 2:
        raise InputError(f"log {path}: fewer than 2 rows with measured values from the plan on")
    settings = header.get("settings") or {}
    rate = settings.get("rate_hz")
    period = 1.0 / rate if rate else float(np.median(np.diff(t[read])))
    return _Run(
        t=t[read],
        in_plan=in_plan[read],
        reference=reference[read],
        feed=_feed_in_force(feed, in_plan, period)[read],
        measured={c: v[read] for c, v in values.items()},
        period_s=period,
        skipped=int(np.sum(~read)),
        header=header,
    )


def read_log_checked(path: Path) -> tuple[pd.DataFrame, dict[str, Any]]:
    """An execution log's table and its header, checked to be there and of the kind
    ``spm-opt execute`` writes; one-line :class:`InputError` otherwise."""
    table, header = read_execution_log(path)
    if not header:
        raise InputError(
            f"log {path}: no header {header_path(path).name} beside it (spm-opt execute "
            "writes the two together)"
        )
    _check_header(path, header)
    return table, header


def _check_header(path: Path, header: dict[str, Any]) -> None:
    """Refuse a header whose parts the judge reads are of the wrong kind (a JSON file of
    another kind beside the log): ``plan`` and ``settings`` objects, the loop's rate
    positive, the clock's origin a number."""
    settings = header.get("settings") or {}
    wrong = [
        (key, header[key])
        for key in ("plan", "settings")
        if not isinstance(header.get(key) or {}, dict)
    ]
    if isinstance(settings, dict) and not _number_or_none(settings.get("rate_hz"), positive=True):
        wrong.append(("settings.rate_hz", settings["rate_hz"]))
    if not _number_or_none(header.get("clock_origin_s")):
        wrong.append(("clock_origin_s", header["clock_origin_s"]))
    if wrong:
        key, value = wrong[0]
        raise InputError(
            f"log {path}: its header {header_path(path).name}: {key} = {excerpt(value)}: not "
            "as spm-opt execute writes it; is it this log's header?"
        )


def _number_or_none(value: Any, positive: bool = False) -> bool:
    """Whether ``value`` is None or a finite number (positive, if asked)."""
    if value is None:
        return True
    number = isinstance(value, int | float) and not isinstance(value, bool)
    return number and math.isfinite(value) and (value > 0 or not positive)


def _numbers(
    rows: pd.DataFrame, column: str, path: Path, lines: np.ndarray, needed: np.ndarray
) -> np.ndarray:
    """A column as floats; a value that is not a finite number where ``needed`` is an
    error naming its line."""
    values = pd.to_numeric(rows[column], errors="coerce").to_numpy(float)
    bad = needed & ~np.isfinite(values)
    if np.any(bad):
        row = int(np.argmax(bad))
        raise InputError(
            f"log {path}: line {lines[row]}: {column} is {_shown(rows[column].iloc[row])}, "
            "expected a number"
        )
    return values


def _shown(value: Any) -> str:
    """A CSV value for a message: empty and NaN alike are "empty or NaN"."""
    return "empty or NaN" if pd.isna(value) else repr(str(value))


def _feed_in_force(feed: np.ndarray, in_plan: np.ndarray, period_s: float) -> np.ndarray:
    """The feed the tool speed limit is scaled by at each row (see the module's
    docstring): at least 1; in the plan phase the largest feed over the last
    :data:`FEED_SPAN_S`, elsewhere the largest feed logged."""
    width = max(1, int(round(FEED_SPAN_S / period_s)) + 1)
    recent = pd.Series(np.where(in_plan, feed, np.nan)).rolling(width, min_periods=1).max()
    force = np.where(in_plan, recent.to_numpy(), np.nanmax(feed[in_plan]))
    return np.maximum(force, 1.0)


def _trace_shaped(trace: dict[str, np.ndarray]) -> bool:
    """Whether a trace's arrays are those :class:`StateTrace` saves: numbers, the times
    (N,), the rest (N, 2)."""
    shapes = {name: (len(trace["time_s"]),) + (() if name == "time_s" else (2,)) for name in trace}
    return all(
        trace[name].shape == shape and np.issubdtype(trace[name].dtype, np.number)
        for name, shape in shapes.items()
    )


def _true_state(path: Path, run: _Run) -> dict[str, np.ndarray]:
    """The plant's true position, velocity and current (N, 2) at the run's times, and its
    peak speeds since the row before (one period before the first), from a
    :class:`StateTrace` file on the log's clock."""
    origin = run.header.get("clock_origin_s")
    if origin is None:
        raise InputError("--trace: the log's header has no clock_origin_s to align it with")
    check_file(path, "a trace of the plant's state (.npz)", MAX_TRACE_BYTES)
    try:
        trace = StateTrace.load(path, float(origin))
        if not _trace_shaped(trace):
            raise ValueError("not a trace's arrays")
    except (OSError, EOFError, ValueError, TypeError, KeyError, zipfile.BadZipFile):
        raise InputError(
            f"trace {path}: not a trace of the plant's state (an .npz of "
            f"{', '.join(StateTrace.FIELDS)}, as spm-opt execute --backend sim --trace and "
            "spm-opt emulate --trace write)"
        ) from None
    times = trace["time_s"]
    first, last = run.t[0], run.t[-1]
    if len(times) < 2 or times[0] > first + TIME_TOLERANCE_S or times[-1] < last - TIME_TOLERANCE_S:
        span = f"{times[0]:.3f} to {times[-1]:.3f} s" if len(times) else "no time"
        raise InputError(
            f"trace {path}: covers {span} of the log's clock, not the judged rows' "
            f"{first:.3f} to {last:.3f} s; is it this run's trace?"
        )
    state = {
        name: np.column_stack([np.interp(run.t, times, trace[name][:, j]) for j in range(2)])
        for name in ("position_rad", "velocity_rad_s", "current_a")
    }
    between = _peaks_between(times, trace["peak_speed_rad_s"], run.t, run.period_s)
    state["peak_speed_rad_s"] = np.maximum(np.abs(state["velocity_rad_s"]), between)
    return state


def _peaks_between(
    times: np.ndarray, peaks: np.ndarray, rows: np.ndarray, period_s: float
) -> np.ndarray:
    """The largest of the trace's ``peaks`` (n, 2), sampled at ``times`` (n,), s, over each
    of ``rows``' spans (N,), s: after the row before, up to and at the row (the first's
    begins one ``period_s`` before it); 0 for a span no sample falls in (N, 2)."""
    bounds = np.searchsorted(times, np.concatenate([[rows[0] - period_s], rows]), side="right")
    largest = np.zeros((len(rows), 2))
    spans = np.flatnonzero(bounds[1:] > bounds[:-1])
    if len(spans):  # an empty span has no width, so each span ends where the next begins
        largest[spans] = np.maximum.reduceat(peaks[: bounds[-1]], bounds[spans], axis=0)
    return largest
