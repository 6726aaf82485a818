"""The toppra planner: time-optimal motion along the exact contour, at rest at every
landmark, jerk-limited and within every limit of the problem."""

from __future__ import annotations

import dataclasses
import time

from spm_opt.planners.path import joint_paths
from spm_opt.planners.toppra.constraints import plan_limits
from spm_opt.planners.toppra.segment import (
    chained,
    piece_statistics,
    segment_motion,
    visiting_trajectory,
)
from spm_opt.planners.toppra.settings import NAME, ToppraSettings, toppra_settings
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory


class ToppraPlanner:
    """Time-optimal motion along the planned contour, at rest at every landmark, within every
    limit of the problem; see :mod:`spm_opt.planners.toppra`."""

    name = NAME

    def settings(self, problem: Problem) -> ToppraSettings:
        return toppra_settings(problem)

    def plan(self, problem: Problem) -> Trajectory:
        settings = self.settings(problem)
        started = time.perf_counter()
        limits = plan_limits(problem, settings)
        pieces = [
            segment_motion(problem, limits, k, segment, settings)
            for k, segment in enumerate(joint_paths(problem, settings.path_samples))
        ]
        samples, starts = chained(pieces)
        statistics = {
            "status": "Ok",
            "solve_time_s": time.perf_counter() - started,
            "gridpoints": settings.gridpoints,
            "samples": int(samples[0].size),
            **piece_statistics(pieces),
            "toppra_runs": [piece.runs for piece in pieces],
            "settings": dataclasses.asdict(settings),
        }
        return visiting_trajectory(problem, samples, starts, statistics)
