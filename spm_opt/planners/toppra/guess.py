"""A near-time-optimal motion along the contour in milliseconds, from toppra's first run:
the start of the minimum-time optimal control in the time domain.

The first toppra run of every segment with the same limits and shares as the planner's, on a
coarse grid (:data:`GUESS_GRIDPOINTS` gridpoints, a path through :data:`GUESS_PATH_SAMPLES`
samples; the model evaluated once for all segments), and toppra's own motion (no uniform
time grid) averaged once over the first window, max(a / j, ``min_smoothing_s``). Left out:
the rescaling of the window by the measured jerk, the measuring of the smoothed motion and
the runs with tighter shares, so the guess may exceed a limit by a little (the speeds by
what the average and the coarse grid add, the jerk by what the window's first estimate
misses). Its segments start and end at rest and last within 0.5 % of the plan's where the
jerk is limited; without a jerk limit toppra's ramps last a few ms, which the plan's time
grid cuts at a cost the guess does not pay (its 0.25 s segments of the hardware problem
are 0.7–1.4 % shorter than the plan's, within 0.5 % of toppra's on the fine grid).

It lives with toppra, not with the optimal control that starts from it: it is made of
toppra's parts (its constraints, LP and smoothing, with the toppra planner's settings), and
the optimal control reads nothing of it but the motion it returns.
"""

from __future__ import annotations

import time

import numpy as np

from spm_opt.planners.path import JointPath, joint_paths, path_points
from spm_opt.planners.toppra.constraints import (
    Constraints,
    PlanLimits,
    first_shares,
    plan_limits,
    speed_bound,
    toppra_constraints,
)
from spm_opt.planners.toppra.lp import path_speeds
from spm_opt.planners.toppra.segment import (
    Piece,
    chained,
    gridpoints,
    joint_samples,
    piece_statistics,
    visiting_trajectory,
)
from spm_opt.planners.toppra.settings import ToppraSettings, toppra_settings
from spm_opt.planners.toppra.smoothing import (
    average_knots,
    moving_average,
    path_profile,
    toppra_steps,
)
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

GUESS_GRIDPOINTS = 30
"""toppra's gridpoints per segment in :func:`time_optimal_guess` (the planner's: 800):
enough to keep the guess's segments within 0.5 % of the plan's (20 are not: 1.2 %)."""
GUESS_PATH_SAMPLES = 30
"""Inverse-kinematics samples per segment of the guess's path (the planner's: 100)."""


def time_optimal_guess(problem: Problem) -> Trajectory:
    """A near-time-optimal motion along the contour, at rest at every landmark, in a few
    milliseconds: the start for the minimum-time optimal control (see the module
    docstring). Its metadata has ``landmark_times_s`` (s), ``landmarks`` and
    ``statistics``.

    Raises
    ------
    PlanningError
        Where the toppra planner's first run fails (the same messages).
    """
    settings = toppra_settings(problem)
    started = time.perf_counter()
    pieces = _rough_pieces(problem, plan_limits(problem, settings), settings)
    samples, starts = chained(pieces)
    statistics = {
        "solve_time_s": time.perf_counter() - started,
        "gridpoints": GUESS_GRIDPOINTS,
        "samples": int(samples[0].size),
        **piece_statistics(pieces),
    }
    return visiting_trajectory(problem, samples, starts, statistics)


def _rough_pieces(problem: Problem, limits: PlanLimits, settings: ToppraSettings) -> list[Piece]:
    """Every segment's motion for the guess: toppra on the coarse grid within the first
    shares of the limits, averaged over the first window; the model evaluated once for all
    segments."""
    shares, jerk = first_shares(settings), limits.jerk
    segments = joint_paths(problem, GUESS_PATH_SAMPLES)
    grids = [gridpoints(segment.length, GUESS_GRIDPOINTS) for segment in segments]
    derivatives = [segment.derivatives(s) for segment, s in zip(segments, grids, strict=True)]
    points = path_points(problem, *(np.vstack(order) for order in zip(*derivatives, strict=True)))
    x_max = speed_bound(problem, limits.bounds, points.q, points.dq, shares)
    pieces = []
    for k, (segment, s) in enumerate(zip(segments, grids, strict=True)):
        part = slice(k * GUESS_GRIDPOINTS, (k + 1) * GUESS_GRIDPOINTS)
        constraints, acceleration = toppra_constraints(
            problem, limits, k, points[part], x_max[part], shares
        )
        first = 0.0 if jerk is None or acceleration is None else acceleration / jerk
        width = max(first, settings.min_smoothing_s)
        pieces.append(_rough_piece(problem, k, segment, s, constraints, acceleration, width))
    return pieces


def _rough_piece(
    problem: Problem,
    index: int,
    segment: JointPath,
    s: np.ndarray,
    constraints: Constraints,
    acceleration: float | None,
    width: float,
) -> Piece:
    """toppra's motion along segment ``index`` at gridpoints s (N,), mm, within
    ``constraints`` (``acceleration`` the joint acceleration bound among them, rad/s²),
    averaged over ``width`` s and sampled at every knot of the average."""
    speed = path_speeds(segment, s, constraints)
    profile = path_profile(toppra_steps(s, speed), speed, s[:-1], float(s[-1]))
    t = average_knots(profile.x[1:-1], width)
    path_s, sd, sdd, _ = moving_average(profile, width, t)
    q, qd, qdd = joint_samples(problem, index, segment, path_s, sd, sdd)
    return Piece(t, q, qd, qdd, float(profile.x[-2]), width, acceleration)
