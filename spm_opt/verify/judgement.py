"""The judge's one entry for whatever a person has: a plan or an execution log.

A plan (a :class:`~spm_opt.problem.trajectory.Trajectory` or its CSV) is judged by
:func:`spm_opt.judge.evaluate.evaluate`; a log by
:func:`spm_opt.verify.executed_cut.evaluate_log` on its own samples from the plan's start
on, by the same rules (the measured cut's report; that function judges the plant's true
state too). ``so.evaluate`` is this function.
"""

from __future__ import annotations

from pathlib import Path

from spm_opt.judge import evaluate as plan_judge
from spm_opt.judge.evaluate import DEFAULT_RATE_HZ
from spm_opt.judge.report import Report
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.verify.executed_cut import evaluate_log, is_execution_log


def evaluate(
    problem: Problem,
    trajectory: Trajectory | str | Path,
    rate_hz: float = DEFAULT_RATE_HZ,
    *,
    other_problem: bool = False,
) -> Report:
    """Judge ``trajectory`` against ``problem``.

    Parameters
    ----------
    problem : Problem
    trajectory : Trajectory, or the path of a trajectory CSV or of an execution log CSV
        A log's report is an :class:`~spm_opt.verify.executed_cut.ExecutionReport`.
    rate_hz : float
        Sampling rate of a plan's evaluation grid, Hz (default 1 kHz; a log keeps its own).
    other_problem : bool
        Judge a plan file or a log under ``problem`` though it was made for (ran under)
        another, or records none; without it, either is refused with a one-line
        :class:`~spm_opt.base.errors.InputError`.
    """
    if isinstance(trajectory, str | Path) and is_execution_log(trajectory):
        return evaluate_log(problem, trajectory, other_problem=other_problem).measured
    return plan_judge.evaluate(problem, trajectory, rate_hz, other_problem=other_problem)
