"""Actuator torques by Euler–Lagrange in minimal coordinates θ = (θ1, θ2).

This module is written separately from ``spm_opt/model/dynamics.py`` ON PURPOSE: it is the
project's cross-check of the paper's redundant-coordinate Lagrange method (Section 4,
Eqs. 6–7, 15–19) and of its friction model (Section 5, Eqs. 20–22). It shares only the
geometry with the rest of the package (B(θ) of Eq. 5 and the platform frames of Eq. 17,
from :mod:`spm_opt.model.kinematics`); everything else is derived here by another route:

- angular velocities from the rotation matrices themselves, ω = vee(Ṙ Rᵀ) with
  Ṙ = Σ_k ∂R/∂θ_k θ̇_k by CasADi's automatic differentiation (not
  ``kinematics.angular_velocity`` / ``frame_rates``);
- the Lagrangian L = K − U written in θ with B = B(θ) substituted, so no constraint and
  no Lagrange multiplier appears;
- τ = d/dt(∂L/∂θ̇) − ∂L/∂θ − Q_θ, where d/dt(∂L/∂θ̇) = (∂²L/∂θ̇²) θ̈ + (∂²L/∂θ̇∂θ) θ̇;
- friction as virtual work: Q_θ = (∂B/∂θ)ᵀ (F_fu + (r_L/r_u) F_fl), the forces acting at
  B and at D = (r_L/r_u) B.

The robot's parameters are inputs of the CasADi Functions, so the symbolic model is built
once per process and serves every :class:`~spm_opt.model.params.Robot`.
"""

from __future__ import annotations

from functools import cache

import casadi as ca
import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.model import kinematics
from spm_opt.model.params import Body, Robot

__all__ = ["minimal_energy", "minimal_inverse_dynamics", "robot_parameters"]

# Layout of the parameter vector p fed to the Functions (see robot_parameters).
_SCALARS = ("r_u", "r_l", "m_u", "m_l", "m_ua", "m_la", "r_ua", "r_la", "m_p", "mu", "eps", "g")
_N_PARAMETERS = len(_SCALARS) + 3 + 4 * 9  # scalars, payload offset, four inertia tensors


def robot_parameters(robot: Robot, *, friction: bool = True) -> np.ndarray:
    """Pack a robot into the parameter vector of the CasADi Functions.

    Parameters
    ----------
    robot : Robot
    friction : bool
        If False, the friction coefficient is packed as 0.

    Returns
    -------
    ndarray, shape (P,)
        SI units: radii m, masses kg, μ dimensionless, smoothing rad/s, g m/s², the
        payload offset (3,) m, then the four inertia tensors (3, 3) kg·m² flattened
        row-major (upper platform, lower platform, upper arc, lower arc).
    """
    scalars = [
        robot.upper_platform_radius,
        robot.lower_platform_radius,
        robot.upper_platform.mass,
        robot.lower_platform.mass,
        robot.upper_arc.mass,
        robot.lower_arc.mass,
        robot.upper_arc.com_radius,
        robot.lower_arc.com_radius,
        robot.payload.mass,
        robot.friction.mu if friction else 0.0,
        robot.friction.smoothing,
        robot.gravity,
    ]
    bodies: tuple[Body, ...] = (
        robot.upper_platform,
        robot.lower_platform,
        robot.upper_arc,
        robot.lower_arc,
    )
    inertias = [np.asarray(b.inertia, dtype=float).reshape(9) for b in bodies]
    offset = np.asarray(robot.payload.offset, dtype=float).reshape(3)
    p = np.concatenate([np.asarray(scalars, dtype=float), offset, *inertias])
    assert p.shape == (_N_PARAMETERS,)
    return p


# --- the symbolic model ------------------------------------------------------------


def _vee(skew: ca.SX) -> ca.SX:
    """w from [w]× (the antisymmetric part, so rounding in Ṙ Rᵀ does not matter)."""
    return 0.5 * ca.vertcat(
        skew[2, 1] - skew[1, 2], skew[0, 2] - skew[2, 0], skew[1, 0] - skew[0, 1]
    )


def _angular_velocity(rotation: ca.SX, q: ca.SX, qd: ca.SX) -> ca.SX:
    """ω = vee(Ṙ Rᵀ) with Ṙ = Σ_k ∂R/∂θ_k θ̇_k (base-frame angular velocity)."""
    rate = ca.reshape(ca.jacobian(ca.vec(rotation), q) @ qd, 3, 3)
    return _vee(rate @ rotation.T)


def _column(v: kinematics.Vec) -> ca.SX:
    return ca.vertcat(*v)


def _body_energy(
    mass: ca.SX, inertia: ca.SX, rotation: ca.SX, com: ca.SX, q: ca.SX, qd: ca.SX, g: ca.SX
) -> tuple[ca.SX, ca.SX]:
    """½ m |v|² + ½ ωᵀ R I Rᵀ ω and m g z of one rigid body, its mass centre at ``com``."""
    velocity = ca.jacobian(com, q) @ qd
    omega = _angular_velocity(rotation, q, qd)
    kinetic = 0.5 * mass * ca.dot(velocity, velocity) + 0.5 * ca.dot(
        omega, rotation @ inertia @ rotation.T @ omega
    )
    return kinetic, mass * g * com[2]


@cache
def _functions(exact: bool) -> tuple[ca.Function, ca.Function]:
    """CasADi Functions (torque, energy) of (q, qd, qdd, p) and (q, qd, p), one sample each."""
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)
    p = ca.SX.sym("p", _N_PARAMETERS)
    s = {name: p[i] for i, name in enumerate(_SCALARS)}
    base = len(_SCALARS)
    offset = p[base : base + 3]
    inertia = [ca.reshape(p[base + 3 + 9 * k : base + 12 + 9 * k], 3, 3).T for k in range(4)]
    r_u, r_l, g = s["r_u"], s["r_l"], s["g"]
    theta1, theta2 = q[0], q[1]

    # Geometry shared with the package: Eq. 5 (b = B/r_u) and Eq. 17 (platform frames).
    b = _column(kinematics.direction(theta1, theta2))
    upper_cols, lower_cols = kinematics.frames(theta1, theta2)
    rot_u = ca.horzcat(*(_column(c) for c in upper_cols))
    rot_l = ca.horzcat(*(_column(c) for c in lower_cols))
    point_b = r_u * b
    point_d = r_l * b  # D = (r_L / r_u) B

    # Eq. 16: the arcs turn about x (θ1) and y (θ2); mass centres on their z axes.
    c1, s1, c2, s2 = ca.cos(theta1), ca.sin(theta1), ca.cos(theta2), ca.sin(theta2)
    rot_ua = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c1, -s1), ca.horzcat(0, s1, c1))
    rot_la = ca.vertcat(ca.horzcat(c2, 0, s2), ca.horzcat(0, 1, 0), ca.horzcat(-s2, 0, c2))
    com_ua = s["r_ua"] * rot_ua[:, 2]
    com_la = s["r_la"] * rot_la[:, 2]

    parts = [
        _body_energy(s["m_u"], inertia[0], rot_u, point_b, q, qd, g),
        _body_energy(s["m_l"], inertia[1], rot_l, point_d, q, qd, g),
        _body_energy(s["m_ua"], inertia[2], rot_ua, com_ua, q, qd, g),
        _body_energy(s["m_la"], inertia[3], rot_la, com_la, q, qd, g),
        # payload: a point mass rigidly on the upper platform
        _body_energy(s["m_p"], ca.SX.zeros(3, 3), rot_u, point_b + rot_u @ offset, q, qd, g),
    ]
    kinetic = sum(k for k, _ in parts)
    potential = sum(u for _, u in parts)
    lagrangian = kinetic - potential

    # Euler–Lagrange in θ: τ = d/dt(∂L/∂θ̇) − ∂L/∂θ.
    momentum = ca.jacobian(lagrangian, qd).T
    mass_matrix = ca.jacobian(momentum, qd)
    mixed = ca.jacobian(momentum, q)
    euler_lagrange = mass_matrix @ qdd + mixed @ qd - ca.jacobian(lagrangian, q).T

    # Friction, Eqs. 20–22, as generalised forces on θ by virtual work.
    jac_b = ca.jacobian(point_b, q)  # ∂B/∂θ, m/rad
    b_dot = jac_b @ qd
    x_u, y_l = rot_u[:, 0], rot_l[:, 1]
    rate_u = -ca.dot(b_dot, x_u) / r_u  # sliding rates against the rails, rad/s
    rate_l = -ca.dot(b_dot, y_l) / r_u
    if exact:
        sign_u, sign_l = ca.sign(rate_u), ca.sign(rate_l)
    else:
        eps = s["eps"]
        sign_u = rate_u / ca.sqrt(rate_u**2 + eps**2)
        sign_l = rate_l / ca.sqrt(rate_l**2 + eps**2)
    normal = b[2] * g * s["mu"]  # B_z / r_u · g μ
    force_u = sign_u * normal * (s["m_u"] + s["m_p"]) * x_u
    force_l = sign_l * normal * s["m_l"] * y_l
    q_theta = jac_b.T @ (force_u + (r_l / r_u) * force_l)

    torque = euler_lagrange - q_theta
    torque_fn = ca.Function(
        "minimal_torque", [q, qd, qdd, p], [torque], ["q", "qd", "qdd", "p"], ["tau"]
    )
    energy_fn = ca.Function(
        "minimal_energy", [q, qd, p], [kinetic, potential], ["q", "qd", "p"], ["K", "U"]
    )
    return torque_fn, energy_fn


# --- the numpy face ----------------------------------------------------------------


def _samples(name: str, value: np.ndarray, n: int | None) -> np.ndarray:
    array = np.atleast_2d(np.asarray(value, dtype=float))
    if array.ndim != 2 or array.shape[1] != 2:
        raise InputError(f"{name}: expected shape (N, 2), got {np.shape(value)}")
    if n is not None and array.shape[0] != n:
        raise InputError(f"{name}: expected {n} samples like q, got {array.shape[0]}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name}: expected finite numbers")
    return array


def _parameter_columns(robot: Robot, n: int, friction: bool) -> np.ndarray:
    return np.repeat(robot_parameters(robot, friction=friction)[:, None], n, axis=1)


def minimal_inverse_dynamics(
    robot: Robot,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    *,
    friction: bool = True,
    exact: bool = True,
) -> np.ndarray:
    """Actuator torques from Euler–Lagrange in minimal coordinates.

    Parameters
    ----------
    robot : Robot
    q, qd, qdd : ndarray, shape (N, 2)
        Joint angles (rad), rates (rad/s) and accelerations (rad/s²) of (θ1, θ2).
    friction : bool
        Include the rail friction of Eqs. 20–22 with ``robot.friction.mu``.
    exact : bool
        True: sign() of the sliding rate; False: the smooth sign v / sqrt(v² + ε²) with
        v the sliding rate in rad/s and ε = ``robot.friction.smoothing``.

    Returns
    -------
    ndarray, shape (N, 2)
        Torques (τ1, τ2) the actuators must supply, N·m.
    """
    q = _samples("q", q, None)
    n = q.shape[0]
    qd, qdd = _samples("qd", qd, n), _samples("qdd", qdd, n)
    torque_fn, _ = _functions(bool(exact))
    tau = torque_fn.map(n)(q.T, qd.T, qdd.T, _parameter_columns(robot, n, friction))
    return np.asarray(tau).T.reshape(n, 2)


def minimal_energy(robot: Robot, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kinetic and potential energy of the whole robot (four bodies and the payload).

    Parameters
    ----------
    robot : Robot
    q, qd : ndarray, shape (N, 2)
        Joint angles (rad) and rates (rad/s).

    Returns
    -------
    kinetic, potential : ndarray, shape (N,)
        J; the potential is m g z summed over the mass centres (zero at the isocenter).
    """
    q = _samples("q", q, None)
    n = q.shape[0]
    qd = _samples("qd", qd, n)
    _, energy_fn = _functions(True)
    kinetic, potential = energy_fn.map(n)(q.T, qd.T, _parameter_columns(robot, n, True))
    return np.asarray(kinetic).reshape(n), np.asarray(potential).reshape(n)
