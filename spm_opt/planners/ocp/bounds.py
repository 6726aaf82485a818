"""The NLP's bounds for one problem: the variables' (the limits of
:data:`~spm_opt.planners.ocp.constraints.LIMITS` that bound q, q̇, q̈ or the jerk; the
landmarks' angles; rest at both ends; the intervals' lengths) and the rows' (the limits'
constraint rows, the segment and total durations as the planner's timing keeps them)."""

from __future__ import annotations

import numpy as np

from spm_opt.judge.bounds import segment_lower_bounds
from spm_opt.judge.limits import PlannerBounds
from spm_opt.planners.ocp.constraints import ACCELERATION, JERK, LIMITS, POSITION, VELOCITY
from spm_opt.planners.ocp.nlp import Nlp
from spm_opt.planners.ocp.point import NODE
from spm_opt.planners.ocp.transcription import STATE
from spm_opt.problem.problem import Problem

MIN_INTERVAL_S = 1e-4
"""Shortest interval of the time grid, s. A phase squeezed to 1 ms in all (0.06 ms an
interval: a minimum-jerk re-solve on a random flap) leaves the plan's samples consistent
only to IPOPT's tolerance over a span too short for it, and the motion rebuilt from them
swings (5e5 rad/s³). Kept well below the intervals plans use, since IPOPT's path depends on
it: on the paper's flap, 41 and 92 iterations (minimum time, energy) at 0.1 ms, 64 and 208
at 1 ms."""

_STATE_COLUMNS = {POSITION: slice(0, 2), VELOCITY: slice(2, 4), ACCELERATION: slice(4, 6)}
"""Where each bounded variable stands in a node's state (q, q̇, q̈)."""


def nlp_bounds(
    problem: Problem,
    nlp: Nlp,
    bounds: PlannerBounds,
    timing: str,
    durations: np.ndarray,
) -> dict[str, np.ndarray]:
    """lbx, ubx, lbg, ubg for one problem within ``bounds`` (the problem's limits as
    :mod:`spm_opt.judge.limits` translates them for a planner); ``durations``: the initial phase
    durations (D,), s."""
    grid = nlp.grid
    m = grid.intervals
    low, high = np.full((m + 1, STATE), -np.inf), np.full((m + 1, STATE), np.inf)
    jerk_low, jerk_high = np.full(2, -np.inf), np.full(2, np.inf)
    for limit in LIMITS:
        if limit.variable == JERK:
            jerk_low, jerk_high = limit.box(bounds)
        elif limit.variable is not None:
            columns = _STATE_COLUMNS[limit.variable]
            low[:, columns], high[:, columns] = limit.box(bounds)
    landmarks = grid.landmark_nodes
    low[landmarks, 0:2] = high[landmarks, 0:2] = problem.waypoint_angles
    low[[0, -1], 2:6] = high[[0, -1], 2:6] = 0.0
    longest = 20.0 * np.max(durations) + 1.0
    shortest = MIN_INTERVAL_S * np.tile(grid.counts, grid.segments)
    lbx = np.concatenate([low.ravel(), np.tile(jerk_low, m), shortest])
    ubx = np.concatenate([high.ravel(), np.tile(jerk_high, m), np.full(3 * grid.segments, longest)])

    limits = [group.limits(bounds) for group in nlp.groups]
    row_low = np.concatenate([np.zeros(STATE), *(low for low, _ in limits)])
    row_high = np.concatenate([np.zeros(STATE), *(high for _, high in limits)])
    interval_low, interval_high = np.tile(row_low, (m, 1)), np.tile(row_high, (m, 1))
    for group in nlp.groups:
        if group.place == NODE and not group.constraint.at_landmarks:
            columns = slice(STATE + group.start, STATE + group.start + group.size)
            interval_low[landmarks[:-1], columns] = -np.inf
            interval_high[landmarks[:-1], columns] = np.inf

    segments = (0.5 * segment_lower_bounds(problem), np.full(grid.segments, np.inf))
    total = (0.0, np.inf)
    given = float(np.sum(problem.segment_durations))
    if timing == "segments":
        segments = (problem.segment_durations, problem.segment_durations)
    elif timing == "total":
        total = (given, given)
    elif timing == "bounded":
        total = (0.0, given)
    return {
        "lbx": lbx,
        "ubx": ubx,
        "lbg": np.concatenate([interval_low.ravel(), segments[0], [total[0]]]),
        "ubg": np.concatenate([interval_high.ravel(), segments[1], [total[1]]]),
    }
