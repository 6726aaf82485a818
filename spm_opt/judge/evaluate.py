"""The one evaluator: every trajectory measured the same way, on a fine time grid.

A planner's own claims are never reported; these figures are. What each limit means and
how much the evaluator allows beyond it is :mod:`spm_opt.judge.limits`' table: 0.5 % of every
rate-type limit, nothing beyond the joint range and the singularity margin. Besides the
limits, a clean plan cuts the contour: it visits every landmark in order within the path
tolerance (the contour tolerance), sweeps the whole contour inside the tube with no
stretch left out, and never backtracks along it by more than the path tolerance. A plan's
tube is the contour tolerance less the problem's execution reserve, an executed cut's the
whole (:func:`spm_opt.judge.limits.contour_tube`). A plan
whose metadata say ``ignores_contour`` (an excitation plan for identification) is judged
by the robot's limits alone: its cut figures are measured, not judged.

A plan is sampled on its grid (a :class:`~spm_opt.judge.motion.Motion`) and judged by the one
judgement of plans and executed runs, :func:`spm_opt.judge.judge.judge`; a plan's room for a
feed hold (:mod:`spm_opt.judge.hold_room`) is judged here, of plans only.

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
from pathlib import Path

from spm_opt.judge.checks import Checks
from spm_opt.judge.hold_room import hold_checks
from spm_opt.judge.judge import judge
from spm_opt.judge.limits import contour_tube, path_tolerance
from spm_opt.judge.motion import Claimed, Motion, Steps
from spm_opt.judge.report import Report
from spm_opt.model import dynamics, kinematics
from spm_opt.problem.problem import Problem
from spm_opt.problem.provenance import check_plan_made_for
from spm_opt.problem.trajectory import Trajectory

DEFAULT_RATE_HZ = 1000.0

_LOG = logging.getLogger(__name__)


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
    trajectory : Trajectory, or the path of a trajectory CSV
        (:func:`spm_opt.verify.judgement.evaluate`, ``so.evaluate``, takes an execution
        log too.)
    rate_hz : float
        Sampling rate of the evaluation grid, Hz (default 1 kHz).
    other_problem : bool
        Judge a plan file under ``problem`` though it was made for another, or records
        none; without it, it is refused with a one-line
        :class:`~spm_opt.base.errors.InputError` (:mod:`spm_opt.problem.provenance`). A
        :class:`Trajectory` object is judged under whatever problem it is given (code
        may judge a plan under tighter limits on purpose).
    """
    if isinstance(trajectory, str | Path):
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
    checks = Checks(t)  # a plan's room for a feed hold: judged of plans, not of runs
    for rule, label, values, limit in hold_checks(problem, qd, qdd, jerk):
        checks.upper(rule, label, values, limit)
    return dataclasses.replace(report, violations=report.violations + checks.found)
