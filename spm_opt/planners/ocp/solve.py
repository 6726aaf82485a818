"""One solve of the optimal-control NLP: from an initial x or a solution to continue, to a
converged :class:`Solution` with its statistics, or a planning error naming IPOPT's status
and the most violated row."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from spm_opt.base import interrupt
from spm_opt.base.errors import PlanningError
from spm_opt.judge.limits import PlannerBounds
from spm_opt.model.joint_torque import range_key
from spm_opt.planners.ocp import ipopt
from spm_opt.planners.ocp.bounds import nlp_bounds
from spm_opt.planners.ocp.diagnostics import worst_constraint
from spm_opt.planners.ocp.nlp import build_nlp
from spm_opt.planners.ocp.parameters import nlp_parameters
from spm_opt.planners.ocp.settings import OcpSettings
from spm_opt.problem.problem import Problem


@dataclass(frozen=True)
class Solution:
    """A converged solve: x, what continuing from it takes, and its statistics."""

    x: np.ndarray
    continuation: dict[str, np.ndarray]  # x0, lam_x0, lam_g0
    scales: np.ndarray  # the objective's terms at the solve's initial guess
    statistics: dict[str, Any]


def solve(
    planner: str,
    problem: Problem,
    settings: OcpSettings,
    bounds: PlannerBounds,
    fractions: np.ndarray,
    with_torque: bool,
    demanded: frozenset[str],
    start: np.ndarray | Solution,
) -> Solution:
    """Solve from ``start``: an initial x, or a solution to continue from with its
    multipliers and objective scales (its NLP must have the same rows); ``demanded``:
    the constraints whose on-demand rows the NLP has; ``planner`` names the planner in
    errors. An early stop at IPOPT's acceptable level is continued strictly from there."""
    started = time.perf_counter()
    segments = len(problem.segment_durations)
    joint_range = range_key(problem.robot.joint_range)
    nlp = build_nlp(segments, settings, with_torque, joint_range, demanded)
    continued = isinstance(start, Solution)
    solver = ipopt.solver(segments, settings, with_torque, joint_range, demanded, warm=continued)
    construction = time.perf_counter() - started
    weights = [settings.time_weight, settings.energy_weight, settings.jerk_weight]
    if isinstance(start, Solution):
        scales, guess = start.scales, start.continuation
    else:
        at_guess = nlp.terms(
            start, nlp_parameters(problem, fractions, weights, np.ones(3), with_torque)
        )
        scales = np.maximum(np.abs([float(v) for v in at_guess]), 1e-9)
        guess = {"x0": start}
    parameters = nlp_parameters(problem, fractions, weights, scales, with_torque)
    box = nlp_bounds(problem, nlp, bounds, settings.timing, nlp.grid.split(guess["x0"])[2])
    started = time.perf_counter()
    solution = interrupt.solve(solver, **guess, p=parameters, **box)
    stats = solver.stats()
    statuses, iterations = [stats["return_status"]], int(stats["iter_count"])
    if stats["return_status"] == ipopt.ACCEPTABLE:  # loose: re-solve strictly from there
        solver = ipopt.solver(segments, settings, with_torque, joint_range, demanded, warm=True)
        solution = interrupt.solve(solver, **ipopt.continuation(solution), p=parameters, **box)
        stats = solver.stats()
        statuses.append(stats["return_status"])
        iterations += int(stats["iter_count"])
    wall = time.perf_counter() - started
    x, g = solution["x"].full().ravel(), solution["g"].full().ravel()
    most = worst_constraint(nlp, g, box, fractions, problem.visit_names)
    if stats["return_status"] != ipopt.CONVERGED:
        raise PlanningError(
            f"{planner}: IPOPT stopped with {' then '.join(statuses)} after "
            f"{iterations} iterations; most violated: {most}"
        )
    total_time, effort, jerk_integral = (float(v) for v in nlp.terms(x, parameters))
    return Solution(
        x,
        ipopt.continuation(solution),
        scales,
        {
            "status": stats["return_status"],
            "statuses": statuses,
            "iterations": iterations,
            "solve_time_s": wall,
            "function_time_s": sum(v for k, v in stats.items() if k.startswith("t_wall_nlp")),
            "construction_time_s": construction,
            "constraint_violation": float(max(np.max(box["lbg"] - g), np.max(g - box["ubg"]), 0.0)),
            "most_binding": most,
            "torque_in_nlp": with_torque,
            "duration_s": total_time,
            "effort_n2m2s": effort if with_torque else None,
            "jerk_integral_rad2_s5": jerk_integral,
        },
    )


def added(statistics: dict[str, Any], again: dict[str, Any]) -> dict[str, Any]:
    """The statistics of a re-solve, with the solve times and iterations of both."""
    summed = {
        k: statistics[k] + again[k] for k in ("solve_time_s", "function_time_s", "iterations")
    }
    return {**statistics, **again, **summed, "statuses": statistics["statuses"] + again["statuses"]}
