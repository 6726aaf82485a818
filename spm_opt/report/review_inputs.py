"""What the review draws, read and checked as ``spm-opt evaluate`` and ``spm-opt execute``
check it: the plan, an execution log with the judge's reports of it, and the plan's cut
predicted on a robot file's closed-loop model; a plan or a log made for another problem
only when asked for, with a warning for the page."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from spm_opt.base.errors import InputError
from spm_opt.problem.provenance import PLAN_HINT, check_made_for, check_run_of, log_hint

if TYPE_CHECKING:
    import pandas as pd

    from spm_opt.model.params import Robot
    from spm_opt.problem.problem import Problem
    from spm_opt.problem.trajectory import Trajectory
    from spm_opt.verify.executed_cut import LogReports
    from spm_opt.verify.predicted_cut import PredictedCut

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReviewInputs:
    """What the review draws, checked (:func:`review_inputs`).

    Attributes
    ----------
    trajectory : Trajectory
        The plan.
    log : pandas.DataFrame or None
        The execution log's table, when one was given.
    warnings : tuple of str
        What ``other_problem`` let through, one line each, for the page.
    run : LogReports or None
        The judge's reports of that log (:func:`~spm_opt.verify.executed_cut.evaluate_log`):
        given with ``log``.
    predicted : PredictedCut or None
        The plan's run predicted on a robot file's closed-loop model, and its judgement
        (:func:`~spm_opt.verify.predicted_cut.predict_cut`).
    """

    trajectory: Trajectory
    log: pd.DataFrame | None = None
    warnings: tuple[str, ...] = ()
    run: LogReports | None = None
    predicted: PredictedCut | None = None


def review_inputs(
    problem: Problem,
    plan: Path,
    log: Path | None = None,
    other_problem: bool = False,
    trace: Path | None = None,
    predict_on: Robot | None = None,
) -> ReviewInputs:
    """Read the plan, and the execution log when given, checked as ``spm-opt evaluate``
    and ``spm-opt execute`` check them: each must record ``problem`` as the one it was made
    for or ran under (:func:`spm_opt.problem.provenance.check_made_for`; another, or none, only
    with ``other_problem``, then logged as a warning and returned for the page), and the
    log must be a run of the plan (:func:`spm_opt.problem.provenance.check_run_of`). One-line
    :class:`~spm_opt.base.errors.InputError` naming the file otherwise. The log is judged as
    ``spm-opt evaluate LOG [--trace TRACE]`` judges it.

    Parameters
    ----------
    problem : Problem
    plan : path
        The plan's CSV (its JSON sidecar beside it).
    log : path, optional
        An execution log's CSV (its JSON header beside it).
    other_problem : bool
        Draw a plan or a log made for another problem, or recording none.
    trace : path, optional
        The plant's true state over the run (``spm-opt execute --trace``): its true cut is
        judged too. Only with ``log``.
    predict_on : Robot, optional
        Predict the plan's run on this robot's closed-loop model (the executor's default
        settings) and judge its cut.
    """
    from spm_opt.problem.trajectory import Trajectory
    from spm_opt.verify.executed_cut import evaluate_log, read_log_checked

    if trace is not None and log is None:
        raise InputError(f"trace {trace}: only with a log (the true state of its run)")

    trajectory = Trajectory.from_csv(plan)
    why = check_made_for(
        problem,
        trajectory.metadata,
        "plan",
        other_problem,
        refused=f"plan {plan} refused",
        hint=PLAN_HINT,
    )
    warnings = [f"plan {plan}: {why}"] if why else []
    table, run = None, None
    if log is not None:
        table, header = read_log_checked(log)
        why = check_made_for(
            problem,
            header,
            "log",
            other_problem,
            refused=f"log {log} refused",
            hint=log_hint("review"),
        )
        warnings += [f"log {log}: {why}"] if why else []
        check_run_of(trajectory, str(plan), header, str(log))
        run = evaluate_log(problem, log, trace, other_problem=other_problem)
    predicted = None
    if predict_on is not None:
        from spm_opt.execution import ExecutionSettings
        from spm_opt.verify.predicted_cut import predict_cut

        settings = ExecutionSettings(other_problem=other_problem)
        predicted = predict_cut(problem, trajectory, predict_on, settings)
    for warning in warnings:
        _LOG.warning("%s; reviewed under %s's limits as asked", warning, problem.name)
    return ReviewInputs(trajectory, table, tuple(warnings), run, predicted)
