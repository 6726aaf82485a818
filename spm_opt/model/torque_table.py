"""The optimisers' actuator torques (smooth friction) from a B-spline table: cheap to
evaluate and differentiate, exact to micro-newton-metres, with the robot as an input.

For this 2-DOF robot the torque of :func:`spm_opt.model.dynamics.inverse_dynamics` with
``exact=False`` (frictionless + smooth friction: the form the optimisers impose) is,
exactly,

    τ = M(q) q̈ + c(q, q̇) + G(q) + diag(J_ua, J_la) q̈ + b_z(q) A(q)ᵀ (κ ⊙ σ(A(q) q̇)),
    c_i = c_i_11 q̇1² + c_i_12 q̇1 q̇2 + c_i_22 q̇2²,        σ(v) = v / sqrt(v² + s²),

and the 11 maps of q in M (3), c (6) and G (2) (:data:`ENTRIES`) are linear in the robot's
base parameters π (:func:`base_parameters`): the kinetic energy's columns (|ḃ|² of the
platforms' and the payload's translation, the six entries of each platform's inertia —
the payload's point inertia added to the upper one — and the payload's offset coupling)
and the potential energy's (b_z, cos θ1, cos θ2, the upper frame's z row). So the maps
are tabulated ONCE per joint range, for every robot: their grid values, 11 × 22 maps,
span R = 46 functions of q (a truncated SVD), each a uniform tensor cubic B-spline
(not-a-knot ends) on a grid over the joint range padded by :data:`PADDING`. A robot is the
vector :func:`table_values`: the weights (11, R) of its maps on those functions, and the
five exactly-written terms' parameters: the arcs' inertias J, the friction's κ and s (the
slide map A = −(x_u, y_L)ᵀ ∂b/∂q, whose A q̇ are the platforms' sliding rates, and b_z
are written in closed form). One NLP, and one compiled library of it, serves every robot,
payload and friction of a joint range. Units: q rad, q̇ rad/s, q̈ rad/s², τ N·m. Per
point, τ takes 927 SX instructions (511 of them reading the values) and the Hessian of
λᵀτ in (q, q̇, q̈) 1,888 and one call, against 3,987 and 57,766 for the Lagrange model.

The splines in CasADi SX: one SX call node (``never_inline``) reads the R functions and
their first and second derivatives in q (six B-spline nodes, the derivatives' coefficients
precomputed) at q0, q clamped to the grid, and weights them with the robot's values,
(11, 6). SX writes each map as its second-order Taylor expansion about q0,
m(q0) + ∂m δ + ½ δᵀ ∂²m δ with δ = q − q0 (0 inside the grid), so the value, gradient and
Hessian of τ are the spline's, from a dozen SX terms per map. The call's results and q0
pass through floor(x 2⁶⁰) 2⁻⁶⁰, x to 1e-18 with a structurally zero derivative, so
CasADi's AD never differentiates through the call (no derivative calls in the Hessian).
(Detached inside the call instead, in MX, CasADi 3.8.2's SX Hessian of an expanded graph
with two or more calls came out NaN; so did ``is_diff_in``/``is_diff_out`` = False, with
a call of 50 outputs.) Beyond the grid the expansion extrapolates quadratically.
``Function.expand()`` keeps the call node; ``ca.CodeGenerator`` writes it as C.

Why not a parametric interpolant (CasADi 3.8.2): ``ca.interpolant(name, "bspline", grid,
m)`` takes the grid values as an input and works in SX as a call node, but refits the
coefficients (a linear solve) at every call: 0.15 s a point on a 40 × 40 grid.
``ca.bspline`` with coefficients as an MX input has no SX form ('eval_sx' not defined for
BSplineParametric); wrapped as an SX call node it copies its ~19,000 coefficients at every
point (Hessian over 257 points 0.86 s). An MX constant table, read with a symbolic index,
is copied at every call too (~100 µs a point). So the robot enters as 11 R + 5 numbers.

Grid and accuracy: :data:`GRID_POINTS` = 40 points per joint over its range ± 15° (3.85°
apart for the prototype's ±60°); the padding keeps the points the OCP imposes between its
nodes, which the joint range does not bound, inside the grid. Against the exact model
(20,000 random points within the joint range, |q̇| ≤ 1.5 rad/s, |q̈| ≤ 1 rad/s²): max
error 1.6e-6 N·m for the prototype (max |τ| 0.44 N·m) and 5.7e-6 N·m with a 0.3 kg
payload 37 mm off the platform and μ = 0.1 (max |τ| 0.98 N·m), worst near the corners of
the joint box; 2° beyond the range 3.7e-6 and 1.4e-5, at 75° (the grid's edge) 8e-4 and
3e-3, the corners (±75°, ±75°) being nearer the singular (±90°, ±90°). The error falls as
the grid spacing to the 3.7th power (60 points: 1.0e-6 N·m with the payload) at no cost
per evaluation, only memory: the six coefficient tables are 6 × 42² × 46 doubles (12 MB
of generated C). :data:`TORQUE_ERROR` is the bound the tests hold.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import casadi as ca
import numpy as np

from spm_opt.model import kinematics
from spm_opt.model.params import DEG, Robot

PADDING = 15.0 * DEG
"""How far the table reaches beyond each end of the joint range, rad."""
GRID_POINTS = 40
"""Grid points per joint over the padded range."""
TORQUE_ERROR = 1e-5
"""Bound on |τ_table − τ_exact|, N·m, within the joint range for |q̇| ≤ 1.5 rad/s and
|q̈| ≤ 1 rad/s², for the prototype with up to 0.3 kg of payload (measured: 5.7e-6)."""

ENTRIES = ("M11", "M12", "M22", "c1_11", "c1_12", "c1_22", "c2_11", "c2_12", "c2_22", "G1", "G2")
"""The tabulated maps of q, N·m per (rad/s²), (rad/s)² or 1: τ_i = Σ_j M_ij q̈_j
+ c_i_11 q̇1² + c_i_12 q̇1 q̇2 + c_i_22 q̇2² + G_i + the exact terms."""
_INERTIA_ENTRIES = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_KINETIC_COLUMNS = 16  # |ḃ|², upper inertia (6), lower inertia (6), payload offset (3)
_POTENTIAL_COLUMNS = 6  # b_z, cos θ1, cos θ2, z-row of the upper platform's frame (3)
_TABULATED = _KINETIC_COLUMNS + _POTENTIAL_COLUMNS
_EXACT = 5  # J_ua, J_la, κ_u, κ_L, s
PARAMETERS = _TABULATED + _EXACT
"""Length of the base parameter vector π."""
RANK_TOLERANCE = 1e-6
"""Singular values of the tabulated maps below this fraction of the largest are dropped
(the prototype's 46th is 2.9e-4 of the largest, the 47th 4e-16; from the Gram matrix,
rounding reaches ~1e-8)."""
DERIVATIVES = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))
"""Orders (∂q1, ∂q2) the lookup reads: the value, the gradient and the Hessian."""
_DETACH = 2.0**60
"""floor(x · this) / this: x to 1e-18 (absolute), with a structurally zero derivative."""


def base_parameters(robot: Robot) -> np.ndarray:
    """The robot's base parameters π (:data:`PARAMETERS`,), in which the torque is linear.

    The kinetic columns (kg·m²): m_u r_u² + m_L r_L² + m_p r_u²; the upper platform's
    inertia plus the payload's point inertia m_p(|o|² 1 − o oᵀ) (xx, yy, zz, xy, xz, yz,
    body frame); the lower platform's; m_p r_u o. The potential columns (N·m):
    g(m_u r_u + m_L r_L + m_p r_u), g m_ua r_ua, g m_la r_la, g m_p o. Then the arcs'
    inertias about their axes J_ua, J_la (kg·m²), the friction torques per unit slide sign
    κ_u = μ g (m_u + m_p) r_u and κ_L = μ g m_L r_L (N·m), and the smoothing s (rad/s).
    """
    upper, lower = robot.upper_platform, robot.lower_platform
    upper_arc, lower_arc = robot.upper_arc, robot.lower_arc
    r_u, r_l, g, mu = upper.com_radius, lower.com_radius, robot.gravity, robot.friction.mu
    m_p, offset = robot.payload.mass, np.asarray(robot.payload.offset, dtype=float)
    point_inertia = m_p * (offset @ offset * np.eye(3) - np.outer(offset, offset))
    upper_inertia = np.asarray(upper.inertia) + point_inertia
    return np.array(
        [
            upper.mass * r_u**2 + lower.mass * r_l**2 + m_p * r_u**2,
            *(upper_inertia[ij] for ij in _INERTIA_ENTRIES),
            *(np.asarray(lower.inertia)[ij] for ij in _INERTIA_ENTRIES),
            *(m_p * r_u * offset),
            g * (upper.mass * r_u + lower.mass * r_l + m_p * r_u),
            g * upper_arc.mass * upper_arc.com_radius,
            g * lower_arc.mass * lower_arc.com_radius,
            *(g * m_p * offset),
            upper_arc.mass * upper_arc.com_radius**2 + upper_arc.inertia[0, 0],
            lower_arc.mass * lower_arc.com_radius**2 + lower_arc.inertia[1, 1],
            mu * g * (upper.mass + m_p) * r_u,
            mu * g * lower.mass * r_l,
            robot.friction.smoothing,
        ]
    )


# --- the regressor: the tabulated maps per base parameter ----------------------------


def _kinetic_matrices(k: kinematics.SymbolicKinematics) -> list[ca.SX]:
    """M_k (2, 2) of the kinetic columns, KE_k = ½ q̇ᵀ M_k q̇, in the order of π."""
    jacobian = k.direction_jacobian  # ∂b/∂q (3, 2)
    omegas = [
        ca.jacobian(frame.T @ omega, k.qd)  # body-frame angular velocity per q̇ (3, 2)
        for frame, omega in (
            (k.upper_frame, k.upper_angular_velocity),
            (k.lower_frame, k.lower_angular_velocity),
        )
    ]
    matrices = [jacobian.T @ jacobian]
    for omega in omegas:
        for i, j in _INERTIA_ENTRIES:
            product = omega[i, :].T @ omega[j, :]
            matrices.append(product if i == j else product + product.T)
    for i in range(3):  # ḃ · ė_i, e_i the upper platform's frame columns
        column_jacobian = ca.jacobian(k.upper_frame[:, i], k.q)
        coupling = jacobian.T @ column_jacobian
        matrices.append(coupling + coupling.T)
    return matrices


def _coriolis(mass: ca.SX, q: ca.SX) -> list[ca.SX]:
    """Coefficients (c_i_11, c_i_12, c_i_22) of q̇1², q̇1 q̇2, q̇2² in the Coriolis and
    centrifugal torque of joint i, from the Christoffel symbols of M."""
    d = [ca.reshape(ca.jacobian(ca.vec(mass), q[k]), 2, 2) for k in range(2)]  # ∂M/∂q_k
    coefficients = []
    for i in range(2):
        coefficients += [
            d[0][i, 0] - 0.5 * d[i][0, 0],
            d[1][i, 0] + d[0][i, 1] - d[i][0, 1],
            d[1][i, 1] - 0.5 * d[i][1, 1],
        ]
    return coefficients


def _potentials(k: kinematics.SymbolicKinematics) -> list[ca.SX]:
    """The potential columns U_k(q), U = Σ π_k U_k, in the order of π."""
    return [k.direction[2], ca.cos(k.q[0]), ca.cos(k.q[1]), *ca.vertsplit(k.upper_frame[2, :].T)]


@cache
def _regressor() -> ca.Function:
    """q -> Φ(q) (len(ENTRIES), tabulated columns): the tabulated maps are Φ π[:22]."""
    k = kinematics.symbolic()
    columns = []
    for mass in _kinetic_matrices(k):
        entries = [mass[0, 0], mass[0, 1], mass[1, 1], *_coriolis(mass, k.q), 0, 0]
        columns.append(ca.vertcat(*entries))
    for potential in _potentials(k):
        columns.append(ca.vertcat(*([0] * 9), ca.gradient(potential, k.q)))
    return ca.Function("torque_regressor", [k.q], [ca.horzcat(*columns)])


# --- the table ------------------------------------------------------------------------


def grid(joint_range: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The table's grid per joint, rad: :data:`GRID_POINTS` points over each joint's range
    (rows of ``joint_range``, (2, 2), rad) padded by :data:`PADDING`."""
    joint_range = np.asarray(joint_range, dtype=float)
    return tuple(
        np.linspace(low - PADDING, high + PADDING, GRID_POINTS) for low, high in joint_range
    )


def _spline_system(n: int) -> np.ndarray:
    """(n + 2, n + 2): interpolation at the n uniform knots by the uniform cubic B-spline's
    n + 2 coefficients, and not-a-knot at the second and last-but-one knots (no jump of
    the third derivative: the fourth difference of the coefficients vanishes there)."""
    system = np.zeros((n + 2, n + 2))
    for i in range(n):
        system[i, i : i + 3] = np.array([1.0, 4.0, 1.0]) / 6.0
    system[n, 0:5] = system[n + 1, n - 3 : n + 2] = [1.0, -4.0, 6.0, -4.0, 1.0]
    return system


def _coefficients(values: np.ndarray) -> np.ndarray:
    """B-spline coefficients (n + 2, n + 2, P) interpolating grid values (n, n, P)."""
    n = values.shape[0]
    inverse = np.linalg.inv(_spline_system(n))[:, :n]
    return np.einsum("ia,jb,abp->ijp", inverse, inverse, values, optimize=True)


def _knots(axis: np.ndarray) -> np.ndarray:
    """The uniform cubic B-spline's knots for grid points ``axis`` (n,): three more a side."""
    step = axis[1] - axis[0]
    ends = step * np.arange(1, 4)
    return np.concatenate([axis[0] - ends[::-1], axis, axis[-1] + ends])


@dataclass(frozen=True)
class _Table:
    """The tabulated maps of one joint range as R functions of q.

    Attributes
    ----------
    axes : tuple of ndarray (n,), rad
        The grid.
    coefficients : ndarray (n + 2, n + 2, R)
        The functions' B-spline coefficients on the grid's :func:`_knots`.
    weights : ndarray (len(ENTRIES), 22, R)
        Map (entry e, column k of π) = Σ_j weights[e, k, j] · function j.
    """

    axes: tuple[np.ndarray, np.ndarray]
    coefficients: np.ndarray
    weights: np.ndarray


@cache
def _table(joint_range: bytes) -> _Table:
    """The table for a joint range's bytes: the regressor on the grid, the R functions
    spanning its maps (their projections on the leading left singular vectors, from the
    Gram matrix: a full SVD is 100 times slower on busy cores) and their B-spline
    coefficients."""
    axes = grid(np.frombuffer(joint_range).reshape(2, 2))
    q1, q2 = np.meshgrid(*axes, indexing="ij")
    points = np.stack([q1.ravel(), q2.ravel()])  # point i n + j at (q1_i, q2_j)
    flat = np.array(_regressor().map(points.shape[1])(points))  # Φ of point p: columns p K…
    maps = flat.reshape(len(ENTRIES), points.shape[1], _TABULATED).transpose(0, 2, 1)
    maps = maps.reshape(-1, points.shape[1])  # (E K, N)
    squares, vectors = np.linalg.eigh(maps @ maps.T)  # singular values², left vectors
    kept = vectors[:, squares > RANK_TOLERANCE**2 * squares[-1]]  # (E K, R)
    functions = (kept.T @ maps).T.reshape(GRID_POINTS, GRID_POINTS, -1)
    weights = kept.reshape(len(ENTRIES), _TABULATED, -1)
    return _Table(axes, _coefficients(functions), weights)


def _key(joint_range: np.ndarray) -> bytes:
    return np.ascontiguousarray(joint_range, dtype=float).tobytes()


def table_values(robot: Robot) -> np.ndarray:
    """The robot as :func:`torque_function`'s last input, (11 R + 5,): the weights (11, R)
    of its tabulated maps on the table's functions of q (column-major; N·m per (rad/s²),
    (rad/s)² or 1, as :data:`ENTRIES`), then J_ua, J_la (kg·m²), κ_u, κ_L (N·m) and s
    (rad/s) (see :func:`base_parameters`). Under a millisecond once the table of the
    robot's joint range is built (about a second, once per process and joint range)."""
    pi = base_parameters(robot)
    weights = _table(_key(robot.joint_range)).weights
    combined = np.einsum("ekr,k->er", weights, pi[:_TABULATED])
    return np.concatenate([combined.ravel(order="F"), pi[_TABULATED:]])


# --- the Function -----------------------------------------------------------------------


def _detached(x: ca.SX) -> ca.SX:
    """x (to 1e-18) as CasADi sees a constant: its derivative is structurally zero."""
    return ca.floor(x * _DETACH) * (1.0 / _DETACH)


def _derivative(
    coefficients: np.ndarray, knots: list[np.ndarray], axis: int
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The coefficients and knots of a uniform B-spline's derivative along ``axis``: the
    coefficients' differences over the knot step, on the knots less one a side."""
    step = knots[axis][1] - knots[axis][0]
    knots = list(knots)
    knots[axis] = knots[axis][1:-1]
    return np.diff(coefficients, axis=axis) / step, knots


def _spline(table: _Table, point: ca.MX, orders: tuple[int, int]) -> ca.MX:
    """The table's R functions' derivative of ``orders`` (∂q1, ∂q2) at ``point`` (R,)."""
    coefficients, knots = table.coefficients, [_knots(axis) for axis in table.axes]
    for axis, order in enumerate(orders):
        for _ in range(order):
            coefficients, knots = _derivative(coefficients, knots, axis)
    flat = np.transpose(coefficients, (2, 0, 1)).ravel(order="F")  # function, q1, q2
    degrees = [3 - order for order in orders]
    rank = coefficients.shape[2]
    return ca.bspline(point, ca.DM(flat), [list(k) for k in knots], degrees, rank, {})


def _lookup(table: _Table) -> ca.Function:
    """(q0 (2) rad, weights (11 R)) -> the robot's tabulated maps and their derivatives at
    q0, (len(ENTRIES), len(DERIVATIVES))."""
    rank = table.coefficients.shape[2]
    q0, weights = ca.MX.sym("q0", 2), ca.MX.sym("weights", len(ENTRIES) * rank)
    functions = ca.horzcat(*(_spline(table, q0, orders) for orders in DERIVATIVES))
    maps = ca.reshape(weights, len(ENTRIES), rank) @ functions
    return ca.Function("torque_table_lookup", [q0, weights], [maps], {"never_inline": True})


def _tabulated(table: _Table, q: ca.SX, weights: ca.SX) -> ca.SX:
    """The tabulated maps at q (len(ENTRIES),): their second-order Taylor expansion about
    q0 = q clamped to the grid (δ = q − q0 is 0 inside it), whose value, gradient and
    Hessian in q are the spline's. q0 and the lookup's results are :func:`_detached`, so
    CasADi never differentiates the call (see the module docstring)."""
    low, high = (ca.DM([axis[k] for axis in table.axes]) for k in (0, -1))
    q0 = _detached(ca.fmin(ca.fmax(q, low), high))
    d = q - q0
    terms = ca.vertcat(1, d[0], d[1], 0.5 * d[0] ** 2, d[0] * d[1], 0.5 * d[1] ** 2)
    return _detached(_lookup(table)(q0, weights)) @ terms


def _friction(q: ca.SX, qd: ca.SX, kappa: ca.SX, smoothing: ca.SX) -> ca.SX:
    """b_z Aᵀ (κ ⊙ σ(A q̇)), N·m: the platforms' smooth Coulomb friction, exact.

    The slide map A = −(x_u, y_L)ᵀ ∂b/∂q (A q̇: the platforms' sliding rates along the
    rails, rad/s) in closed form: with u = N_L × N_u = (s2 c1, −c2 s1, c1 c2), b = u/|u|
    and x_u ⊥ b, x_uᵀ ∂b/∂q = (N_u × u)ᵀ ∂u/∂q / |u|² = (−s1 s2 c2, c1) / |u|², and
    y_Lᵀ ∂b/∂q = (u × N_L)ᵀ ∂u/∂q / |u|² = (−c2, c1 s1 s2) / |u|²; b_z = c1 c2 / |u|."""
    c1, s1, c2, s2 = ca.cos(q[0]), ca.sin(q[0]), ca.cos(q[1]), ca.sin(q[1])
    squared = (s2 * c1) ** 2 + (c2 * s1) ** 2 + (c1 * c2) ** 2  # |u|²
    slide_map = ca.vertcat(ca.horzcat(s1 * s2 * c2, -c1), ca.horzcat(c2, -c1 * s1 * s2)) / squared
    rates = slide_map @ qd
    signs = rates / ca.sqrt(rates**2 + smoothing**2)
    return c1 * c2 / ca.sqrt(squared) * (slide_map.T @ (kappa * signs))


@cache
def _torque_function(joint_range: bytes) -> ca.Function:
    """:func:`torque_function` for a joint range's bytes."""
    table = _table(joint_range)
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)
    n_weights = len(ENTRIES) * table.coefficients.shape[2]
    values = ca.SX.sym("values", n_weights + _EXACT)
    inertias, kappa, smoothing = (
        values[n_weights + i : n_weights + j] for i, j in ((0, 2), (2, 4), (4, 5))
    )
    m = _tabulated(table, q, values[:n_weights])
    mass = ca.vertcat(ca.horzcat(m[0], m[1]), ca.horzcat(m[1], m[2]))
    squares = ca.vertcat(qd[0] ** 2, qd[0] * qd[1], qd[1] ** 2)
    coriolis = ca.vertcat(ca.dot(m[3:6], squares), ca.dot(m[6:9], squares))
    tau = mass @ qdd + coriolis + m[9:11] + inertias * qdd + _friction(q, qd, kappa, smoothing)
    return ca.Function(
        "torque_table", [q, qd, qdd, values], [tau], ["q", "qd", "qdd", "values"], ["tau"]
    )


def torque_function(joint_range: np.ndarray) -> ca.Function:
    """(q (2) rad, q̇ (2) rad/s, q̈ (2) rad/s², :func:`table_values` of a robot with this
    joint range) -> its actuator torques τ (2), N·m, with smooth friction: an SX Function
    for robots whose joint range (rows per joint, (2, 2), rad) is ``joint_range``, cached
    per joint range. Map it over points with the values shared:
    ``f.map("name", "serial", n, [3], [])``."""
    return _torque_function(_key(joint_range))
