"""An optimal-control planner: checks what no solver can do, solves from its starts in
turn, and solves again until the evaluator finds the plan clean
(:mod:`~spm_opt.planners.ocp.refinement`).

The planner judges its own plans because the judgement decides what it does next: a clean
plan is returned, a broken one solved again with check points moved and bounds tightened.
The returned plan's report stays with it (:func:`spm_opt.judge.evaluate.evaluate` keeps each
trajectory's report), so whoever asked judges it without measuring it again."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from spm_opt.base.errors import PlanningError
from spm_opt.judge.evaluate import evaluate
from spm_opt.judge.limits import PlannerBounds
from spm_opt.model.joint_torque import range_key
from spm_opt.model.params import MM
from spm_opt.planners.ocp.constraints import ON_DEMAND
from spm_opt.planners.ocp.feasibility import check_feasible_at_all
from spm_opt.planners.ocp.guess import initial_guess, segment_durations
from spm_opt.planners.ocp.path_planner import plan_in_path_coordinates
from spm_opt.planners.ocp.refinement import (
    REFINEMENTS,
    moved_check_points,
    tightened,
    torque_exceeded,
)
from spm_opt.planners.ocp.settings import OcpSettings
from spm_opt.planners.ocp.solve import Solution, added, solve
from spm_opt.planners.ocp.transcription import Grid, default_fractions
from spm_opt.planners.ocp.warm_start import SOLVED, Solved
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory


@dataclass(frozen=True)
class OcpPlanner:
    """An optimal-control planner with fixed weights (:class:`OcpSettings` defaults) and
    the start its solves try first."""

    name: str
    defaults: OcpSettings
    start: Callable[[Problem], Trajectory] | None = None

    def settings(self, problem: Problem) -> OcpSettings:
        """The problem's ``[planner.NAME]`` settings over this planner's defaults."""
        return OcpSettings.from_problem(problem, self.name, self.defaults)

    def plan(self, problem: Problem, warm_start: Trajectory | None = None) -> Trajectory:
        """Solve; ``warm_start`` (a plan of a similar problem with the same landmark visits)
        replaces the contour-following initial guess.

        Without an energy term the dynamics enter only through the torque limit, which is
        far from binding on this robot: the NLP is first solved without it, and solved again
        with it (from the first solution) only if the model's torques at the constraint
        points exceed it. Both give the same optimum when it does not bind.
        """
        settings = self.settings(problem)
        plannable = check_feasible_at_all(problem, settings.timing, settings.margin)
        bounds = plannable.bounds
        if in_path_coordinates(settings, bounds):
            return plan_in_path_coordinates(problem, settings, bounds, self.name, warm_start)
        need = plannable.lower_bounds / (1 - settings.margin)
        grid = settings.grid(len(problem.segment_durations))
        with_torque = settings.energy_weight > 0.0
        fractions = np.tile(
            default_fractions(settings.checks_per_interval)[:, None], grid.intervals
        )
        demanded: frozenset[str] = frozenset()
        shape = (
            len(problem.segment_durations),
            settings,
            with_torque,
            range_key(problem.robot.joint_range),
        )
        starts: list[Trajectory | Solved | None] = (
            [warm_start] if warm_start is not None else self._starts(problem)
        )
        solved = SOLVED.get(warm_start) if warm_start is not None else None
        if solved is not None and solved.shape == shape:
            starts.insert(0, solved)
        for number, start in enumerate(starts, 1):
            try:
                if isinstance(start, Solved):  # its solution and multipliers: continue
                    fractions, demanded = start.fractions, start.demanded
                    begin: np.ndarray | Solution = start.solution
                else:
                    durations = segment_durations(problem, settings.timing, need, start)
                    begin = initial_guess(problem, grid, durations, start)
                solution = solve(
                    self.name, problem, settings, bounds, fractions, with_torque, demanded, begin
                )
                break
            except PlanningError:
                if number == len(starts):
                    raise
        statistics = {
            **solution.statistics,
            "starts_tried": number,
            "start": _start_kind(start),
            "transcription": "time",
        }
        # how far the radius the NLP reads strays from the skull's surface (a mesh's facets)
        fit_error = max(fit.max_error for fit in problem.arc_radius_fits)
        statistics["skull_fit_error_mm"] = fit_error / MM
        moved_checks = 0
        for round_ in range(1, REFINEMENTS + 2):
            if not with_torque and torque_exceeded(problem, grid, bounds, solution.x):
                with_torque = True  # new rows: a fresh start from x
                solution = solve(
                    self.name, problem, settings, bounds, fractions, True, demanded, solution.x
                )
                statistics = added(statistics, solution.statistics)
            statistics["refinements"] = round_ - 1
            statistics["check_points_moved"] = moved_checks
            trajectory = self._trajectory(problem, grid, solution.x, statistics, settings)
            broken = evaluate(problem, trajectory).violations  # decides: return or refine
            if not broken:
                SOLVED[trajectory] = Solved(shape, fractions, demanded, solution)
                return trajectory
            if round_ > REFINEMENTS:
                break
            newly = {v.rule for v in broken if v.rule in ON_DEMAND} - demanded
            demanded |= newly  # its rows at the check points from now on
            moved, found = moved_check_points(
                problem, settings, bounds, solution.x, fractions, demanded
            )
            moved_checks += int(np.sum(moved != fractions))
            fractions = moved
            if round_ == 1:  # later, what moved check points did not cure is tightened
                broken = [v for v in broken if v.rule not in found]
            broken = [v for v in broken if v.rule not in newly]
            # from x alone after tighter bounds or new rows: continuing with the multipliers
            # of looser bounds as well halves the iterations but ends in worse optima (five
            # landmarks: ∫τᵀτ 0.885 against 0.855); new rows have none. The same problem
            # with a few check points moved continues with them.
            bounds = tightened(bounds, broken)
            begin = solution.x if broken or newly else solution
            solution = solve(
                self.name, problem, settings, bounds, fractions, with_torque, demanded, begin
            )
            statistics = added(statistics, solution.statistics)
        raise PlanningError(
            f"{self.name}: the evaluator still finds {'; '.join(map(str, broken))} after "
            f"{REFINEMENTS} re-solves with check points moved and tighter bounds; raise "
            f"planner.{self.name}.checks_per_interval or margin"
        )

    def _starts(self, problem: Problem) -> list[Trajectory | None]:
        """The motions a solve starts from, in turn while IPOPT fails from them:
        :attr:`start` of the problem (unless it fails), then the contour-following guess
        (None). The near-optimal start finds the better optimum (the paper's flap 37.87 s
        against 38.09 s), the contour the more robust one (the five-landmark flap fails
        from the near-optimal start)."""
        if self.start is None:
            return [None]
        try:
            return [self.start(problem), None]
        except PlanningError:
            return [None]

    def _trajectory(
        self,
        problem: Problem,
        grid: Grid,
        x: np.ndarray,
        statistics: dict[str, Any],
        settings: OcpSettings,
    ) -> Trajectory:
        """The plan x describes, with its landmark times and the solver's statistics."""
        _, _, durations = grid.split(x)
        landmark_times = grid.node_times(durations)[grid.landmark_nodes]
        metadata = {
            "landmark_times_s": landmark_times.tolist(),
            "landmarks": problem.visit_names,
            "statistics": {**statistics, "settings": dataclasses.asdict(settings)},
        }
        return grid.trajectory(x, metadata)


def in_path_coordinates(settings: OcpSettings, bounds: PlannerBounds) -> bool:
    """Whether ``settings`` plan in path coordinates: ``"path"``, or ``"auto"`` on a problem
    with a contour tube (``bounds``: the problem's, as the planner imposes them) (on the
    hardware run, which has none, the cut left the contour by
    33 mm, far beyond what the offset's first-order model of the motion holds for, and
    minimum energy's ∫τᵀτ came out 0.128 N²·m²·s against 0.042 in the time domain)."""
    if settings.transcription == "auto":
        return bounds.contour_tolerance is not None
    return settings.transcription == "path"


def _start_kind(start: Trajectory | Solved | None) -> str:
    """How a solve started: from a plan's "solution" and multipliers, a plan's "motion"
    re-timed, or the "contour"-following guess."""
    if isinstance(start, Solved):
        return "solution"
    return "contour" if start is None else "motion"
