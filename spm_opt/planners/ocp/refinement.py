"""Every plan clean, by construction: what to change after the evaluator finds a solution
exceeding a limit between the points where the NLP imposes it.

After each solve the evaluator re-measures the plan; if it finds a limit exceeded, each
interval where the solution exceeds a bound between its check points gets its nearest check
point moved there (the check points' places are NLP parameters: the same NLP, continued
from the solution and its multipliers; the evaluator's findings of that limit's rules count
as cured by the move, so a cut found outside the tube there counts as the cause of the
contour it left uncut), a limit with on-demand rows (backtracking) gets them at the check
points (a new NLP, solved from x), and any other limit the evaluator finds exceeded gets its
bound tightened by the excess; up to :data:`REFINEMENTS` rounds, then a planning error.
Without an energy term the NLP starts without the torque rows, and gets them only when the
model's torques at the Gauss points exceed the bound (:func:`torque_exceeded`).
"""

from __future__ import annotations

import dataclasses
from functools import cache

import casadi as ca
import numpy as np

from spm_opt.base.errors import PlanningError
from spm_opt.judge.limits import RELATIVE_TOLERANCE, PlannerBounds
from spm_opt.judge.report import Violation
from spm_opt.model.joint_torque import joint_side_torque
from spm_opt.planners.ocp.constraints import ON_DEMAND, keeping
from spm_opt.planners.ocp.diagnostics import excess
from spm_opt.planners.ocp.parameters import arcs
from spm_opt.planners.ocp.point import GAUSS_FRACTIONS, INSIDE
from spm_opt.planners.ocp.settings import OcpSettings
from spm_opt.planners.ocp.transcription import (
    Grid,
    RowGroup,
    default_fractions,
    interval_function,
    row_groups,
)
from spm_opt.problem.problem import Problem

REFINEMENTS = 5
"""Re-solves, each with check points moved and tighter bounds for whatever the evaluator
found exceeded between the constraint points, before the planner gives up. A minimum-energy
cut rides the tube's edge, and each re-solve may bulge out elsewhere: of 400 random flaps
two needed all of three rounds or more (varied flap 101: 0.063, 0.062, 0.058 mm against
0.057 mm, clean at the third)."""
COVERAGE_TIGHTENING = 0.95
"""Factor on the contour bound when the cut leaves a stretch uncut without a deviation
beyond the tube (the gap's length says nothing about how much tighter to go)."""
PROBE_EXCESS = 1e-6
"""Relative excess over a bound below which a probed point counts as within it."""
PROBE_POINTS = 24
"""Points inside each interval where a solution is probed for limits exceeded between its
check points."""


@cache
def probe(segments: int, settings: OcpSettings) -> tuple[ca.Function, tuple[RowGroup, ...]]:
    """The interval function with :data:`PROBE_POINTS` check points, mapped over the grid,
    and its row groups."""
    grid = settings.grid(segments)
    interval = interval_function(PROBE_POINTS, False, None, 0, ON_DEMAND)
    return interval.map(grid.intervals), row_groups(PROBE_POINTS, False, ON_DEMAND)


def moved_check_points(
    problem: Problem,
    settings: OcpSettings,
    bounds: PlannerBounds,
    x: np.ndarray,
    fractions: np.ndarray,
    demanded: frozenset[str],
) -> tuple[np.ndarray, set[str]]:
    """The check fractions with, in every interval where x exceeds a bound between its
    check points, the check nearest to the worst place moved there; and the evaluator's
    rules of the limits so exceeded (on-demand rows count once ``demanded``)."""
    grid = settings.grid(len(problem.segment_durations))
    mapped, groups = probe(grid.segments, settings)
    states, jerks, durations = grid.split(x)
    places = default_fractions(PROBE_POINTS)
    _, rows, _ = mapped(
        states[:-1].T,
        jerks.T,
        (grid.interval_matrix @ durations)[None, :],
        (arcs(problem).T)[:, grid.interval_segments],
        np.tile(places[:, None], (1, grid.intervals)),
        np.zeros(0),
    )
    rows = rows.full().T  # (M, probe rows)
    worst = np.full((grid.intervals, PROBE_POINTS), -np.inf)
    found: set[str] = set()
    for group in groups:
        if group.place != INSIDE or group.constraint.waiting(group.place, demanded):
            continue
        low, high = (np.asarray(v, dtype=float) for v in group.limits(bounds))
        values = rows[:, group.start : group.start + group.size]
        relative = np.max(
            excess(values, low[None, :], high[None, :], group.constraint.squared), axis=1
        )
        if np.max(relative) > PROBE_EXCESS:
            found.update(group.limit.rules)
        worst[:, group.point] = np.maximum(worst[:, group.point], relative)
    exceeded = np.flatnonzero(np.max(worst, axis=1) > PROBE_EXCESS)
    moved = fractions.copy()
    for interval in exceeded:
        place = places[int(np.argmax(worst[interval]))]
        nearest = int(np.argmin(np.abs(moved[:, interval] - place)))
        moved[nearest, interval] = place
    return moved, found


def tightened(bounds: PlannerBounds, violations: list[Violation]) -> PlannerBounds:
    """``bounds`` with the bound of each limit whose rule the evaluator found broken
    (:func:`~spm_opt.planners.ocp.constraints.keeping`) cut by the excess (worst / limit),
    and half the evaluator's tolerance more."""
    factors: dict[str, float] = {}
    for violation in violations:
        limit = keeping(violation.rule)
        if limit is None or limit.bound is None:
            raise PlanningError(f"the plan breaks a limit no bound keeps: {violation}")
        factor = COVERAGE_TIGHTENING
        if violation.rule != "coverage":
            factor = abs(violation.allowed / violation.worst) * (1 - RELATIVE_TOLERANCE / 2)
        factors[limit.bound] = min(factors.get(limit.bound, 1.0), factor)
    return dataclasses.replace(
        bounds, **{name: getattr(bounds, name) * f for name, f in factors.items()}
    )


def torque_exceeded(problem: Problem, grid: Grid, bounds: PlannerBounds, x: np.ndarray) -> bool:
    """Whether the joint side torques (:func:`~spm_opt.model.joint_torque.joint_side_torque`)
    at the Gauss points of x's intervals (where the NLP would impose them) exceed
    ``bounds``' torque bound."""
    motion = grid.trajectory(x, {})
    nodes = grid.node_times(grid.split(x)[2])
    t = np.concatenate([nodes[:-1] + f * np.diff(nodes) for f in GAUSS_FRACTIONS])
    q, qd, qdd = motion.position(t), motion.velocity(t), motion.acceleration(t)
    torque = joint_side_torque(problem.robot, q, qd, qdd)
    return bool(np.max(np.abs(torque)) > bounds.load_torque)
