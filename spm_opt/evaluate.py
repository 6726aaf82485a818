"""The one evaluator: every trajectory measured the same way, on a fine time grid.

A planner's own claims are never reported; these figures are. What each limit means and
how much the evaluator allows beyond it is :mod:`spm_opt.limits`' table: 0.5 % of every
rate-type limit, nothing beyond the joint range and the singularity margin. Besides the
limits, a clean plan cuts the contour: it visits every landmark in order within the path
tolerance (the contour tolerance), sweeps the whole contour inside the tube with no
stretch left out, and never backtracks along it by more than the path tolerance. A plan's
tube is the contour tolerance less the problem's execution reserve, an executed cut's the
whole (:func:`spm_opt.limits.contour_tube`). A plan
whose metadata say ``ignores_contour`` (an excitation plan for identification) is judged
by the robot's limits alone: its cut figures are measured, not judged.

One function, :func:`judge`, judges a motion sampled on a grid (:class:`Motion`): a plan's
here, an executed run's (its log, and the plant's true state) in
:mod:`spm_opt.evaluate_execution`.

A trajectory measured once is not measured again for the same problem object, rate and
landmark times while it lives: a planner that checks its own plan (the optimal-control
planners do) leaves the report for whoever evaluates the plan next (a comparison, a sweep
task; 48 ms of a 0.22 s minimum-time plan of the paper's flap).
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import weakref
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from spm_opt.bounds import duration_lower_bound
from spm_opt.contour import row_lengths, surface_speed
from spm_opt.hold_room import hold_checks
from spm_opt.limits import ROBOT, RULES, contour_tube, path_tolerance
from spm_opt.model import dynamics, kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.problem import Problem
from spm_opt.provenance import check_plan_made_for
from spm_opt.report.markdown import markdown_table
from spm_opt.skull.depth import depth_rates
from spm_opt.trajectory import Trajectory

DEFAULT_RATE_HZ = 1000.0

_LOG = logging.getLogger(__name__)

TUBE_RULES = frozenset(("contour deviation", "landmark visit", "coverage", "backtracking"))
"""The rules whose limit is the cut's tube (:func:`spm_opt.limits.path_tolerance`)."""


@dataclass(frozen=True)
class Violation:
    """One limit broken: the worst value, the limit (``allowed``, before the evaluator's
    tolerance) and when (units in ``unit``); ``rule`` names its entry in
    :data:`spm_opt.limits.RULES`. ``reserve`` (in ``unit``), when not 0, says the limit is
    a plan's contour tube: the contour tolerance less this much kept for execution."""

    limit: str
    worst: float
    allowed: float
    unit: str
    time_s: float
    rule: str
    reserve: float = 0.0

    def __str__(self) -> str:
        limit = f"limit {self.allowed:.4g} {self.unit}"
        if self.reserve:
            limit += (
                f": the plan's tube, {self.allowed + self.reserve:.4g} {self.unit} less "
                f"{self.reserve:.4g} {self.unit} kept for execution"
            )
        return f"{self.limit}: {self.worst:.4g} {self.unit} at t = {self.time_s:.3f} s ({limit})"


@dataclass(frozen=True)
class Report:
    """What the evaluator measured. Units are in the names; per-joint values are lists.

    Torques are the model's inverse dynamics with exact friction, as the actuators deliver
    them (with their reflected rotor inertia and gear efficiency, when the robot has them).
    ``torque_margin`` is 1 − peak / continuous torque per actuator, ``current_margin`` the
    same for the motor current the actuator's current map gives; ``energy_j`` is
    ∫ Σ|τ·θ̇| dt (the mechanical work the actuators put in, braking counted as work too)
    and ``effort_n2m2s`` is ∫ τᵀτ dt. ``duration_lower_bound_s`` is the shortest time the
    limits allow along the contour (:mod:`spm_opt.bounds`). ``max_acceleration_step_rad_s2``
    is the largest jump of q̈ (from rest at the start, to rest at the end, or between
    pieces): an unbounded jerk that the polynomials' own jerk does not show; with a jerk
    limit, a step larger than what that jerk reaches in one grid interval is a violation
    (None, "—": not measured, as of an executed run, whose smoothed jerk shows any step).
    """

    planner: str | None
    duration_s: float
    peak_joint_speed_rad_s: list[float]
    joint_speed_limit_rad_s: float
    peak_joint_acceleration_rad_s2: list[float]
    rms_jerk_rad_s3: list[float]
    max_acceleration_step_rad_s2: list[float] | None
    max_contour_deviation_mm: float
    rms_contour_deviation_mm: float
    max_tool_speed_mm_s: float
    mean_tool_speed_mm_s: float
    tool_speed_cv: float
    landmark_errors_mm: list[dict[str, Any]]
    max_landmark_error_mm: float
    coverage_gap_mm: float
    max_backtrack_mm: float
    min_singularity_margin: float
    contour_length_mm: float
    duration_lower_bound_s: float
    duration_over_lower_bound: float
    peak_torque_nm: list[float]
    rms_torque_nm: list[float]
    torque_margin: list[float]
    peak_current_a: list[float]
    current_margin: list[float]
    energy_j: float
    effort_n2m2s: float
    violations: list[Violation] = field(default_factory=list)
    contour_judged: bool = True
    max_tool_incidence_deg: float | None = None
    max_depth_speed_mm_s: float | None = None
    max_depth_acceleration_mm_s2: float | None = None

    _NOT_IN_TABLE: ClassVar[tuple[str, ...]] = (
        "planner",
        "violations",
        "landmark_errors_mm",
        "contour_judged",
    )
    """Fields the markdown's table leaves out (shown otherwise, or not at all)."""

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON; violations as dicts."""
        data = asdict(self)
        data["violations"] = [asdict(v) for v in self.violations]
        return data

    def to_markdown(self) -> str:
        """The report as a two-column markdown table, then the violations."""
        rows = [("planner", self.planner or "(unknown)")]
        for key, value in self.to_dict().items():
            if key in self._NOT_IN_TABLE:
                continue
            rows.append((key, _format(value)))
        for visit in self.landmark_errors_mm:
            rows.append(
                (
                    f"landmark error {visit['landmark']} at {visit['time_s']:.3f} s, mm",
                    _format(visit["error_mm"]),
                )
            )
        lines = [*markdown_table(("figure", "value"), rows), "", *self._notes()]
        if self.violations:
            lines.append(f"**{len(self.violations)} violation(s):**")
            lines += [f"- {v}" for v in self.violations]
        else:
            lines.append("No limit is violated.")
        return "\n".join(lines) + "\n"

    def _notes(self) -> list[str]:
        """Lines between the table and the violations."""
        if self.contour_judged:
            return []
        return ["The plan ignores the contour: only the robot's limits are judged."]


def _format(value: Any) -> str:
    if value is None:
        return "—"
    if isinstance(value, list):
        return ", ".join(_format(v) for v in value)
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _peaks(values: np.ndarray) -> np.ndarray:
    """Largest magnitude in each column of ``values`` (N, joints), in their units."""
    return np.array([np.max(np.abs(column)) for column in values.T])


def _time_mean(values: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Time average over the grid (trapezoid rule), per column, each column on its own
    (numpy sums a contiguous 1-D array pairwise, several times quicker than down a 2-D
    array's rows, and as close or closer)."""
    if values.ndim == 1:
        return np.trapezoid(values, t) / (t[-1] - t[0])
    return np.array([_time_mean(np.ascontiguousarray(column), t) for column in values.T])


def _joint_sum(values: np.ndarray) -> np.ndarray:
    """The sum (N,) over both joints of ``values`` (N, 2): ``np.sum(values, axis=1)``'s
    values, without its slow reduction over two."""
    return values[:, 0] + values[:, 1]


_MEASURED: weakref.WeakKeyDictionary[Trajectory, tuple[Problem, tuple, Report]] = (
    weakref.WeakKeyDictionary()
)
"""Each living trajectory's last report, with the problem object and the (rate, landmark
times) it was measured at."""


def evaluate(
    problem: Problem,
    trajectory: Trajectory | str | Path,
    rate_hz: float = DEFAULT_RATE_HZ,
    *,
    other_problem: bool = False,
) -> Report:
    """Measure ``trajectory`` against ``problem`` on a grid at ``rate_hz`` (with breakpoints).

    Parameters
    ----------
    problem : Problem
    trajectory : Trajectory, or the path of a trajectory CSV or of an execution log CSV
        A log is judged on its own samples from the plan's start on, by the same rules
        (:func:`spm_opt.evaluate_execution.evaluate_log`, which also judges the plant's
        true state); its report is an :class:`~spm_opt.evaluate_execution.ExecutionReport`.
    rate_hz : float
        Sampling rate of the evaluation grid, Hz (default 1 kHz; a log keeps its own).
    other_problem : bool
        Judge a plan file or a log under ``problem`` though it was made for (ran under)
        another, or records none; without it, either is refused with a one-line
        :class:`~spm_opt.errors.InputError` (:mod:`spm_opt.provenance`). A
        :class:`Trajectory` object is judged under whatever problem it is given (code
        may judge a plan under tighter limits on purpose).
    """
    if isinstance(trajectory, str | Path):
        from spm_opt import evaluate_execution  # it builds on this module

        if evaluate_execution.is_execution_log(trajectory):
            return evaluate_execution.evaluate_log(
                problem, trajectory, other_problem=other_problem
            ).measured
        path, trajectory = trajectory, Trajectory.from_csv(trajectory)
        _check_plan(problem, trajectory, other_problem, f"plan {path} refused")
    landmark_times = trajectory.landmark_times
    inputs = (rate_hz, None if landmark_times is None else tuple(landmark_times))
    known = _MEASURED.get(trajectory)
    if known is not None and known[0] is problem and known[1] == inputs:
        planner = trajectory.metadata.get("planner")
        return dataclasses.replace(copy.deepcopy(known[2]), planner=planner)
    report = _measure(problem, trajectory, rate_hz)
    _MEASURED[trajectory] = (problem, inputs, report)
    return copy.deepcopy(report)


def _check_plan(
    problem: Problem, trajectory: Trajectory, other_problem: bool, refused: str
) -> None:
    """Refuse a plan made for another problem unless ``other_problem``; warn when let
    through."""
    why = check_plan_made_for(problem, trajectory, other_problem, refused)
    if why:
        _LOG.warning(
            "%s: %s; judged under %s's limits as asked",
            refused.removesuffix(" refused"),
            why,
            problem.name,
        )


@dataclass(frozen=True)
class Motion:
    """A motion sampled at times ``t`` (N,), s, and what drove it; per-joint arrays (N, 2).

    Attributes
    ----------
    t : ndarray, s
    q, qd, qdd, jerk : ndarray, rad, rad/s, rad/s², rad/s³
    torque : ndarray, N·m
        The torque the actuators delivered.
    current : ndarray, A
        The motor current it took.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    jerk: np.ndarray
    torque: np.ndarray
    current: np.ndarray


@dataclass(frozen=True)
class Steps:
    """Jumps of q̈ the samples cannot show: at ``times`` (K,), s, ``values`` (K, 2),
    rad/s², judged against ``limit`` (rad/s², the jerk a grid interval allows; None: not
    limited)."""

    times: np.ndarray
    values: np.ndarray
    limit: float | None


@dataclass(frozen=True)
class Claimed:
    """Where a motion says it visits each landmark: ``times`` (visits,), s, and the unit
    ``directions`` (visits, 3) of the cut then."""

    times: np.ndarray
    directions: np.ndarray


def _measure(problem: Problem, trajectory: Trajectory, rate_hz: float) -> Report:
    """:func:`evaluate`'s measurement, every time."""
    robot = problem.robot
    t = trajectory.time_grid(rate_hz)
    q, qd, qdd, jerk = trajectory.states(t)
    torque = dynamics.actuator_torque(robot, q, qd, qdd)
    current = robot.actuator.current_map.current(torque)
    step_times, steps = trajectory.acceleration_steps()
    jerk_limit = problem.limits.max_joint_jerk
    claimed = trajectory.landmark_times
    visits = None
    if claimed is not None and len(claimed) == len(problem.visit_order):
        visits = Claimed(claimed, kinematics.forward_kinematics(trajectory.position(claimed), 1.0))
    report = judge(
        problem,
        Motion(t, q, qd, qdd, jerk, torque, current),
        contour_tube(problem),
        path_tolerance(problem),
        planner=trajectory.metadata.get("planner"),
        duration=trajectory.duration,
        steps=Steps(step_times, steps, None if jerk_limit is None else jerk_limit / rate_hz),
        claimed=visits,
        contour_judged=not trajectory.metadata.get("ignores_contour", False),
    )
    if not report.contour_judged:
        return report
    checks = _Checks(t)  # a plan's room for a feed hold: judged of plans, not of runs
    for rule, label, values, limit in hold_checks(problem, qd, qdd, jerk):
        checks.upper(rule, label, values, limit)
    return dataclasses.replace(report, violations=report.violations + checks.found)


def judge(
    problem: Problem,
    motion: Motion,
    tube: float | None,
    path: float,
    *,
    planner: str | None,
    duration: float,
    steps: Steps | None = None,
    claimed: Claimed | None = None,
    feed: np.ndarray | None = None,
    between_samples: bool = False,
    contour_judged: bool = True,
    unjudged: frozenset[str] = frozenset(),
) -> Report:
    """Judge a sampled motion by every rule of :data:`spm_opt.limits.RULES`: the one
    judgement of a plan and of an executed run.

    Parameters
    ----------
    problem : Problem
    motion : Motion
    tube : float or None, m
        The contour tolerance the cut is judged against (None: not checked).
    path : float, m
        The path tolerance of the landmark visits, coverage and backtracking.
    planner : str or None
    duration : float, s
        The motion's duration, for the report and the lower bound's ratio.
    steps : Steps, optional
        Jumps of q̈ between samples (None: not measured).
    claimed : Claimed, optional
        The landmark visits the motion claims (None: each is searched for on the samples).
    feed : ndarray (N,), optional
        The pace in force at each sample: the tool speed limit is the problem's times it.
    between_samples : bool
        A searched landmark visit may fall between two samples: its error is the
        distance to the straight segments from the nearest sample to its neighbours.
    contour_judged : bool
        False: the cut's figures are measured, not judged (an excitation plan).
    unjudged : frozenset of str
        Rules left out: their figures are measured, not judged (an executed run's rules
        whose limits its readings cannot resolve).
    """
    robot, limits, contour = problem.robot, problem.limits, problem.contour
    t, q, qd, qdd, jerk = motion.t, motion.q, motion.qd, motion.qdd, motion.jerk
    torque, current = motion.torque, motion.current
    directions, rates, margins = kinematics.motion_directions(q, qd)
    near = contour.nearest(directions)
    radius, gradient = contour.surface.radius_gradient(directions)
    deviation = contour.distance(near, radius)
    tool_speed = surface_speed(radius, gradient, rates)
    incidence = np.degrees(np.arctan(row_lengths(gradient) / radius))
    torque_limit = problem.max_joint_torque
    peak_torque = _peaks(torque)
    peak_current = _peaks(current)
    mean_speed = float(_time_mean(tool_speed, t))
    speed_std = float(np.sqrt(_time_mean((tool_speed - mean_speed) ** 2, t)))
    lower_bound = duration_lower_bound(problem)
    in_tube = (
        np.ones(len(t), bool)
        if tube is None
        else deviation <= RULES["contour deviation"].allowed(tube)
    )
    progress = contour.progress(near)
    gap, gap_at = _largest_gap(progress, in_tube, contour.length)
    backtrack = np.maximum.accumulate(progress) - progress
    landmark_errors = _landmark_errors(problem, claimed, t, directions, path, between_samples)

    # a plan's tube keeps part of the tolerance for execution: its violations say so
    tolerance = limits.contour_tolerance
    reserve = 0.0 if tube is None or tolerance is None else (tolerance - tube) / MM
    checks = _Checks(t, reserve)
    for joint in range(2):
        name = f"theta{joint + 1}"
        low, high = robot.joint_range[joint]
        angle = q[:, joint] / DEG
        checks.upper("joint range", f"{name} upper range", angle, high / DEG)
        checks.lower("joint range", f"{name} lower range", angle, low / DEG)
        checks.upper("joint speed", f"{name} speed", np.abs(qd[:, joint]), limits.max_joint_speed)
        checks.upper(
            "joint acceleration",
            f"{name} acceleration",
            np.abs(qdd[:, joint]),
            limits.max_joint_acceleration,
        )
        checks.upper("joint jerk", f"{name} jerk", np.abs(jerk[:, joint]), limits.max_joint_jerk)
        if steps is not None and steps.limit is not None:
            checks.upper(
                "acceleration step",
                f"{name} acceleration step",
                np.abs(steps.values[:, joint]),
                steps.limit,
                steps.times,
            )
        checks.upper("actuator torque", f"{name} torque", np.abs(torque[:, joint]), torque_limit)
        checks.upper(
            "motor current",
            f"{name} current",
            np.abs(current[:, joint]),
            robot.actuator.continuous_current_a,
        )
    if limits.max_tool_speed is not None:
        speed_limit = limits.max_tool_speed / MM
        checks.upper(
            "tool speed",
            "tool speed",
            tool_speed / MM,
            speed_limit if feed is None else speed_limit * feed,
        )
    if tube is not None:
        checks.upper("contour deviation", "contour deviation", deviation / MM, tube / MM)
    if limits.max_tool_incidence is not None:
        limit = np.degrees(limits.max_tool_incidence)
        checks.upper("tool incidence", "tool incidence", incidence, limit)
    depth_speed, depth_acceleration = _depth_rates(problem, t, directions, rates)
    for rule, values, limit in (
        ("depth speed", depth_speed, limits.max_depth_speed),
        ("depth acceleration", depth_acceleration, limits.max_depth_acceleration),
    ):
        if limit is not None:
            checks.upper(rule, rule, np.abs(values) / MM, limit / MM)
    for visit in landmark_errors:
        checks.upper(
            "landmark visit",
            f"landmark {visit['landmark']} visit",
            np.array([visit["error_mm"]]),
            path / MM,
            np.array([visit["time_s"]]),
        )
    reached = np.flatnonzero(progress >= gap_at)
    gap_time = t[reached[0]] if reached.size else t[-1]
    checks.upper("coverage", "coverage", np.array([gap / MM]), path / MM, np.array([gap_time]))
    checks.upper("backtracking", "backtracking", backtrack / MM, path / MM)
    checks.lower("singularity margin", "singularity margin", margins, robot.min_singularity_margin)
    violations = [
        v
        for v in checks.found
        if (contour_judged or RULES[v.rule].judges == ROBOT) and v.rule not in unjudged
    ]

    return Report(
        planner=planner,
        duration_s=duration,
        peak_joint_speed_rad_s=_peaks(qd).tolist(),
        joint_speed_limit_rad_s=limits.max_joint_speed,
        peak_joint_acceleration_rad_s2=_peaks(qdd).tolist(),
        rms_jerk_rad_s3=np.sqrt(_time_mean(jerk**2, t)).tolist(),
        max_acceleration_step_rad_s2=None if steps is None else _peaks(steps.values).tolist(),
        max_contour_deviation_mm=float(np.max(deviation) / MM),
        rms_contour_deviation_mm=float(np.sqrt(_time_mean(deviation**2, t)) / MM),
        max_tool_speed_mm_s=float(np.max(tool_speed) / MM),
        mean_tool_speed_mm_s=float(mean_speed / MM),
        tool_speed_cv=float(speed_std / mean_speed) if mean_speed > 0 else float("nan"),
        landmark_errors_mm=landmark_errors,
        max_landmark_error_mm=max(v["error_mm"] for v in landmark_errors),
        coverage_gap_mm=float(gap / MM),
        max_backtrack_mm=float(np.max(backtrack) / MM),
        min_singularity_margin=float(np.min(margins)),
        contour_length_mm=contour.length / MM,
        duration_lower_bound_s=lower_bound,
        duration_over_lower_bound=duration / lower_bound,
        peak_torque_nm=peak_torque.tolist(),
        rms_torque_nm=np.sqrt(_time_mean(torque**2, t)).tolist(),
        torque_margin=(1.0 - peak_torque / robot.actuator.continuous_torque_nm).tolist(),
        peak_current_a=peak_current.tolist(),
        current_margin=(1.0 - peak_current / robot.actuator.continuous_current_a).tolist(),
        energy_j=float(np.trapezoid(_joint_sum(np.abs(torque * qd)), t)),
        max_tool_incidence_deg=float(np.max(incidence)),
        max_depth_speed_mm_s=_largest(depth_speed, MM),
        max_depth_acceleration_mm_s2=_largest(depth_acceleration, MM),
        effort_n2m2s=float(_time_mean(_joint_sum(torque**2), t) * (t[-1] - t[0])),
        violations=violations,
        contour_judged=contour_judged,
    )


class _Checks:
    """Collects violations: the worst sample beyond a limit and its rule's allowance."""

    def __init__(self, t: np.ndarray, reserve_mm: float = 0.0) -> None:
        self.t = t
        self.reserve_mm = reserve_mm
        self.found: list[Violation] = []

    def upper(
        self,
        rule: str,
        label: str,
        values: np.ndarray,
        limit: float | np.ndarray | None,
        times: np.ndarray | None = None,
    ) -> None:
        """Record the worst of ``values`` (at ``times``, default the grid) above ``limit``
        (one for all, or one per value: the worst is then the largest ratio) by more than
        the rule allows; ``None``: not limited."""
        if limit is None or len(values) == 0:
            return
        if np.ndim(limit) == 0:
            worst = int(np.argmax(values))
        else:
            worst = int(np.argmax(values / limit))
            limit = limit[worst]
        if values[worst] > RULES[rule].allowed(limit):
            times = self.t if times is None else times
            self._add(rule, label, values[worst], limit, times[worst])

    def lower(self, rule: str, label: str, values: np.ndarray, limit: float) -> None:
        """Record the worst of ``values`` below ``limit`` by more than the rule allows."""
        worst = int(np.argmin(values))
        if values[worst] < RULES[rule].allowed(limit, upper=False):
            self._add(rule, label, values[worst], limit, self.t[worst])

    def _add(self, rule: str, label: str, worst: float, limit: float, time: float) -> None:
        reserve = self.reserve_mm if rule in TUBE_RULES else 0.0
        self.found.append(
            Violation(
                label, float(worst), float(limit), RULES[rule].unit, float(time), rule, reserve
            )
        )


def _largest_gap(progress: np.ndarray, in_tube: np.ndarray, length: float) -> tuple[float, float]:
    """The longest stretch of the contour, m, that the cut never swept while in the tube,
    and the arc length, m, where it starts.

    Each step between consecutive samples that are both in the tube sweeps the contour
    between their nearest points' arc lengths (``progress``); the stretches of [0, length]
    that no such step sweeps (a plan that stands still, stops early, or leaves the tube
    to skip a stretch) are the gaps.
    """
    swept = in_tube[:-1] & in_tube[1:]
    low = np.clip(np.minimum(progress[:-1], progress[1:])[swept], 0.0, length)
    high = np.clip(np.maximum(progress[:-1], progress[1:])[swept], 0.0, length)
    if low.size == 0:
        return length, 0.0
    # stable: quick on a cut's nearly sorted arc lengths; the result is any sort's, as of
    # steps with equal starts the first in the order has the largest gap before it
    order = np.argsort(low, kind="stable")
    low, reached = low[order], np.maximum.accumulate(high[order])
    starts = np.concatenate([[0.0], reached])
    gaps = np.concatenate([low, [length]]) - starts
    worst = int(np.argmax(gaps))
    return float(max(gaps[worst], 0.0)), float(starts[worst])


def _landmark_errors(
    problem: Problem,
    claimed: Claimed | None,
    t: np.ndarray,
    directions: np.ndarray,
    tolerance: float,
    between_samples: bool,
) -> list[dict[str, Any]]:
    """Distance on the skull from each landmark visit, in visiting order: where the
    motion claims it, or, when it does not say, at the closest approach of the first pass
    within ``tolerance`` (m) after the previous visit (the closest approach after it, when
    the cut never comes that close); ``between_samples``: that approach measured on the
    straight segments from the nearest sample to its neighbours."""
    errors = []
    earliest = 0
    for k, index in enumerate(problem.visit_order):
        landmark = problem.landmarks[index]
        radius = np.linalg.norm(landmark)
        unit = landmark / radius
        if claimed is not None:
            time = float(claimed.times[k])
            error = radius * np.linalg.norm(claimed.directions[k] - unit)
        else:
            distances = radius * np.linalg.norm(directions[earliest:] - unit, axis=1)
            near = np.flatnonzero(distances <= RULES["landmark visit"].allowed(tolerance))
            if near.size:  # the closest approach of the first pass that comes near enough
                left = np.flatnonzero(np.diff(near) > 1)
                end = near[left[0]] + 1 if left.size else near[-1] + 1
                closest = near[0] + int(np.argmin(distances[near[0] : end]))
            else:
                closest = int(np.argmin(distances))
            time, error = float(t[earliest + closest]), distances[closest]
            if between_samples:
                time, error = _between(t, directions, earliest + closest, unit, radius)
            if near.size:
                earliest += closest
        errors.append(
            {
                "landmark": problem.landmark_names[index],
                "time_s": time,
                "error_mm": float(error / MM),
            }
        )
    return errors


def _largest(values: np.ndarray, unit: float) -> float | None:
    """The largest magnitude of ``values`` in ``unit``s, None for none."""
    return float(np.max(np.abs(values)) / unit) if len(values) else None


def _depth_rates(
    problem: Problem, t: np.ndarray, directions: np.ndarray, rates: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The speed (N,), m/s, and acceleration (N,), m/s², of the tool's depth setpoint along
    unit directions (N, 3) moving at ``rates`` (N, 3), 1/s (empty without an inner mesh)."""
    inner = problem.inner_radius
    if inner is None:
        return np.zeros(0), np.zeros(0)
    return depth_rates(inner, t, directions, rates)


def _between(
    t: np.ndarray, directions: np.ndarray, k: int, unit: np.ndarray, radius: float
) -> tuple[float, float]:
    """The closest approach, (time, s; distance, m), of the cut to the landmark in
    direction ``unit`` on the skull's sphere of ``radius`` along the straight segments
    from sample ``k`` to its neighbours (time interpolated along them)."""
    best = (float(t[k]), float(radius * np.linalg.norm(directions[k] - unit)))
    for other in (k - 1, k + 1):
        if not 0 <= other < len(t):
            continue
        step = directions[other] - directions[k]
        squared = float(step @ step)
        if squared == 0.0:
            continue
        along = min(max(float((unit - directions[k]) @ step) / squared, 0.0), 1.0)
        distance = float(radius * np.linalg.norm(directions[k] + along * step - unit))
        if distance < best[1]:
            best = (float(t[k] + along * (t[other] - t[k])), distance)
    return best
