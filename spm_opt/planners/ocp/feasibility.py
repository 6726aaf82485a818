"""What no optimal-control planner can plan, refused before any NLP is built, each with
its reason: a contour tube too narrow to have an interior, gravity beyond the torque limit
at rest, and durations shorter than the speed limits allow."""

from __future__ import annotations

import numpy as np

from spm_opt.bounds import segment_lower_bounds
from spm_opt.errors import PlanningError
from spm_opt.limits import contour_tube, planner_bounds
from spm_opt.model import dynamics
from spm_opt.model.params import MM
from spm_opt.problem import Problem

MIN_CONTOUR_TOLERANCE = 1e-6
"""Narrowest contour tube the planners accept, m: a zero-width tube has no interior."""


def check_feasible_at_all(problem: Problem, timing: str, margin: float) -> np.ndarray:
    """Refuse what no solver can do, with the reason; return the segments' lower bounds
    on their durations, s (:func:`spm_opt.bounds.segment_lower_bounds`)."""
    limits, names = problem.limits, problem.visit_names
    tube = contour_tube(problem)
    if tube is not None and tube < MIN_CONTOUR_TOLERANCE:
        raise PlanningError(
            f"contour_tolerance_mm = {limits.contour_tolerance / MM:g} less "
            f"execution_reserve_mm = {limits.execution_reserve / MM:g}: the cut would have to "
            f"turn every corner exactly; leave a plan at least {MIN_CONTOUR_TOLERANCE / MM:g} mm"
        )
    torque_limit = planner_bounds(problem, margin).load_torque
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
    return bounds
