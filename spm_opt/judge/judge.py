"""The one judgement of a motion sampled on a grid, a plan's or an executed run's: every
rule of :data:`spm_opt.judge.limits.RULES` checked, and the report of what was measured.

A plan is judged here by :func:`spm_opt.judge.evaluate.evaluate`, an executed run (its log,
and the plant's true state) by :mod:`spm_opt.verify.executed_cut`.
"""

from __future__ import annotations

import numpy as np

from spm_opt.judge.bounds import duration_lower_bound
from spm_opt.judge.checks import Checks
from spm_opt.judge.cut_figures import CutFigures, cut_figures
from spm_opt.judge.limits import ROBOT, RULES
from spm_opt.judge.motion import Claimed, Motion, Steps
from spm_opt.judge.report import Report, Violation
from spm_opt.model.params import DEG, MM
from spm_opt.problem.problem import Problem


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
    """Judge a sampled motion by every rule of :data:`spm_opt.judge.limits.RULES`: the one
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
    cut = cut_figures(problem, motion, tube, path, claimed, between_samples)
    checks = Checks(motion.t, _reserve_mm(problem, tube))
    _check_joints(checks, problem, motion, steps)
    _check_cut(checks, problem, cut, tube, path, feed)
    violations = [
        v
        for v in checks.found
        if (contour_judged or RULES[v.rule].judges == ROBOT) and v.rule not in unjudged
    ]
    return _report(problem, motion, cut, planner, duration, steps, violations, contour_judged)


def _reserve_mm(problem: Problem, tube: float | None) -> float:
    """What a plan's ``tube`` (m) keeps of the contour tolerance for execution, mm, which
    its violations say (0: the whole tolerance, or none)."""
    tolerance = problem.limits.contour_tolerance
    return 0.0 if tube is None or tolerance is None else (tolerance - tube) / MM


def _check_joints(checks: Checks, problem: Problem, motion: Motion, steps: Steps | None) -> None:
    """Each joint's range, speed, acceleration, jerk, steps of q̈, torque and current."""
    robot, limits = problem.robot, problem.limits
    for joint in range(2):
        name = f"theta{joint + 1}"
        low, high = robot.joint_range[joint]
        angle = motion.q[:, joint] / DEG
        checks.upper("joint range", f"{name} upper range", angle, high / DEG)
        checks.lower("joint range", f"{name} lower range", angle, low / DEG)
        speed = motion.joint_speed()[:, joint]
        checks.upper("joint speed", f"{name} speed", speed, limits.max_joint_speed)
        checks.upper(
            "joint acceleration",
            f"{name} acceleration",
            np.abs(motion.qdd[:, joint]),
            limits.max_joint_acceleration,
        )
        jerk = np.abs(motion.jerk[:, joint])
        checks.upper("joint jerk", f"{name} jerk", jerk, limits.max_joint_jerk)
        if steps is not None and steps.limit is not None:
            checks.upper(
                "acceleration step",
                f"{name} acceleration step",
                np.abs(steps.values[:, joint]),
                steps.limit,
                steps.times,
            )
        torque = np.abs(motion.torque[:, joint])
        checks.upper("actuator torque", f"{name} torque", torque, problem.max_joint_torque)
        current = np.abs(motion.current[:, joint])
        limit = robot.actuator.continuous_current_a
        checks.upper("motor current", f"{name} current", current, limit)


def _check_cut(
    checks: Checks,
    problem: Problem,
    cut: CutFigures,
    tube: float | None,
    path: float,
    feed: np.ndarray | None,
) -> None:
    """The tool's speed (the problem's limit times the ``feed``, when given) and incidence,
    the cut's distance from the contour (in the ``tube``, m), the depth setpoint's rates,
    the landmark visits, coverage and backtracking (within ``path``, m), and the
    singularity margin."""
    limits = problem.limits
    if limits.max_tool_speed is not None:
        speed_limit = limits.max_tool_speed / MM
        checks.upper(
            "tool speed",
            "tool speed",
            cut.tool_speed / MM,
            speed_limit if feed is None else speed_limit * feed,
        )
    if tube is not None:
        checks.upper("contour deviation", "contour deviation", cut.deviation / MM, tube / MM)
    if limits.max_tool_incidence is not None:
        limit = np.degrees(limits.max_tool_incidence)
        checks.upper("tool incidence", "tool incidence", cut.incidence, limit)
    for rule, values, limit in (
        ("depth speed", cut.depth_speed, limits.max_depth_speed),
        ("depth acceleration", cut.depth_acceleration, limits.max_depth_acceleration),
    ):
        if limit is not None:
            checks.upper(rule, rule, np.abs(values) / MM, limit / MM)
    for visit in cut.landmark_errors:
        checks.upper(
            "landmark visit",
            f"landmark {visit['landmark']} visit",
            np.array([visit["error_mm"]]),
            path / MM,
            np.array([visit["time_s"]]),
        )
    gap = np.array([cut.gap / MM])
    checks.upper("coverage", "coverage", gap, path / MM, np.array([cut.gap_time]))
    checks.upper("backtracking", "backtracking", cut.backtrack / MM, path / MM)
    margin = problem.robot.min_singularity_margin
    checks.lower("singularity margin", "singularity margin", cut.margins, margin)


def _report(
    problem: Problem,
    motion: Motion,
    cut: CutFigures,
    planner: str | None,
    duration: float,
    steps: Steps | None,
    violations: list[Violation],
    contour_judged: bool,
) -> Report:
    """The report of a judged motion: its figures (:class:`~spm_opt.judge.report.Report`)
    and ``violations``."""
    robot, limits = problem.robot, problem.limits
    t, torque = motion.t, motion.torque
    peak_torque = _peaks(torque)
    peak_current = _peaks(motion.current)
    mean_speed = float(_time_mean(cut.tool_speed, t))
    speed_std = float(np.sqrt(_time_mean((cut.tool_speed - mean_speed) ** 2, t)))
    lower_bound = duration_lower_bound(problem)
    landmark_errors = cut.landmark_errors
    return Report(
        planner=planner,
        duration_s=duration,
        peak_joint_speed_rad_s=_peaks(motion.joint_speed()).tolist(),
        joint_speed_limit_rad_s=limits.max_joint_speed,
        peak_joint_acceleration_rad_s2=_peaks(motion.qdd).tolist(),
        rms_jerk_rad_s3=np.sqrt(_time_mean(motion.jerk**2, t)).tolist(),
        max_acceleration_step_rad_s2=None if steps is None else _peaks(steps.values).tolist(),
        max_contour_deviation_mm=float(np.max(cut.deviation) / MM),
        rms_contour_deviation_mm=float(np.sqrt(_time_mean(cut.deviation**2, t)) / MM),
        max_tool_speed_mm_s=float(np.max(cut.tool_speed) / MM),
        mean_tool_speed_mm_s=float(mean_speed / MM),
        tool_speed_cv=float(speed_std / mean_speed) if mean_speed > 0 else float("nan"),
        landmark_errors_mm=landmark_errors,
        max_landmark_error_mm=max(v["error_mm"] for v in landmark_errors),
        coverage_gap_mm=float(cut.gap / MM),
        max_backtrack_mm=float(np.max(cut.backtrack) / MM),
        min_singularity_margin=float(np.min(cut.margins)),
        contour_length_mm=problem.contour.length / MM,
        duration_lower_bound_s=lower_bound,
        duration_over_lower_bound=duration / lower_bound,
        peak_torque_nm=peak_torque.tolist(),
        rms_torque_nm=np.sqrt(_time_mean(torque**2, t)).tolist(),
        torque_margin=(1.0 - peak_torque / robot.actuator.continuous_torque_nm).tolist(),
        peak_current_a=peak_current.tolist(),
        current_margin=(1.0 - peak_current / robot.actuator.continuous_current_a).tolist(),
        energy_j=float(np.trapezoid(_joint_sum(np.abs(torque * motion.qd)), t)),
        max_tool_incidence_deg=float(np.max(cut.incidence)),
        max_depth_speed_mm_s=_largest(cut.depth_speed, MM),
        max_depth_acceleration_mm_s2=_largest(cut.depth_acceleration, MM),
        effort_n2m2s=float(_time_mean(_joint_sum(torque**2), t) * (t[-1] - t[0])),
        violations=violations,
        contour_judged=contour_judged,
    )


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


def _largest(values: np.ndarray, unit: float) -> float | None:
    """The largest magnitude of ``values`` in ``unit``s, None for none."""
    return float(np.max(np.abs(values)) / unit) if len(values) else None
