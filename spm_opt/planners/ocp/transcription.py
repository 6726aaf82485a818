"""The optimal-control planners' transcription: the time grid, the motion on one interval,
and the interval's function that holds every constraint row of
:data:`~spm_opt.planners.ocp.constraints.LIMITS`.

Each segment between consecutive landmark visits is three phases (a short one at each end,
the middle between them) of uniform intervals; the phase durations are variables. The
state is (q, q̇, q̈) and the control is the jerk, constant on each interval, so the motion is
integrated exactly: q is a cubic in time on each interval, and the returned
:class:`~spm_opt.problem.trajectory.Trajectory` reproduces the solution exactly. Landmarks are
reached exactly at phase boundaries; the motion starts and ends at rest.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.judge.limits import PlannerBounds
from spm_opt.planners.ocp.constraints import LIMITS, Constraint, Limit
from spm_opt.planners.ocp.point import (
    ARC_PARAMETERS,
    GAUSS,
    GAUSS_FRACTIONS,
    INSIDE,
    NODE,
    SPEED_CONTROL,
    Point,
)
from spm_opt.problem.trajectory import Trajectory

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


@dataclass(frozen=True)
class RowGroup:
    """Consecutive rows of one interval: a limit's constraint at one point of one place."""

    limit: Limit
    constraint: Constraint
    place: str
    point: int  # which check point, for INSIDE
    start: int  # first row within the interval's rows
    size: int

    def limits(self, bounds: PlannerBounds) -> tuple[list[float], list[float]]:
        """Its rows' lower and upper bounds within ``bounds``, in the rows' units."""
        return self.constraint.limits(self.limit.value(bounds))


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


def _points(place: str, checks: int) -> int:
    """How many points of an interval a place has."""
    return {INSIDE: checks, GAUSS: len(GAUSS_FRACTIONS)}.get(place, 1)


def row_groups(
    checks: int, with_dynamics: bool, demanded: frozenset[str] = frozenset()
) -> tuple[RowGroup, ...]:
    """The rows of one interval after its continuity rows, in :data:`LIMITS`' order; the
    rows needing the dynamics only ``with_dynamics``, on-demand places only for the
    constraints ``demanded``."""
    groups, start = [], 0
    for limit in LIMITS:
        for constraint in limit.constraints:
            if constraint.dynamics and not with_dynamics:
                continue
            for place in constraint.places:
                if constraint.waiting(place, demanded):
                    continue
                for point in range(_points(place, checks)):
                    groups.append(RowGroup(limit, constraint, place, point, start, constraint.size))
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
