"""The limits toppra gets on a segment, as its linear constraints in the path acceleration
u = s̈ and x = ṡ², at the segment's gridpoints.

By toppra's interpolation scheme each gridpoint's constraints hold again at the next one:

- joint speed |q'| ṡ ≤ ω and tool speed k(s) ṡ ≤ v, with k the cut point's speed per unit
  ṡ as the contour measures it (ρ|ṗ| and ρ' φ̇): bounds on x;
- joint acceleration q̈ = q' u + q'' x within ±a;
- actuator torque from the one model, τ = (M + J)(q' u + q'' x) + h(q, q') x + g(q) + f
  (:mod:`spm_opt.planners.path`): exact in toppra's form, the friction f(q, q') a constant
  per gridpoint. Only where the sliding direction reverses between gridpoints is it
  bounded: each gridpoint's bound allows every friction value of it and its neighbours (and
  0, at rest, at the ends). The bound on |τ| is :mod:`spm_opt.judge.limits`' load-torque bound
  (the gear efficiency and the continuous current taken into account there).

Each limit is given to toppra as a share of it (:class:`Shares`); the acceleration and
jerk are the bounds that keep a feed hold its room
(:func:`spm_opt.judge.limits.planner_bounds`, :mod:`spm_opt.judge.hold_room`), read once per
plan (:class:`PlanLimits`). Starting and stopping at joint acceleration a cost
t_a = ω_c / a over the cruise (ω_c the fastest joint's cruise speed at the segment's ends)
and the smoothing adds T_w ≈ a / j (:mod:`spm_opt.planners.toppra.smoothing`), least in sum
at a = √(ω_c j), where the averaged start is the jerk-limited time-optimal one (a triangle
of acceleration): toppra is given that acceleration, or the limit if lower.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from spm_opt.base.errors import PlanningError
from spm_opt.judge.limits import PlannerBounds, planner_bounds, torque_limit
from spm_opt.model.params import MM
from spm_opt.planners.path import PathPoints
from spm_opt.planners.toppra.settings import ToppraSettings
from spm_opt.problem.problem import Problem

SPEED_SLACK = 1e-4
"""Relative excess of a speed limit left to rounding; shares are cut this much below it."""


@dataclass(frozen=True)
class PlanLimits:
    """The problem's limits as one plan's toppra runs read them, built once per plan.

    Attributes
    ----------
    bounds : PlannerBounds
        :func:`~spm_opt.judge.limits.planner_bounds` without a margin (the shares keep it).
    jerk : float or None
        The joint jerk the smoothing keeps within, rad/s³: the limit less the settings'
        margin (None: unlimited).
    actuator_torque : float
        The largest torque the actuators may deliver, N·m
        (:func:`~spm_opt.judge.limits.torque_limit`).
    """

    bounds: PlannerBounds
    jerk: float | None
    actuator_torque: float


def plan_limits(problem: Problem, settings: ToppraSettings) -> PlanLimits:
    """The limits every toppra run of one plan of ``problem`` reads."""
    bounds = planner_bounds(problem, 0.0)
    limit = bounds.joint_jerk
    jerk = None if limit is None else limit * (1.0 - settings.margin)
    return PlanLimits(bounds, jerk, torque_limit(problem))


@dataclass(frozen=True)
class Shares:
    """The share of each limit given to toppra (1: the limit itself). The speeds start at
    1 (a moving average of feasible speeds stays feasible where the bound is flat); the
    acceleration and torque keep the settings' margin. Whatever the smoothed motion still
    exceeds is cut by the excess, and toppra runs again."""

    joint_speed: float = 1.0
    tool_speed: float = 1.0
    acceleration: float = 1.0
    torque: float = 1.0

    def tightened(self, excess: dict[str, float]) -> Shares:
        """Each share in ``excess`` (limit name: peak / limit) divided by its excess."""
        cut = {k: getattr(self, k) / ratio * (1.0 - SPEED_SLACK) for k, ratio in excess.items()}
        return dataclasses.replace(self, **cut)


def first_shares(settings: ToppraSettings) -> Shares:
    """The shares of the limits toppra gets first: the acceleration and torque keep the
    settings' margin."""
    keep = 1.0 - settings.margin
    return Shares(acceleration=keep, torque=keep)


@dataclass(frozen=True)
class Constraints:
    """Every limit at N gridpoints as low ≤ a u + b x + c ≤ high, and x ≤ x_max, with u in
    mm/s² and x in mm²/s²: arrays (N, m), one column per row of ``rows`` ((what, unit)),
    whose nominal bound is ``limit`` (m,)."""

    rows: tuple[tuple[str, str], ...]
    limit: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    low: np.ndarray
    high: np.ndarray
    x_max: np.ndarray

    def per_unit(self, unit: float) -> Constraints:
        """The same limits for the path parameter s / unit (unit in mm)."""
        return dataclasses.replace(
            self, a=self.a * unit, b=self.b * unit**2, x_max=self.x_max / unit**2
        )

    def at_rest(self, index: int) -> list[str]:
        """The rows that fail with the path at rest (u = x = 0) at gridpoint ``index``, in
        words: what they need there against their bound."""
        c, low, high = self.c[index], self.low[index], self.high[index]
        need = self.limit + np.maximum(c - high, low - c)
        return [
            f"{what} {need[k]:.4g} {unit} (allowed {self.limit[k]:.4g} {unit})"
            for k, (what, unit) in enumerate(self.rows)
            if need[k] > self.limit[k]
        ]


def _friction_range(friction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest friction torque (N, 2) over each gridpoint and its neighbours,
    and 0 (at rest) at the two ends."""
    padded = np.concatenate([friction[:1], friction, friction[-1:]])
    near = np.stack([padded[:-2], padded[1:-1], padded[2:]])
    low, high = near.min(axis=0), near.max(axis=0)
    low[[0, -1]] = np.minimum(low[[0, -1]], 0.0)
    high[[0, -1]] = np.maximum(high[[0, -1]], 0.0)
    return low, high


def speed_bound(
    problem: Problem, bounds: PlannerBounds, q: np.ndarray, dq: np.ndarray, shares: Shares
) -> np.ndarray:
    """Largest ṡ², mm²/s², at joint angles q (N, 2) with path tangents q' (N, 2), rad/mm:
    each joint within its share of its speed bound and the cut point within its share of
    the tool-speed bound (``bounds``)."""
    pace = np.max(np.abs(dq), axis=1) / (bounds.joint_speed * shares.joint_speed)  # s/mm
    if bounds.tool_speed is not None:
        stretch = problem.contour.joint_tool_speed(q, dq) / MM
        pace = np.maximum(pace, stretch / (bounds.tool_speed / MM * shares.tool_speed))
    return 1.0 / pace**2


def _constraints(
    points: PathPoints,
    x_max: np.ndarray,
    torque: float,
    acceleration: float | None,
) -> Constraints:
    """The limits at one segment's gridpoints (``points``), with x_max (N,) their largest
    ṡ², mm²/s², ``torque`` the bound on |τ| given to toppra, N·m, and ``acceleration`` the
    joint acceleration bound, rad/s² (None: unlimited)."""
    q, dq, ddq = points.q, points.dq, points.ddq
    friction_low, friction_high = _friction_range(points.friction)
    rows = (("actuator 1 torque", "N·m"), ("actuator 2 torque", "N·m"))
    limit = np.full(2, torque)
    a = np.einsum("nij,nj->ni", points.inertia, dq)
    b = np.einsum("nij,nj->ni", points.inertia, ddq) + points.bias
    c = points.gravity
    low, high = -torque - friction_low, torque - friction_high
    if acceleration is not None:
        rows += (("theta1 acceleration", "rad/s²"), ("theta2 acceleration", "rad/s²"))
        limit = np.append(limit, [acceleration, acceleration])
        a, b, c = np.hstack([a, dq]), np.hstack([b, ddq]), np.hstack([c, np.zeros_like(c)])
        low, high = (
            np.hstack([low, np.full_like(q, -acceleration)]),
            np.hstack([high, np.full_like(q, acceleration)]),
        )
    return Constraints(rows, limit, a, b, c, low, high, x_max)


def _toppra_acceleration(
    limits: PlanLimits, dq: np.ndarray, x_max: np.ndarray, shares: Shares
) -> float | None:
    """The joint acceleration bound, rad/s², given to toppra: the limit, or less where the
    jerk limit makes a gentler start faster (a = √(ω_c j), see the module docstring), with
    ω_c from the path tangents q' (2, 2), rad/mm, and the largest ṡ² (2,), mm²/s², at the
    segment's two ends."""
    limit = limits.bounds.joint_acceleration
    bound = None if limit is None else limit * shares.acceleration
    if limits.jerk is None:
        return bound
    cruise = float(np.max(np.abs(dq) * np.sqrt(x_max)[:, None]))
    gentle = math.sqrt(cruise * limits.jerk)
    return gentle if bound is None else min(bound, gentle)


def _check_rest(problem: Problem, segment: int, constraints: Constraints) -> None:
    """Refuse a segment at whose end landmarks the robot cannot be held still (every segment
    starts and ends at rest)."""
    names = problem.visit_names
    for index, landmark in ((0, names[segment]), (-1, names[segment + 1])):
        failing = constraints.at_rest(index)
        if failing:
            raise PlanningError(
                f"max_joint_torque_nm = {problem.max_joint_torque:g}: holding the robot still "
                f"at {landmark} against gravity and friction takes {'; '.join(failing)}"
            )


def toppra_constraints(
    problem: Problem,
    limits: PlanLimits,
    index: int,
    points: PathPoints,
    x_max: np.ndarray,
    shares: Shares,
) -> tuple[Constraints, float | None]:
    """The limits toppra gets on segment ``index`` at its gridpoints (``points``, with
    their largest ṡ² x_max (N,), mm²/s²), once the robot is known to rest at its ends; and
    the joint acceleration bound among them, rad/s² (None: unlimited)."""
    ends = [0, -1]
    acceleration = _toppra_acceleration(limits, points.dq[ends], x_max[ends], shares)
    torque = limits.bounds.load_torque * shares.torque
    constraints = _constraints(points, x_max, torque, acceleration)
    _check_rest(problem, index, constraints)
    return constraints, acceleration
