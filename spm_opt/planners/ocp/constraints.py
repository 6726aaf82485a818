"""The constraint table: every limit the optimal-control planners keep, declared once.

A :class:`Limit` names the bound that keeps it (a field of
:class:`~spm_opt.judge.limits.PlannerBounds`), the evaluator's rules
(:data:`spm_opt.judge.limits.RULES`) it answers for, and how the NLP keeps it: by rows of one
interval's function (its constraints, :class:`Constraint`), by the bounds of a variable (q, q̇, q̈ at
the nodes, the jerk on the intervals), or both. The NLP's rows and their bounds, the
variables' bounds, the report of the most violated row, the probe that moves check points
and the bounds tightened after the evaluator finds a limit exceeded all read
:data:`LIMITS`: adding a limit is one entry.

Every constraint row is evaluated at some places of an interval
(:mod:`~spm_opt.planners.ocp.point`): the node that starts it, check points inside it at
fractions that are parameters (so the planner can move them to where a limit was exceeded
without changing the NLP's shape), its two Gauss points, or, for the joint speed, the
middle Bernstein coefficient of q̇ (q̇ is quadratic on an interval: its node values and
this coefficient bound it everywhere on the interval, exactly). So the rows are: the tool
speed, the contour tube and the segment's ends at the node and at ``checks_per_interval``
check points, the cut's progress along its arc never negative at the node (and at the
check points once the evaluator finds the cut running back between nodes), the joint speed
exactly, and the load torque at the two Gauss points; the joint range, acceleration and
jerk are bounds on the nodes and controls. Each limit keeps a reserve of the planner's
``margin``; the acceleration and jerk bounds also keep a feed hold its room
(:func:`~spm_opt.judge.limits.planner_bounds`, :mod:`spm_opt.judge.hold_room`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.judge.limits import PlannerBounds
from spm_opt.model.params import MM
from spm_opt.planners.ocp.point import GAUSS, INSIDE, NODE, SPEED_CONTROL, Point

UNLIMITED = 1e3
"""Stands in for a limit the problem leaves open (in the limit's SI unit)."""

POSITION, VELOCITY, ACCELERATION, JERK = "q", "q̇", "q̈", "jerk"
"""The NLP's variables a limit may bound: the nodes' joint angles (rad), rates (rad/s) and
accelerations (rad/s²), and the intervals' jerks (rad/s³)."""


@dataclass(frozen=True)
class Constraint:
    """One kind of constraint row.

    Attributes
    ----------
    name : str
        What it limits, in the evaluator's words.
    unit : str
        Unit of the rows (of their square root when ``squared``).
    squared : bool
        Whether the rows hold the square of the quantity.
    places : tuple of str
        Where on each interval it applies (:data:`~spm_opt.planners.ocp.point.NODE`, ...).
    rows : callable
        Point -> its rows (SX column).
    limits : callable
        (its limit's bound: the PlannerBounds field's value, SI, None where unlimited or
        unbounded) -> per-row lower and upper bounds, in the rows' units.
    size : int
        Rows per point.
    at_landmarks : bool
        Whether it applies at a landmark's node (where the angles are fixed anyway).
    on_demand : tuple of str
        Places whose rows an NLP has only once the planner found the limit exceeded
        between the constraint points (the row groups' ``demanded``).
    dynamics : bool
        Whether the rows need the dynamics (left out of NLPs without them).
    """

    name: str
    unit: str
    squared: bool
    places: tuple[str, ...]
    rows: Callable[[Point], ca.SX]
    limits: Callable[[Any], tuple[list[float], list[float]]]
    size: int = 1
    at_landmarks: bool = True
    on_demand: tuple[str, ...] = ()
    dynamics: bool = False

    def waiting(self, place: str, demanded: frozenset[str]) -> bool:
        """Whether its rows at ``place`` are on demand and not (yet) ``demanded``."""
        return place in self.on_demand and self.name not in demanded


@dataclass(frozen=True)
class Limit:
    """One limit the planners keep.

    Attributes
    ----------
    bound : str or None
        The :class:`~spm_opt.judge.limits.PlannerBounds` field that bounds it, tightened by the
        excess when the evaluator finds one of ``rules`` broken. None: a condition of the
        cut's geometry, kept exactly, with nothing to tighten.
    rules : tuple of str
        The evaluator's rules (:data:`spm_opt.judge.limits.RULES`) it keeps: a plan that breaks
        one is solved again with its check points moved or ``bound`` tightened. A rule no
        limit keeps is a planning error.
    constraints : tuple of Constraint
        Its rows in the interval's function, in the NLP's order.
    variable : str or None
        The variable whose bounds keep it (:data:`POSITION`, :data:`VELOCITY`,
        :data:`ACCELERATION` or :data:`JERK`), per joint within ``bound``'s range, or
        ± ``bound`` (:data:`UNLIMITED` where the problem sets none).
    """

    bound: str | None
    rules: tuple[str, ...] = ()
    constraints: tuple[Constraint, ...] = ()
    variable: str | None = None

    def value(self, bounds: PlannerBounds) -> Any:
        """Its bound in ``bounds``, SI (None for a condition of the geometry)."""
        return None if self.bound is None else getattr(bounds, self.bound)

    def box(self, bounds: PlannerBounds) -> tuple[np.ndarray, np.ndarray]:
        """Per joint lower and upper bounds (2,) on its :attr:`variable`, SI."""
        value = self.value(bounds)
        if np.ndim(value) == 2:  # a range: [[low1, high1], [low2, high2]]
            return value[:, 0], value[:, 1]
        magnitude = value or UNLIMITED
        return np.full(2, -magnitude), np.full(2, magnitude)


def _mm(value: float | None) -> float:
    """A length (or speed) bound in mm (per s), :data:`UNLIMITED` where unset."""
    return (value or UNLIMITED) / MM


def _symmetric(value: float) -> tuple[list[float], list[float]]:
    """± ``value`` on both joints' rows."""
    return [-value] * 2, [value] * 2


def _ahead(_: None) -> tuple[list[float], list[float]]:
    """Rows that must not fall below zero."""
    return [0.0], [np.inf]


LIMITS = (
    Limit(
        "tool_speed",
        ("tool speed",),
        (
            Constraint(
                "tool speed",
                "mm/s",
                True,
                (NODE, INSIDE),
                lambda point: point["tool speed²"],
                lambda speed: ([-np.inf], [_mm(speed) ** 2]),
            ),
        ),
    ),
    # a cut found outside the tube where the evaluator finds the contour uncut (coverage)
    # counts as the cause of the gap
    Limit(
        "contour_tolerance",
        ("contour deviation", "coverage"),
        (
            Constraint(
                "contour deviation",
                "mm",
                True,
                (NODE, INSIDE),
                lambda point: point["chord²"],
                lambda tolerance: ([-np.inf], [_mm(tolerance) ** 2]),
                at_landmarks=False,
            ),
        ),
    ),
    # the cut stays between its segment's landmarks
    Limit(
        None,
        (),
        (
            Constraint(
                "segment start",
                "",
                False,
                (NODE, INSIDE),
                lambda point: point["past start"],
                _ahead,
                at_landmarks=False,
            ),
            Constraint(
                "segment end",
                "",
                False,
                (NODE, INSIDE),
                lambda point: point["before end"],
                _ahead,
                at_landmarks=False,
            ),
        ),
    ),
    # the cut never runs back along its arc: the evaluator's backtracking. At the check
    # points on demand: a minimum-energy cut on varied flap 157 slowed almost to rest
    # mid-segment and ran 0.30 mm back between two nodes, but bounded there from the start
    # the rows cost minimum jerk its convergence on 2 of the first 130 random flaps
    # (300 iterations), and minimum time more iterations on 14 of 24 flaps (median 59
    # against 50.5)
    Limit(
        None,
        ("backtracking",),
        (
            Constraint(
                "backtracking",
                "mm/s",
                False,
                (NODE, INSIDE),
                lambda point: point["progress speed"],
                _ahead,
                on_demand=(INSIDE,),
            ),
        ),
    ),
    Limit(
        "joint_speed",
        ("joint speed",),
        (
            Constraint(
                "joint speed",
                "rad/s",
                False,
                (SPEED_CONTROL,),
                lambda point: point.qd,
                _symmetric,
                size=2,
            ),
        ),
        variable=VELOCITY,
    ),
    Limit(
        "load_torque",
        ("actuator torque", "motor current"),
        (
            Constraint(
                "actuator torque",
                "N·m",
                False,
                (GAUSS,),
                lambda point: point.torque,
                _symmetric,
                size=2,
                dynamics=True,
            ),
        ),
    ),
    Limit("joint_acceleration", ("joint acceleration", "hold acceleration"), variable=ACCELERATION),
    Limit("joint_jerk", ("joint jerk", "acceleration step", "hold jerk"), variable=JERK),
    # hard (no margin), never tightened
    Limit("joint_range", variable=POSITION),
)
"""Every limit the planners keep; the NLP's rows follow this order."""

ON_DEMAND = frozenset(c.name for limit in LIMITS for c in limit.constraints if c.on_demand)
"""The constraints with on-demand rows."""

_KEEPING = {rule: limit for limit in LIMITS for rule in limit.rules}


def keeping(rule: str) -> Limit | None:
    """The limit that keeps the evaluator's ``rule``, if any."""
    return _KEEPING.get(rule)
