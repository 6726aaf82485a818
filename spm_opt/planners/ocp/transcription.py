"""The optimal-control planners' transcription: the time grid, the motion on one interval,
and the constraints, each with its name, unit, places and bounds in one list.

Each segment between consecutive landmark visits is three phases (a short one at each end,
the middle between them) of uniform intervals; the phase durations are variables. The
state is (q, q̇, q̈) and the control is the jerk, constant on each interval, so the motion is
integrated exactly: q is a cubic in time on each interval.

Every constraint is a row (or rows) of one interval's function, evaluated at some of its
places: the node that starts it, check points inside it at fractions that are parameters
(so the planner can move them to where a limit was exceeded without changing the NLP's
shape), its two Gauss points, or, for the joint speed, the middle Bernstein coefficient of q̇ (q̇ is
quadratic on an interval: its node values and this coefficient bound it everywhere on the
interval, exactly). :data:`CONSTRAINTS` is the one list: adding a constraint is one entry,
and the NLP's rows, their bounds and the planner's report of the most violated one all read
it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.limits import PlannerBounds
from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.skull.arc_fit import ACROSS_DEGREE, ALONG_DEGREE, COEFFICIENTS
from spm_opt.trajectory import Trajectory

UNLIMITED = 1e3
"""Stands in for a limit the problem leaves open (in the limit's SI unit)."""
ARC_PARAMETERS = 15 + COEFFICIENTS
"""Per segment: the arc's a, w, n, n × end (3 each), and the skull's radius near it
(:mod:`spm_opt.skull.arc_fit`): φ_c, φ_h (rad), o_h, and the coefficients C_kj (mm)."""
CORNER_SHARE = 0.05
"""Share of a segment's duration each corner phase takes in a contour-following guess."""
STATE, CONTROL = 6, 2
"""(q, q̇, q̈) and the jerk, per node and per interval."""


def advance(x: Any, u: Any, h: Any) -> Any:
    """The state (q, q̇, q̈) h seconds on under the constant jerk u: exact integration."""
    q, qd, qdd = x[0:2], x[2:4], x[4:6]
    return ca.vertcat(
        q + h * qd + h**2 / 2 * qdd + h**3 / 6 * u,
        qd + h * qdd + h**2 / 2 * u,
        qdd + h * u,
    )


class Point:
    """The motion at one place of an interval, with the quantities the constraints share
    (SX expressions, built once when first asked for).

    ``arc`` holds the segment's great circle (:data:`ARC_PARAMETERS`, lengths in mm, so
    that the squared path rows are near 1); ``torque`` maps (q, q̇, q̈) to the joint side
    of the actuators' torque (the load's, the drives' inertia and friction), N·m.
    """

    def __init__(self, state: ca.SX, arc: ca.SX, torque: Callable[..., ca.SX]) -> None:
        self.q, self.qd, self.qdd = state[0:2], state[2:4], state[4:6]
        self._arc, self._torque = arc, torque

    @cached_property
    def _geometry(self) -> dict[str, ca.SX]:
        arc = self._arc
        a, w, n, w_end = (arc[3 * k : 3 * k + 3] for k in range(4))
        p = ca.vertcat(*kinematics.direction(self.q[0], self.q[1]))
        d1, d2 = kinematics.direction_jacobian(self.q[0], self.q[1])
        p_dot = ca.vertcat(*d1) * self.qd[0] + ca.vertcat(*d2) * self.qd[1]
        pa, pw = ca.dot(p, a), ca.dot(p, w)
        off_plane = ca.dot(p, n)
        angle_rate = (ca.dot(p_dot, w) * pa - pw * ca.dot(p_dot, a)) / (pa**2 + pw**2)
        on_arc, rho, along_slope, across_slope = _RADIUS(arc[12:], ca.atan2(pw, pa), off_plane)
        rho_rate = along_slope * angle_rate + across_slope * ca.dot(p_dot, n)
        return {
            "tool speed²": ca.sumsqr(p_dot) * rho**2 + rho_rate**2,
            # |ρ p − ρ_c c|², c the point of the arc's plane nearest p (Contour.distance)
            "chord²": (rho - on_arc) ** 2 + 2 * rho * on_arc * (1 - ca.sqrt(1 - off_plane**2)),
            "progress speed": on_arc * angle_rate,
            "past start": pw,
            "before end": -ca.dot(p, w_end),
        }

    def __getitem__(self, name: str) -> ca.SX:
        return self._geometry[name]

    @cached_property
    def torque(self) -> ca.SX:
        """The joint side of the actuators' torque, N·m (2,)."""
        return self._torque(self.q, self.qd, self.qdd)


def _radius_function() -> ca.Function:
    """The skull's radius (mm) near an arc, from its fit's parameters (φ_c, φ_h, o_h, C_kj)
    at the angle φ along it and the off-plane component o: on the arc (o = 0), at the point
    itself, and the latter's partial derivatives in φ and o."""
    fit = ca.SX.sym("fit", 3 + COEFFICIENTS)
    along, off = ca.SX.sym("along"), ca.SX.sym("off")
    x, y = (along - fit[0]) / fit[1], off / fit[2]
    coefficients = fit[3:]
    chebyshev = [1, x]
    for _ in range(ALONG_DEGREE - 1):
        chebyshev.append(2 * x * chebyshev[-1] - chebyshev[-2])
    across = [
        sum(
            chebyshev[k] * coefficients[k * (ACROSS_DEGREE + 1) + j]
            for k in range(ALONG_DEGREE + 1)
        )
        for j in range(ACROSS_DEGREE + 1)
    ]
    rho = sum(term * y**j for j, term in enumerate(across))
    outputs = [across[0], rho, ca.jacobian(rho, along), ca.jacobian(rho, off)]
    return ca.Function("skull_radius", [fit, along, off], outputs)


_RADIUS = _radius_function()


NODE, INSIDE, GAUSS, SPEED_CONTROL = "node", "inside", "Gauss point", "speed control point"
"""The places of an interval where constraints apply: the node that starts it, the check
points inside it, its two Gauss–Legendre points, and q̇'s middle Bernstein coefficient."""
GAUSS_FRACTIONS = (0.5 - 3**0.5 / 6, 0.5 + 3**0.5 / 6)
"""The two-point Gauss–Legendre rule's places in an interval, as fractions of it: where the
effort integral and the torque limit read the torque (two table look-ups an interval, and
exact for cubics, as Simpson's three)."""


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
        Where on each interval it applies (:data:`NODE`, :data:`INSIDE`, ...).
    rows : callable
        Point -> its rows (SX column).
    limits : callable
        (PlannerBounds) -> per-row lower and upper bounds, in the rows' units.
    size : int
        Rows per point.
    at_landmarks : bool
        Whether it applies at a landmark's node (where the angles are fixed anyway).
    on_demand : tuple of str
        Places whose rows an NLP has only once the planner found the limit exceeded
        between the constraint points (:func:`row_groups`' ``demanded``).
    dynamics : bool
        Whether the rows need the dynamics (left out of NLPs without them).
    """

    name: str
    unit: str
    squared: bool
    places: tuple[str, ...]
    rows: Callable[[Point], ca.SX]
    limits: Callable[[PlannerBounds], tuple[list[float], list[float]]]
    size: int = 1
    at_landmarks: bool = True
    on_demand: tuple[str, ...] = ()
    dynamics: bool = False

    def waiting(self, place: str, demanded: frozenset[str]) -> bool:
        """Whether its rows at ``place`` are on demand and not (yet) ``demanded``."""
        return place in self.on_demand and self.name not in demanded


def _tool_speed_mm(bounds: PlannerBounds) -> float:
    return (bounds.tool_speed or UNLIMITED) / MM


def _tolerance_mm(bounds: PlannerBounds) -> float:
    return (bounds.contour_tolerance or UNLIMITED) / MM


CONSTRAINTS = (
    Constraint(
        "tool speed",
        "mm/s",
        True,
        (NODE, INSIDE),
        lambda point: point["tool speed²"],
        lambda bounds: ([-np.inf], [_tool_speed_mm(bounds) ** 2]),
    ),
    Constraint(
        "contour deviation",
        "mm",
        True,
        (NODE, INSIDE),
        lambda point: point["chord²"],
        lambda bounds: ([-np.inf], [_tolerance_mm(bounds) ** 2]),
        at_landmarks=False,
    ),
    Constraint(
        "segment start",
        "",
        False,
        (NODE, INSIDE),
        lambda point: point["past start"],
        lambda bounds: ([0.0], [np.inf]),
        at_landmarks=False,
    ),
    Constraint(
        "segment end",
        "",
        False,
        (NODE, INSIDE),
        lambda point: point["before end"],
        lambda bounds: ([0.0], [np.inf]),
        at_landmarks=False,
    ),
    # the cut never runs back along its arc: the evaluator's backtracking. At the check
    # points on demand: a minimum-energy cut on varied flap 157 slowed almost to rest
    # mid-segment and ran 0.30 mm back between two nodes, but bounded there from the start
    # the rows cost minimum jerk its convergence on 2 of the first 130 random flaps
    # (300 iterations), and minimum time more iterations on 14 of 24 flaps (median 59
    # against 50.5)
    Constraint(
        "backtracking",
        "mm/s",
        False,
        (NODE, INSIDE),
        lambda point: point["progress speed"],
        lambda bounds: ([0.0], [np.inf]),
        on_demand=(INSIDE,),
    ),
    Constraint(
        "joint speed",
        "rad/s",
        False,
        (SPEED_CONTROL,),
        lambda point: point.qd,
        lambda bounds: ([-bounds.joint_speed] * 2, [bounds.joint_speed] * 2),
        size=2,
    ),
    Constraint(
        "actuator torque",
        "N·m",
        False,
        (GAUSS,),
        lambda point: point.torque,
        lambda bounds: ([-bounds.load_torque] * 2, [bounds.load_torque] * 2),
        size=2,
        dynamics=True,
    ),
)


ON_DEMAND = frozenset(c.name for c in CONSTRAINTS if c.on_demand)
"""The constraints with on-demand rows."""


@dataclass(frozen=True)
class RowGroup:
    """Consecutive rows of one interval: a constraint at one point of one place."""

    constraint: Constraint
    place: str
    point: int  # which check point, for INSIDE
    start: int  # first row within the interval's rows
    size: int


@dataclass(frozen=True)
class Grid:
    """The time grid: each segment is three phases (corner, middle, corner) of uniform
    intervals; D = 3 × segments phase durations, M intervals, M + 1 nodes."""

    segments: int
    counts: tuple[int, int, int]

    @property
    def per_segment(self) -> int:
        return sum(self.counts)

    @property
    def intervals(self) -> int:
        return self.segments * self.per_segment

    @property
    def phase_of_interval(self) -> np.ndarray:
        """The phase (0 … D−1) of every interval (M,)."""
        return np.repeat(np.arange(3 * self.segments), np.tile(self.counts, self.segments))

    @property
    def interval_matrix(self) -> np.ndarray:
        """(M, D): interval lengths = this @ phase durations."""
        phases = self.phase_of_interval
        matrix = np.zeros((self.intervals, 3 * self.segments))
        matrix[np.arange(self.intervals), phases] = (
            1.0 / np.tile(self.counts, self.segments)[phases]
        )
        return matrix

    @property
    def segment_matrix(self) -> np.ndarray:
        """(segments, D): segment durations = this @ phase durations."""
        return np.kron(np.eye(self.segments), np.ones((1, 3)))

    @property
    def landmark_nodes(self) -> np.ndarray:
        return np.arange(self.segments + 1) * self.per_segment

    @property
    def interval_segments(self) -> np.ndarray:
        """Segment of every interval (M,)."""
        return np.arange(self.intervals) // self.per_segment

    def phase_durations(self, segment_durations: np.ndarray) -> np.ndarray:
        """A split of segment durations into phases (D,) for a contour-following guess."""
        shares = np.array([CORNER_SHARE, 1.0 - 2 * CORNER_SHARE, CORNER_SHARE])
        return np.outer(segment_durations, shares).ravel()

    def node_times(self, phase_durations: np.ndarray) -> np.ndarray:
        """Times (M + 1,), s, of the nodes from the start."""
        return np.concatenate([[0.0], np.cumsum(self.interval_matrix @ phase_durations)])

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The NLP's x as node states (M + 1, 6) = (q, q̇, q̈), jerks (M, 2) and phase
        durations (D,); x stacks them in that order."""
        n_states, n_jerks = STATE * (self.intervals + 1), CONTROL * self.intervals
        return (
            np.reshape(x[:n_states], (-1, STATE)),
            np.reshape(x[n_states : n_states + n_jerks], (-1, CONTROL)),
            x[n_states + n_jerks :],
        )

    def trajectory(self, x: np.ndarray, metadata: dict[str, Any]) -> Trajectory:
        """The motion x describes: exact, since each interval is a cubic in time."""
        states, _, durations = self.split(x)
        t = self.node_times(durations)
        return Trajectory.from_samples(
            t, states[:, 0:2], states[:, 2:4], states[:, 4:6], metadata=metadata
        )


def default_fractions(checks: int) -> np.ndarray:
    """Evenly spaced check points inside an interval, as fractions of it (checks,)."""
    return np.arange(1, checks + 1) / (checks + 1)


def constraints(with_dynamics: bool) -> tuple[Constraint, ...]:
    """The constraints an NLP with (or without) the dynamics imposes."""
    return tuple(c for c in CONSTRAINTS if with_dynamics or not c.dynamics)


def _points(place: str, checks: int) -> int:
    """How many points of an interval a place has."""
    return {INSIDE: checks, GAUSS: len(GAUSS_FRACTIONS)}.get(place, 1)


def row_groups(
    checks: int, with_dynamics: bool, demanded: frozenset[str] = frozenset()
) -> tuple[RowGroup, ...]:
    """The rows of one interval after its continuity rows, in order; on-demand places only
    for the constraints ``demanded``."""
    groups, start = [], 0
    for constraint in constraints(with_dynamics):
        for place in constraint.places:
            if constraint.waiting(place, demanded):
                continue
            for point in range(_points(place, checks)):
                groups.append(RowGroup(constraint, place, point, start, constraint.size))
                start += constraint.size
    return tuple(groups)


def interval_function(
    checks: int,
    with_dynamics: bool,
    torque: Callable[..., ca.SX] | None,
    n_dynamics: int,
    demanded: frozenset[str] = frozenset(),
) -> ca.Function:
    """One interval: (x (6), u (2), h (s), arc, check fractions (checks,), dynamics
    parameters) -> the state at its end (6), its constraint rows (in
    :func:`row_groups`' order, with the on-demand rows of the constraints ``demanded``),
    and its jerk and effort integrals (∫jerk² rad²/s⁵, ∫τᵀτ N²m²s; the two-point Gauss
    rule for the effort)."""
    x, u, h = ca.SX.sym("x", STATE), ca.SX.sym("u", CONTROL), ca.SX.sym("h")
    arc, fractions = ca.SX.sym("arc", ARC_PARAMETERS), ca.SX.sym("fractions", checks)
    dynamics = ca.SX.sym("dynamics", n_dynamics)

    def load_torque(q: ca.SX, qd: ca.SX, qdd: ca.SX) -> ca.SX:
        assert torque is not None
        return torque(q, qd, qdd, dynamics)

    def point(state: ca.SX) -> Point:
        return Point(state, arc, load_torque)

    end = advance(x, u, h)
    speed_control = ca.vertcat(x[0:2], x[2:4] + h * x[4:6] / 2, x[4:6])
    places = {
        NODE: [point(x)],
        INSIDE: [point(advance(x, u, fractions[i] * h)) for i in range(checks)],
        GAUSS: [point(advance(x, u, f * h)) for f in GAUSS_FRACTIONS],
        SPEED_CONTROL: [point(speed_control)],
    }
    rows = [
        group.constraint.rows(places[group.place][group.point])
        for group in row_groups(checks, with_dynamics, demanded)
    ]
    effort = ca.SX(0)
    if with_dynamics:
        effort = h * sum(ca.sumsqr(gauss.torque) for gauss in places[GAUSS]) / 2
    jerk = h * ca.sumsqr(u)
    return ca.Function(
        "interval",
        [x, u, h, arc, fractions, dynamics],
        [end, ca.vertcat(*rows), ca.vertcat(jerk, effort)],
        ["x", "u", "h", "arc", "fractions", "dynamics"],
        ["end", "rows", "integrals"],
    )
