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

This module writes one interval's functions and one landmark's (value, Jacobian,
Hessian); :mod:`~spm_opt.planners.ocp.path_assembly` lays them out into the NLP.
"""

from __future__ import annotations

from collections.abc import Sequence
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


INTERVAL_FUNCTIONS = ("path_interval_value", "path_interval_jacobian", "path_interval_hessian")
"""Names of one interval's value, Jacobian and Hessian (and of their compiled C)."""
LANDMARK_FUNCTIONS = ("path_landmark_value", "path_landmark_jacobian", "path_landmark_hessian")
"""Names of the continuity rows' value, Jacobian and Hessian at a landmark passed."""
Z = STATE + CONTROL
"""An interval's variables: its first node's state and its control."""
INTERVAL_PARAMETERS = (len(PLACES) + 1) * PER_PLACE
"""An interval's path terms: at its start, middle and end."""
LIMIT_PARAMETERS = len(LIMITS) + 2
"""The limits (:data:`LIMITS`) and the drives' viscous friction."""
INTERVAL_LOW = np.array(
    [0.0] * STATE + [-1.0, -1.0, MIN_BETA] + ([-np.inf] * 3 + [-1.0] * 6) * 2 + [-1.0] * 2
)
INTERVAL_HIGH = np.array([0.0] * STATE + [1.0, 1.0, np.inf] + [1.0] * 9 * 2 + [1.0] * 2)
"""Bounds of an interval's rows: its next node's state (the gap, 5), the hulls (3), the
motion's rows at its start and middle (9 each) and the jerk at its end (2)."""
LANDMARK_ROWS = 5
"""Continuity rows at a landmark passed."""


def _interval(objectives: tuple[str, ...]) -> tuple[list[ca.SX], ca.SX, ca.SX, ca.SX, ca.SX]:
    """One interval's inputs (z, h, terms, limits, weights) and, from them, its rows (the
    gap's −advance, then the limits'), its integrals (:data:`OBJECTIVES`) and its objective
    term (the weighted ``objectives`` and the offset's smoothing)."""
    z, h = ca.SX.sym("z", Z), ca.SX.sym("h")
    terms = ca.SX.sym("terms", INTERVAL_PARAMETERS)
    limits, weights = ca.SX.sym("limits", LIMIT_PARAMETERS), ca.SX.sym("weights", len(OBJECTIVES))
    state, control = ca.vertsplit(z[:STATE]), ca.vertsplit(z[STATE:])
    rows = [-ca.vertcat(*advance(state, control, h)), _interval_hulls(state, control, h, limits[5])]
    per_time = [
        weight * h / _root(advance(state, control, at * h)[0])
        for at, weight in zip(*TIME_QUADRATURE, strict=True)
    ]
    rates: dict[str, list[ca.SX]] = {name: [] for name in OBJECTIVES[1:]}
    for j, fraction in enumerate((*PLACES, 1.0)):
        at = _rows_at(
            terms[j * PER_PLACE : (j + 1) * PER_PLACE],
            advance(state, control, fraction * h),
            z[STATE:],
            limits,
        )
        for name, values in rates.items():
            values.append(at.pop(name))
        rows.append(at["joint jerk"] if fraction == 1.0 else ca.vertcat(*at.values()))
    integrals = [sum(per_time)]
    for values in rates.values():  # the rate's parabola at the Gauss points
        at_points = INTERPOLATION @ ca.vertcat(*values)
        integrals.append(sum(at_points[g] * per_time[g] for g in range(len(per_time))))
    term = SMOOTHING * h * control[1] ** 2
    for name in objectives:
        term += weights[OBJECTIVES.index(name)] * integrals[OBJECTIVES.index(name)]
    return [z, h, terms, limits, weights], ca.vertcat(*rows), ca.vertcat(*integrals), term


@cache
def interval_functions(objectives: tuple[str, ...]) -> list[ca.Function]:
    """One interval's value (rows, integrals, term), Jacobian (rows, term, the rows'
    Jacobian and the term's and the time's gradients in z) and Hessian (the upper triangle
    of ∇²_z(σ term + λᵀrows + λ_t time)), in SX, for the weighted ``objectives``."""
    inputs, rows, integrals, term = _interval(objectives)
    z, names = inputs[0], ["z", "h", "terms", "limits", "weights"]
    sigma, lam, lam_time = ca.SX.sym("sigma"), ca.SX.sym("lam", rows.numel()), ca.SX.sym("lam_t")
    lagrangian = sigma * term + ca.dot(lam, rows) + lam_time * integrals[0]
    value, jacobian, hessian = INTERVAL_FUNCTIONS
    return [
        ca.Function(value, inputs, [rows, integrals, term], names, ["rows", "integrals", "term"]),
        ca.Function(
            jacobian,
            inputs,
            [
                rows,
                term,
                ca.jacobian(rows, z),
                ca.gradient(term, z),
                ca.gradient(integrals[0], z),
            ],
            names,
            ["rows", "term", "jac_rows", "grad_term", "grad_time"],
        ),
        ca.Function(
            hessian,
            [*inputs, sigma, lam, lam_time],
            [ca.triu(ca.hessian(lagrangian, z)[0])],
            [*names, "sigma", "lam", "lam_t"],
            ["hess"],
        ),
    ]


@cache
def landmark_functions() -> list[ca.Function]:
    """The continuity rows at a landmark passed (:func:`_continuity`): value, Jacobian and
    Lagrangian Hessian (upper triangle) in w = (the state before, the state after)."""
    w = ca.SX.sym("w", 2 * STATE)
    before, after = ca.SX.sym("before", PER_END), ca.SX.sym("after", PER_END)
    limits = ca.SX.sym("limits", LIMIT_PARAMETERS)
    rows = _continuity(w[:STATE], w[STATE:], before, after, limits)
    lam = ca.SX.sym("lam", LANDMARK_ROWS)
    inputs, names = [w, before, after, limits], ["w", "before", "after", "limits"]
    value, jacobian, hessian = LANDMARK_FUNCTIONS
    return [
        ca.Function(value, inputs, [rows], names, ["rows"]),
        ca.Function(jacobian, inputs, [rows, ca.jacobian(rows, w)], names, ["rows", "jac_rows"]),
        ca.Function(
            hessian,
            [*inputs, lam],
            [ca.triu(ca.hessian(ca.dot(lam, rows), w)[0])],
            [*names, "lam"],
            ["hess"],
        ),
    ]


def _continuity(
    end: ca.SX, start: ca.SX, end_terms: ca.SX, start_terms: ca.SX, limits: ca.SX
) -> ca.SX:
    """Rows that make q̇ and q̈ continuous at a landmark passed (d = 0 there), from the
    state at the end of the segment before and at the start of the one after: the arc
    length's rate, q_s (2) and q̈ (2, over the acceleration limit)."""

    def side(state: ca.SX, terms: ca.SX, which: int) -> tuple[ca.SX, ca.SX, ca.SX]:
        factor = terms[which]
        a1, v, a2, v1 = (terms[2 + 4 * n + 2 * which : 4 + 4 * n + 2 * which] for n in range(4))
        qu = a1 + state[3] * v
        qdd = qu * state[1] / 2 + (a2 + state[4] * v + 2 * state[3] * v1) * state[0]
        return factor**2 * state[0], qu / factor, qdd

    rate_end, qs_end, qdd_end = side(end, end_terms, 1)
    rate_start, qs_start, qdd_start = side(start, start_terms, 0)
    return ca.vertcat(rate_end - rate_start, qs_end - qs_start, (qdd_end - qdd_start) / limits[2])
