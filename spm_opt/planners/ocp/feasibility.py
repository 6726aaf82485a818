"""What no optimal-control planner can plan, refused before any NLP is built, each with its
reason; and the bounds the checks establish, which the planner goes on with.

Refused: a contour tube too narrow to have an interior, gravity beyond the torque limit at
rest, and durations shorter than the speed limits allow. Established (:class:`Plannable`):
the planner's bounds, read from :mod:`spm_opt.judge.limits` once per plan, and the
segments' shortest durations."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spm_opt.base.errors import PlanningError
from spm_opt.judge.bounds import segment_lower_bounds
from spm_opt.judge.limits import PlannerBounds, contour_tube, planner_bounds
from spm_opt.model import dynamics
from spm_opt.model.params import MM
from spm_opt.problem.problem import Problem

MIN_CONTOUR_TOLERANCE = 1e-6
"""Narrowest contour tube the planners accept, m: a zero-width tube has no interior."""


@dataclass(frozen=True)
class Plannable:
    """What the checks establish, for the planner to go on with.

    Attributes
    ----------
    bounds : PlannerBounds
        The problem's limits as the planner imposes them, its margin kept
        (:func:`~spm_opt.judge.limits.planner_bounds`).
    lower_bounds : ndarray, shape (segments,), s
        The segments' shortest durations (:func:`spm_opt.judge.bounds.segment_lower_bounds`).
    """

    bounds: PlannerBounds
    lower_bounds: np.ndarray


def check_feasible_at_all(problem: Problem, timing: str, margin: float) -> Plannable:
    """Refuse what no solver can do, with the reason; return the planner's bounds at
    ``margin`` and the segments' lower bounds on their durations."""
    limits, names = problem.limits, problem.visit_names
    tube = contour_tube(problem)
    if tube is not None and tube < MIN_CONTOUR_TOLERANCE:
        raise PlanningError(
            f"contour_tolerance_mm = {limits.contour_tolerance / MM:g} less "
            f"execution_reserve_mm = {limits.execution_reserve / MM:g}: the cut would have to "
            f"turn every corner exactly; leave a plan at least {MIN_CONTOUR_TOLERANCE / MM:g} mm"
        )
    planner = planner_bounds(problem, margin)
    torque_limit = planner.load_torque
    for visit in (0, len(names) - 1):
        holding = dynamics.gravity_torque(problem.robot, problem.waypoint_angles[visit])[0]
        if np.max(np.abs(holding)) > torque_limit:
            joint = int(np.argmax(np.abs(holding)))
            raise PlanningError(
                f"max_joint_torque_nm = {problem.max_joint_torque:g}: holding the robot at rest at "
                f"{names[visit]} takes {abs(holding[joint]):.4g} N·m on actuator {joint + 1} "
                "against gravity"
            )
    bounds = segment_lower_bounds(problem)
    need = bounds / (1 - margin)
    total = float(np.sum(problem.segment_durations))
    if timing == "total" and total < np.sum(need):
        raise PlanningError(
            f"segment_durations_s: the cut lasts {total:g} s in all but the joint- and "
            f"tool-speed limits (max_tool_speed_mm_s, max_joint_speed_rpm) need at least "
            f"{np.sum(need):.4g} s along the contour; lengthen it or raise the limits"
        )
    if timing == "segments":
        short = np.flatnonzero(problem.segment_durations < need)
        if short.size:
            k = int(short[0])
            raise PlanningError(
                f"segment_durations_s: segment {names[k]}→{names[k + 1]} lasts "
                f"{problem.segment_durations[k]:g} s but the joint- and tool-speed limits "
                f"(max_tool_speed_mm_s, max_joint_speed_rpm) need at least {need[k]:.4g} s "
                "along the contour; lengthen it or raise the limits"
            )
    return Plannable(planner, bounds)
