"""The path-coordinate NLP: the least time, effort or jerk along the contour's segments,
the cut free to leave the contour within the tube, through every landmark without stopping.

Per segment, on its grid u (:mod:`path_geometry`), the state at each node is
(β, β', d, d', d''), β = u̇² and ' = d/du, and the control on each interval is (β'', d'''):
β is quadratic and d cubic in u on an interval, integrated exactly. With q_u = A1 + d' v +
d v1, q_uu = A2 + d'' v + 2 d' v1 + d v2 and q_uuu = A3 + d''' v + 3 d'' v1 + 3 d' v2 + d v3:

    q̇ = q_u √β,  q̈ = q_u β'/2 + q_uu β,  q⃛ = √β (q_uuu β + 1.5 q_uu β' + 0.5 q_u β'')

Rows, at the start and the middle of every interval: the cut point's speed (q̇ᵀGq̇), each
joint's speed, acceleration, jerk and torque (toppra's model terms at the contour, and the
drives' viscous friction), the offset within the tube and β > 0; the jerk also at the
interval's end (its control changes at the next node). At every landmark d = 0 (so the
landmarks are met exactly); at the first and the last the cut is at rest (the map's end
zone) with d' = d'' = 0; at a landmark the cut passes through, q̇ and q̈ are continuous:
the arc length's rate, q_s, and q̈ itself agree on both sides.

Objective: a weighted sum of the time Σ ∫ du / √β, the effort ∫ τᵀτ dt = ∫ τᵀτ / √β du and
the jerk ∫ q⃛ᵀq⃛ dt = ∫ q⃛ᵀq⃛ / √β du (Gauss–Legendre on every interval, τᵀτ and q⃛ᵀq⃛ there
from their parabola through the interval's three places; the weights are parameters), plus
1e-9 ∫ d'''² du, which keeps d smooth where the objective does not decide it. With fixed
timing, rows hold the total time or each segment's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import casadi as ca
import numpy as np

STATE, CONTROL = 5, 2
"""(β, β', d, d', d'') per node; (β'', d''') per interval."""
PLACES = (0.0, 0.5)
"""Where in an interval every row applies (fractions); the jerk also at its end."""
TERMS = ("A1", "A2", "A3", "v", "v1", "v2", "v3", "G", "inertia", "bias", "gravity", "friction")
TERM_SIZES = (2, 2, 2, 2, 2, 2, 2, 3, 4, 2, 2, 2)
PER_PLACE = sum(TERM_SIZES)
ENDS = ("A1", "v", "A2", "v1")
"""Terms at the segment's two ends that the continuity rows read, after ds/du at both."""
PER_END = 2 + 2 * 2 * len(ENDS)
LIMITS = ("tool speed", "joint speed", "joint acceleration", "joint jerk", "torque", "tube")
OBJECTIVES = ("time", "effort", "jerk")
"""The objective's terms (s, N²·m²·s, rad²/s⁵), in the order of their weights in p."""
_POINTS, _WEIGHTS = np.polynomial.legendre.leggauss(4)
TIME_QUADRATURE = ((_POINTS + 1) / 2, _WEIGHTS / 2)
"""Gauss–Legendre points (fractions of an interval) and weights of the time ∫ du / √β: on
the paper's flap, min-jerk's 40 s held by Simpson's rule lasted 39.969 s, by 2, 3 and 4
points 40.021, 40.002 and 40.000 s."""
INTERPOLATION = np.array(
    [[2 * (x - 0.5) * (x - 1), -4 * x * (x - 1), 2 * x * (x - 0.5)] for x in TIME_QUADRATURE[0]]
)
"""(4, 3): a rate's values at an interval's start, middle and end to its parabola's at the
:data:`TIME_QUADRATURE` points, where ∫ rate dt = ∫ rate / √β du is summed."""
MIN_BETA = 1e-8
"""Least u̇², mm²/s², anywhere."""
SMOOTHING = 1e-9
"""Weight of ∫ d'''² du (mm⁻⁵·mm) beside the time (s)."""


@dataclass(frozen=True)
class PathNlp:
    """A built NLP: CasADi's problem, each row's bounds, and the shapes to read x by."""

    problem: dict[str, ca.SX]
    low: np.ndarray
    high: np.ndarray
    segments: int
    intervals: int
    integrals: ca.Function
    """(x, p) → the :data:`OBJECTIVES`' values (3,) and each segment's time (segments,)."""
    timed: int
    """Rows of time at the end of g: the total's, or each segment's."""

    def row_bounds(self, durations: np.ndarray, timing: str) -> tuple[np.ndarray, np.ndarray]:
        """The rows' bounds, the time rows' from ``timing`` and the problem's segment
        durations (s)."""
        low, high = self.low.copy(), self.high.copy()
        if self.timed:
            held = durations if timing == "segments" else np.array([np.sum(durations)])
            low[-self.timed :] = 0.0 if timing == "bounded" else held
            high[-self.timed :] = held
        return low, high

    @property
    def per_segment(self) -> int:
        return STATE * (self.intervals + 1) + CONTROL * self.intervals

    def split(self, x: np.ndarray, segment: int) -> tuple[np.ndarray, np.ndarray]:
        """Segment ``segment``'s node states (N + 1, 5) and controls (N, 2) in x (views)."""
        part = x[segment * self.per_segment : (segment + 1) * self.per_segment]
        nodes = STATE * (self.intervals + 1)
        return part[:nodes].reshape(-1, STATE), part[nodes:].reshape(-1, CONTROL)


def advance(state: Sequence[Any], control: Sequence[Any], h: Any) -> list[Any]:
    """(β, β', d, d', d'') h mm on under the controls (β'', d'''): exact; the components
    as SX or as numpy arrays alike."""
    beta, slope, d, d1, d2 = state
    c, e = control
    return [
        beta + h * slope + h**2 / 2 * c,
        slope + h * c,
        d + h * d1 + h**2 / 2 * d2 + h**3 / 6 * e,
        d1 + h * d2 + h**2 / 2 * e,
        d2 + h * e,
    ]


def _root(beta: ca.SX) -> ca.SX:
    """√β, with β at least :data:`MIN_BETA`: between the nodes β is a row's business (its
    hull), which IPOPT's trial points may break (on a varied flap, a NaN stopped minimum
    jerk after 54 iterations)."""
    return ca.sqrt(ca.fmax(beta, MIN_BETA))


def _rows_at(terms: ca.SX, state: list[ca.SX], control: ca.SX, limits: ca.SX) -> dict[str, ca.SX]:
    """The motion's rows at one place from its path terms, state and control."""
    a1, a2, a3, v, v1, v2, v3 = (terms[2 * k : 2 * k + 2] for k in range(7))
    metric, inertia = terms[14:17], ca.reshape(terms[17:21], 2, 2).T
    bias, gravity, friction = terms[21:23], terms[23:25], terms[25:27]
    tool, speed, acceleration, jerk, torque_limit = (limits[k] for k in range(5))
    viscous = limits[6:8]
    beta, slope, d, d1, d2 = state
    qu = a1 + d1 * v + d * v1
    quu = a2 + d2 * v + 2 * d1 * v1 + d * v2
    quuu = a3 + control[1] * v + 3 * d2 * v1 + 3 * d1 * v2 + d * v3
    root = _root(beta)
    qdd = qu * slope / 2 + quu * beta
    torque = inertia @ qdd + bias * beta + gravity + friction + viscous * qu * root
    squared = metric[0] * qu[0] ** 2 + 2 * metric[1] * qu[0] * qu[1] + metric[2] * qu[1] ** 2
    qddd = root * (quuu * beta + 1.5 * quu * slope + 0.5 * qu * control[0])
    return {
        "tool speed": beta * squared / tool**2,
        "joint speed": qu**2 * beta / speed**2,
        "joint acceleration": qdd / acceleration,
        "joint jerk": qddd / jerk,
        "actuator torque": torque / torque_limit,
        "effort": ca.sumsqr(torque),
        "jerk": ca.sumsqr(qddd),
    }


def _interval_hulls(state: ca.SX, control: ca.SX, h: ca.SX, tube: ca.SX) -> ca.SX:
    """The inner Bernstein coefficients of d (cubic, over the tube) and of β (quadratic)
    on an interval: with the nodes' values, their bounds hold everywhere between."""
    beta, slope, d, d1, d2 = (state[k] for k in range(STATE))
    return ca.vertcat(
        (d + h * d1 / 3) / tube,
        (d + 2 * h * d1 / 3 + h**2 * d2 / 6) / tube,
        beta + h * slope / 2,
    )


@cache
def build(
    segments: int, intervals: int, objectives: tuple[str, ...] = ("time",), timing: str = "free"
) -> PathNlp:
    """The NLP for ``segments`` segments of ``intervals`` intervals each, its objective the
    weighted ``objectives`` (of :data:`OBJECTIVES`), with ``timing``'s rows of time; p
    stacks, per segment, the terms at every place, the interval lengths and the ends'
    terms, then the limits (:data:`LIMITS` and the drives' viscous friction), then the
    weights of :data:`OBJECTIVES`."""
    places = intervals * (len(PLACES) + 1)
    per_segment_p = places * PER_PLACE + intervals + PER_END
    per_segment_x = STATE * (intervals + 1) + CONTROL * intervals
    x = ca.SX.sym("x", segments * per_segment_x)
    p = ca.SX.sym("p", segments * per_segment_p + len(LIMITS) + 2 + len(OBJECTIVES))
    limits = p[segments * per_segment_p : -len(OBJECTIVES)]
    weights = p[-len(OBJECTIVES) :]
    rows: list[ca.SX] = []
    low: list[float] = []
    high: list[float] = []
    integrals = {name: ca.SX(0) for name in OBJECTIVES}
    smoothing = ca.SX(0)
    segment_times = []
    ends = []
    for k in range(segments):
        segment_time = ca.SX(0)
        xs = x[k * per_segment_x : (k + 1) * per_segment_x]
        states = ca.reshape(xs[: STATE * (intervals + 1)], STATE, intervals + 1)
        controls = ca.reshape(xs[STATE * (intervals + 1) :], CONTROL, intervals)
        ps = p[k * per_segment_p : (k + 1) * per_segment_p]
        lengths = ps[places * PER_PLACE : places * PER_PLACE + intervals]
        for i in range(intervals):
            h, state, control = lengths[i], states[:, i], controls[:, i]
            rows.append(
                states[:, i + 1]
                - ca.vertcat(*advance(ca.vertsplit(state), ca.vertsplit(control), h))
            )
            low += [0.0] * STATE
            high += [0.0] * STATE
            rows.append(_interval_hulls(state, control, h, limits[5]))
            low += [-1.0, -1.0, MIN_BETA]
            high += [1.0, 1.0, np.inf]
            per_time = [
                weight * h / _root(advance(ca.vertsplit(state), ca.vertsplit(control), at * h)[0])
                for at, weight in zip(*TIME_QUADRATURE, strict=True)
            ]
            segment_time += sum(per_time)
            rates: dict[str, list[ca.SX]] = {name: [] for name in OBJECTIVES[1:]}
            smoothing += h * control[1] ** 2
            for j, fraction in enumerate((*PLACES, 1.0)):
                start = (i * (len(PLACES) + 1) + j) * PER_PLACE
                at = _rows_at(
                    ps[start : start + PER_PLACE],
                    advance(ca.vertsplit(state), ca.vertsplit(control), fraction * h),
                    control,
                    limits,
                )
                for name, values in rates.items():
                    values.append(at.pop(name))
                if fraction == 1.0:
                    rows.append(at["joint jerk"])
                    low += [-1.0] * 2
                    high += [1.0] * 2
                    continue
                rows.append(ca.vertcat(*at.values()))
                low += [-np.inf] * 3 + [-1.0] * 6
                high += [1.0] * 9
            for name, values in rates.items():  # the rate's parabola at the Gauss points
                at_points = INTERPOLATION @ ca.vertcat(*values)
                integrals[name] += sum(at_points[g] * per_time[g] for g in range(len(per_time)))
        integrals["time"] += segment_time
        segment_times.append(segment_time)
        ends.append(
            (states[:, 0], states[:, intervals], ps[places * PER_PLACE + intervals :], limits)
        )
    for k in range(segments - 1):
        rows += _continuity(ends[k], ends[k + 1])
        low += [0.0] * 5
        high += [0.0] * 5
    timed = {"free": [], "segments": segment_times}.get(timing, [integrals["time"]])
    rows += timed
    low += [-np.inf] * len(timed)
    high += [np.inf] * len(timed)
    objective = sum(weights[OBJECTIVES.index(name)] * integrals[name] for name in objectives)
    problem = {"x": x, "p": p, "f": objective + SMOOTHING * smoothing, "g": ca.vertcat(*rows)}
    measured = ca.Function(
        "integrals", [x, p], [ca.vertcat(*integrals.values()), ca.vertcat(*segment_times)]
    )
    return PathNlp(
        problem, np.array(low), np.array(high), segments, intervals, measured, len(timed)
    )


def _continuity(before: tuple, after: tuple) -> list[ca.SX]:
    """Rows that make q̇ and q̈ continuous at a landmark passed (d = 0 there): the arc
    length's rate, q_s (2) and q̈ (2, over the acceleration limit)."""
    end, end_terms, limits = before[1], before[2], before[3]
    start, start_terms = after[0], after[2]

    def side(state: ca.SX, terms: ca.SX, which: int) -> tuple[ca.SX, ca.SX, ca.SX]:
        factor = terms[which]
        a1, v, a2, v1 = (terms[2 + 4 * n + 2 * which : 4 + 4 * n + 2 * which] for n in range(4))
        qu = a1 + state[3] * v
        qdd = qu * state[1] / 2 + (a2 + state[4] * v + 2 * state[3] * v1) * state[0]
        return factor**2 * state[0], qu / factor, qdd

    rate_end, qs_end, qdd_end = side(end, end_terms, 1)
    rate_start, qs_start, qdd_start = side(start, start_terms, 0)
    return [rate_end - rate_start, qs_end - qs_start, (qdd_end - qdd_start) / limits[2]]
