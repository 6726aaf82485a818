"""A reserve from the prediction: re-plan once, keeping for execution what the predicted
cut says execution takes.

A problem's ``execution_reserve_mm`` is a constant: what a plan leaves of the contour
tolerance for tracking. :func:`plan_within_prediction` plans with it and predicts the cut
on a robot file's closed-loop model (:func:`~spm_opt.verify.predicted_cut.predict_cut`).
When the predicted cut leaves the tube, the execution's share is measured rather than
assumed: the predicted cut's distance less the plan's own, plus
:data:`REPEAT_MARGIN_MM` for what does not repeat. If that is more than the problem keeps,
the planner runs once more with it as the reserve. The new plan keeps a narrower tube
than the problem's, so it is made for the problem as given (its metadata records the
problem, and ``execution_reserve_mm`` the reserve kept).

What does not repeat, measured on the simulated robot: nothing in the fourth decimal of
a millimetre over six current-noise seeds and six start positions up to 3 encoder pulses
from the plan's (``prototype_plant.toml``, the paper's flap at 4 mm/s, toppra and
ocp-min-time). The margin is the prediction's own accuracy instead, which the study of
plants the model is not (``experiments/compensated_cut.py``) measures.
"""

from __future__ import annotations

import dataclasses

from spm_opt.execution import ExecutionSettings
from spm_opt.judge.evaluate import evaluate
from spm_opt.model.params import MM, Robot
from spm_opt.planners import plan
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.verify.predicted_cut import PredictedCut, predict_cut

REPEAT_MARGIN_MM = 0.01
"""Kept beyond the predicted execution share for what the prediction does not hold, mm."""
LEAST_PLAN_TUBE = 0.1
"""A re-plan keeps at least this fraction of the contour tolerance for the plan."""


@dataclasses.dataclass(frozen=True)
class PlanWithinPrediction:
    """A plan whose reserve the prediction set.

    Attributes
    ----------
    plan : Trajectory
        The plan kept (the re-plan, if one was made).
    predicted : PredictedCut
        Its predicted cut.
    first : PredictedCut
        The first plan's predicted cut (``predicted`` itself when no re-plan was made).
    reserve_mm : float, mm
        The reserve the kept plan leaves for execution.
    replanned : bool
    """

    plan: Trajectory
    predicted: PredictedCut
    first: PredictedCut
    reserve_mm: float
    replanned: bool


def plan_within_prediction(
    problem: Problem,
    planner: str,
    robot: Robot | None = None,
    settings: ExecutionSettings | None = None,
) -> PlanWithinPrediction:
    """Plan ``problem`` with ``planner``, predict its cut on ``robot`` (default: the
    problem's) run with ``settings``, and re-plan once with the reserve the prediction asks
    for when the cut leaves the tube (see the module's docstring)."""
    limits = problem.limits
    first_plan = plan(problem, planner)
    first = predict_cut(problem, first_plan, robot, settings)
    kept = limits.execution_reserve / MM
    if first.inside or limits.contour_tolerance is None or not first.report.completed:
        return PlanWithinPrediction(first_plan, first, first, kept, False)
    planned = evaluate(problem, first_plan).max_contour_deviation_mm
    needed = max(first.deviation_mm - planned, 0.0) + REPEAT_MARGIN_MM
    most = (1.0 - LEAST_PLAN_TUBE) * limits.contour_tolerance / MM
    reserve = min(needed, most)
    if reserve <= kept:  # the plan's own offset, not execution, leaves the tube
        return PlanWithinPrediction(first_plan, first, first, kept, False)
    narrower = dataclasses.replace(
        problem, limits=dataclasses.replace(limits, execution_reserve=reserve * MM)
    )
    second_plan = plan(narrower, planner)
    second_plan.metadata["problem"] = problem.record()  # a narrower tube keeps the problem's
    second_plan.metadata["execution_reserve_mm"] = reserve
    second = predict_cut(problem, second_plan, robot, settings)
    return PlanWithinPrediction(second_plan, second, first, reserve, True)
