"""What the review page and its PNG say of the cuts: the judge's verdicts, not figures of
their own. The plan is judged by :func:`spm_opt.judge.evaluate.evaluate` against the plan's tube
(the contour tolerance less the execution reserve), a run by
:func:`spm_opt.verify.executed_cut.evaluate_log` against the whole contour tolerance
(:func:`spm_opt.judge.limits.contour_tube`): the reports ``spm-opt evaluate`` prints.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.judge.limits import contour_tube
from spm_opt.model.params import MM

if TYPE_CHECKING:
    from spm_opt.judge.report import Report, Violation
    from spm_opt.problem.problem import Problem
    from spm_opt.verify.executed_cut import LogReports
    from spm_opt.verify.predicted_cut import PredictedCut

PLAN = "plan"
RUN = "run"
RUN_TRUE = "run_true"
PREDICTED = "predicted"
"""The keys of the judged cuts in the page's machine-readable verdict."""


@dataclass(frozen=True)
class Judged:
    """One cut as the judge sees it.

    Attributes
    ----------
    key : str
        :data:`PLAN`, :data:`RUN` (the log's measured angles), :data:`RUN_TRUE` (the
        plant's true angles, from a trace) or :data:`PREDICTED` (the closed-loop model's
        true angles, before the robot moves: :mod:`spm_opt.verify.predicted_cut`).
    label : str
        The cut's name for people: "planned cut", "executed cut (measured)", ...
    report : Report
        The judge's report of the cut.
    tube_mm : float or None, mm
        The half-width of the tube it is judged against (None: the problem sets none).
    """

    key: str
    label: str
    report: Report
    tube_mm: float | None

    @property
    def executed(self) -> bool:
        """Whether this is an executed cut (judged at a log's times, a predicted run's
        too), not the plan."""
        return self.key != PLAN

    @property
    def failed(self) -> bool:
        """Whether the judge rejects the cut: a violation, or a run that did not complete."""
        return not self.report.accepted


def judged_cuts(
    problem: Problem,
    plan: Report,
    run: LogReports | None = None,
    predicted: PredictedCut | None = None,
) -> list[Judged]:
    """The plan's judgement; with ``predicted``, its predicted run's; and with ``run``
    (:func:`~spm_opt.verify.executed_cut.evaluate_log`'s reports of its log), the run's:
    measured, then true when traced."""
    planned_tube, executed_tube = contour_tube(problem), contour_tube(problem, executed=True)
    cuts = [Judged(PLAN, "planned cut", plan, _mm(planned_tube))]
    if predicted is not None:
        label = f"predicted cut (on {predicted.robot})"
        cuts.append(Judged(PREDICTED, label, predicted.report, _mm(executed_tube)))
    if run is not None:
        cuts.append(Judged(RUN, "executed cut (measured)", run.measured, _mm(executed_tube)))
    if run is not None and run.true is not None:
        cuts.append(Judged(RUN_TRUE, "executed cut (true)", run.true, _mm(executed_tube)))
    return cuts


def verdict_json(cuts: list[Judged]) -> str:
    """The verdict as JSON: per cut's key, its violations as ``spm-opt evaluate --json``
    gives them (None for a cut not judged), safe inside an HTML ``<script>``."""
    data: dict[str, list[dict] | None] = {PLAN: None, PREDICTED: None, RUN: None, RUN_TRUE: None}
    data.update({cut.key: [asdict(v) for v in cut.report.violations] for cut in cuts})
    return json.dumps(data, indent=1).replace("</", "<\\/")


def tube_text(cut: Judged) -> str:
    """The tube a cut is judged against, in words: "±0.070 mm (the plan's tube)"."""
    if cut.tube_mm is None:
        return "none set"
    whose = "an executed cut's" if cut.executed else "the plan's"
    return f"±{cut.tube_mm:.3f} mm ({whose} tube)"


def verdict_line(cut: Judged) -> str:
    """One sentence of the judge's verdict on a cut, its tube named."""
    report = cut.report
    count = len(report.violations)
    said = f"{count} violation(s)" if count else "no limit is violated"
    if not getattr(report, "completed", True):
        said += f"; the run did not complete ({getattr(report, 'outcome', '')})"
    return f"The {cut.label}, judged in {tube_text(cut)}: {said}."


def violation_points(violations: list[Violation], t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Where each violation happened on a cut: the point (k, 3) of ``points`` (N, 3) whose
    time in ``t`` (N,), s, is nearest the violation's time."""
    times = np.array([v.time_s for v in violations], dtype=float).reshape(-1, 1)
    return points[np.abs(t[None, :] - times).argmin(axis=1)].reshape(-1, 3)


def _mm(tube_m: float | None) -> float | None:
    return None if tube_m is None else tube_m / MM
