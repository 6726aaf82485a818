"""The feed ceiling: the fastest pace at which a plan still keeps its limits.

The ceiling is bisected (to :data:`CEILING_RESOLUTION`) on how the plan's figures scale
with the feed (:mod:`spm_opt.judge.paced`: one measurement of the plan, then a few array
operations per step), and the pace it finds is then judged once by the evaluator, on the
plan run that much faster. Should that judgement find a limit the scaling missed (the two
sample the plan on different grids), the bisection goes on below it, judging every step.
"""

from __future__ import annotations

from collections.abc import Callable

from spm_opt.execution.tracking import Lead, led_goals_outside, led_samples_outside
from spm_opt.judge.evaluate import evaluate
from spm_opt.judge.paced import PacedLimits
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

CEILING_RESOLUTION = 0.01
"""The feed ceiling is found to this fraction."""


def feed_ceiling(
    problem: Problem, trajectory: Trajectory, most: float, lead: Lead | None = None
) -> float:
    """The highest feed up to ``most`` (at least 1) at which the plan run that much faster
    breaks no limit the plan itself keeps, as the evaluator judges it (to 1 %), and the
    goals ``lead`` leads from it stay inside the joint range and the Velocity Limit."""
    if most <= 1.0:
        return most
    kept = {v.rule for v in evaluate(problem, trajectory).violations}
    paced = PacedLimits(problem, trajectory)

    def predicted(feed: float) -> bool:
        if not paced.broken(feed) <= kept:
            return False
        return lead is None or not led_samples_outside(lead, problem.robot, *paced.states(feed))

    def judged(feed: float) -> bool:
        scaled = trajectory.time_scaled(feed)
        if not {v.rule for v in evaluate(problem, scaled).violations} <= kept:
            return False
        return lead is None or not led_goals_outside(lead, scaled, problem.robot)

    found = most if predicted(most) else _bisect(predicted, 1.0, most)
    if found == 1.0 or judged(found):
        return found
    return _bisect(judged, 1.0, found)


def _bisect(allowed: Callable[[float], bool], low: float, high: float) -> float:
    """The highest feed ``allowed`` between ``low`` (allowed) and ``high`` (not), to
    :data:`CEILING_RESOLUTION`."""
    while high - low > CEILING_RESOLUTION:
        middle = 0.5 * (low + high)
        low, high = (middle, high) if allowed(middle) else (low, middle)
    return low
