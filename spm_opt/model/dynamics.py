"""The robot's dynamics, by the paper's method (Section 4–5, Eqs. 6–16, 19–22).

Lagrange's equations of the first kind in the redundant coordinates p = (B_x, B_y, B_z,
θ1, θ2) with the three constraints γ1 = |B|² − r_u², γ2 = B_y C1 + B_z S1,
γ3 = B_x C2 − B_z S2: the first three equations give the multipliers λ, the last two the
actuator torques (Eq. 7). Friction forces on the platforms (Eqs. 20–22) enter the first
three as generalised forces Q̂_B. Everything is built once as CasADi expressions in which
the robot's parameters are inputs, so one set of generated functions serves every robot
and every sweep; the numpy functions below evaluate them over N samples at once (the
torques compiled to C when a compiler is at hand, :mod:`spm_opt.model.compiled`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import casadi as ca
import numpy as np

from spm_opt.model import kinematics
from spm_opt.model.compiled import BatchFunction, compile_batch
from spm_opt.model.kinematics import Vec, add, cross, scale
from spm_opt.model.params import Robot

_BODY_NAMES = ("upper_platform", "lower_platform", "upper_arc", "lower_arc")
PARAMETER_NAMES = (
    [f"{body}.{item}" for body in _BODY_NAMES for item in ("mass", "com_radius")]
    + [
        f"{body}.inertia.{ij}"
        for body in _BODY_NAMES
        for ij in ("xx", "yy", "zz", "xy", "xz", "yz")
    ]
    + ["payload.mass", "payload.x", "payload.y", "payload.z", "mu", "smoothing", "gravity"]
)
"""Names of the entries of the parameter vector, in order."""


def parameter_vector(robot: Robot) -> np.ndarray:
    """The robot's dynamic parameters as the vector the generated functions take (SI)."""
    values = []
    bodies = [getattr(robot, name) for name in _BODY_NAMES]
    for body in bodies:
        values += [body.mass, body.com_radius]
    for body in bodies:
        i = body.inertia
        values += [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]
    values += [robot.payload.mass, *robot.payload.offset]
    values += [robot.friction.mu, robot.friction.smoothing, robot.gravity]
    return np.array(values, dtype=float)


@dataclass(frozen=True)
class _Symbols:
    """The parameter vector unpacked into named CasADi symbols."""

    vector: ca.SX
    masses: dict[str, ca.SX]
    radii: dict[str, ca.SX]
    inertias: dict[str, ca.SX]
    payload_mass: ca.SX
    payload_offset: Vec
    mu: ca.SX
    smoothing: ca.SX
    gravity: ca.SX


def _parameters() -> _Symbols:
    vector = ca.SX.sym("parameters", len(PARAMETER_NAMES))
    at = {name: vector[k] for k, name in enumerate(PARAMETER_NAMES)}
    inertias = {}
    for body in _BODY_NAMES:
        xx, yy, zz, xy, xz, yz = (
            at[f"{body}.inertia.{ij}"] for ij in ("xx", "yy", "zz", "xy", "xz", "yz")
        )
        inertias[body] = ca.vertcat(
            ca.horzcat(xx, xy, xz), ca.horzcat(xy, yy, yz), ca.horzcat(xz, yz, zz)
        )
    return _Symbols(
        vector=vector,
        masses={b: at[f"{b}.mass"] for b in _BODY_NAMES},
        radii={b: at[f"{b}.com_radius"] for b in _BODY_NAMES},
        inertias=inertias,
        payload_mass=at["payload.mass"],
        payload_offset=(at["payload.x"], at["payload.y"], at["payload.z"]),
        mu=at["mu"],
        smoothing=at["smoothing"],
        gravity=at["gravity"],
    )


def _column(v: Vec) -> ca.SX:
    return ca.vertcat(*v)


def _rotational_energy(
    frame: tuple[Vec, Vec, Vec], rates: ca.SX, coordinates: ca.SX, inertia: ca.SX
) -> ca.SX:
    """½ ωᵀ R I Rᵀ ω with ω = ½ Σ e_i × ė_i (Eq. 18) and ė_i = ∂e_i/∂p · ṗ."""
    omega: Vec = (0.0, 0.0, 0.0)
    for e in frame:
        e_dot = ca.jtimes(_column(e), coordinates, rates)
        omega = add(omega, cross(e, (e_dot[0], e_dot[1], e_dot[2])))
    omega_body = ca.mtimes(ca.horzcat(*(_column(e) for e in frame)).T, _column(scale(omega, 0.5)))
    return 0.5 * ca.dot(omega_body, ca.mtimes(inertia, omega_body))


@dataclass(frozen=True)
class _Model:
    """Generated CasADi functions of (q, qd, qdd, parameters), one column per sample."""

    torque: ca.Function  # -> frictionless τ (2), smooth friction τ_f (2), exact friction τ_f (2)
    multipliers: ca.Function  # -> λ frictionless (3), λ_f smooth (3), λ_f exact (3)
    energy: ca.Function  # (q, qd, parameters) -> kinetic, potential
    friction_forces: ca.Function  # (q, qd, parameters) -> F_fu (3), F_fl (3), exact, μ as given
    plant: ca.Function  # (q, qd, parameters) -> M (4), bias (2), slide map A (4), friction C (4)


@cache
def _model() -> _Model:
    """Build the Lagrange dynamics once (cached for the process)."""
    par = _parameters()
    r_u, r_l = par.radii["upper_platform"], par.radii["lower_platform"]
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)

    # redundant coordinates p = (B, θ) and their rates, as independent symbols
    p, p_dot = ca.SX.sym("p", 5), ca.SX.sym("p_dot", 5)
    b_vec: Vec = (p[0], p[1], p[2])
    theta1, theta2 = p[3], p[4]
    unit: Vec = scale(b_vec, 1.0 / r_u)
    upper_frame, lower_frame = kinematics.frames_at(unit, theta1, theta2)
    b_dot = p_dot[0:3]
    d_dot = (r_l / r_u) * b_dot
    payload = add(
        b_vec,
        add(
            add(
                scale(upper_frame[0], par.payload_offset[0]),
                scale(upper_frame[1], par.payload_offset[1]),
            ),
            scale(upper_frame[2], par.payload_offset[2]),
        ),
    )
    payload_dot = ca.jtimes(_column(payload), p, p_dot)
    m = par.masses
    kinetic = (
        0.5 * m["upper_platform"] * ca.dot(b_dot, b_dot)
        + _rotational_energy(upper_frame, p_dot, p, par.inertias["upper_platform"])
        + 0.5 * m["lower_platform"] * ca.dot(d_dot, d_dot)
        + _rotational_energy(lower_frame, p_dot, p, par.inertias["lower_platform"])
        + 0.5 * m["upper_arc"] * (p_dot[3] * par.radii["upper_arc"]) ** 2
        + 0.5 * par.inertias["upper_arc"][0, 0] * p_dot[3] ** 2
        + 0.5 * m["lower_arc"] * (p_dot[4] * par.radii["lower_arc"]) ** 2
        + 0.5 * par.inertias["lower_arc"][1, 1] * p_dot[4] ** 2
        + 0.5 * par.payload_mass * ca.dot(payload_dot, payload_dot)
    )
    g = par.gravity
    potential = g * (
        m["upper_platform"] * p[2]
        + m["lower_platform"] * (r_l / r_u) * p[2]
        + m["upper_arc"] * par.radii["upper_arc"] * ca.cos(theta1)
        + m["lower_arc"] * par.radii["lower_arc"] * ca.cos(theta2)
        + par.payload_mass * payload[2]
    )
    lagrangian = kinetic - potential
    constraints = ca.vertcat(
        ca.dot(p[0:3], p[0:3]) - r_u**2,
        p[1] * ca.cos(theta1) + p[2] * ca.sin(theta1),
        p[0] * ca.cos(theta2) - p[2] * ca.sin(theta2),
    )
    constraint_jacobian = ca.jacobian(constraints, p)  # (3, 5)

    # friction (Eqs. 20–22): weight-only normal forces, against the sliding direction
    normal = (p[2] / r_u) * g * par.mu
    x_u, y_l = upper_frame[0], lower_frame[1]
    slide_upper = -ca.dot(b_dot, _column(x_u)) / r_u  # rad/s
    slide_lower = -ca.dot(b_dot, _column(y_l)) / r_u

    def friction(sign_upper: ca.SX, sign_lower: ca.SX) -> tuple[ca.SX, ca.SX]:
        upper = sign_upper * normal * (m["upper_platform"] + par.payload_mass) * _column(x_u)
        lower = sign_lower * normal * m["lower_platform"] * _column(y_l)
        return upper, lower

    def smooth_sign(v: ca.SX) -> ca.SX:
        return v / ca.sqrt(v**2 + par.smoothing**2)

    exact_forces = friction(ca.sign(slide_upper), ca.sign(slide_lower))
    signs = ca.SX.sym("signs", 2)
    signed_forces = friction(signs[0], signs[1])
    smooth_forces = friction(smooth_sign(slide_upper), smooth_sign(slide_lower))

    # Euler–Lagrange expressions E = d/dt ∂L/∂ṗ − ∂L/∂p along p(t)
    p_ddot = ca.SX.sym("p_ddot", 5)
    momentum = ca.gradient(lagrangian, p_dot)
    euler_lagrange = (
        ca.mtimes(ca.jacobian(momentum, p_dot), p_ddot)
        + ca.mtimes(ca.jacobian(momentum, p), p_dot)
        - ca.gradient(lagrangian, p)
    )
    g_b, g_theta = constraint_jacobian[:, 0:3], constraint_jacobian[:, 3:5]

    def solve(generalised_b: ca.SX) -> tuple[ca.SX, ca.SX]:
        """Eq. 7: multipliers from the B equations, then the torques from the θ ones."""
        lam = ca.solve(g_b.T, generalised_b)
        return lam, -ca.mtimes(g_theta.T, lam)

    lam_0, tau_rest = solve(euler_lagrange[0:3])
    tau_0 = euler_lagrange[3:5] + tau_rest
    force_smooth = smooth_forces[0] + (r_l / r_u) * smooth_forces[1]
    force_exact = exact_forces[0] + (r_l / r_u) * exact_forces[1]
    lam_smooth, tau_smooth = solve(-force_smooth)
    lam_exact, tau_exact = solve(-force_exact)
    _, tau_signed = solve(-(signed_forces[0] + (r_l / r_u) * signed_forces[1]))

    # substitute the kinematics: B = r_u b(θ), Ḃ = J θ̇, B̈ = J θ̈ + J̇ θ̇
    b_of_q = r_u * _column(kinematics.direction(q[0], q[1]))
    b_rate = ca.jtimes(b_of_q, q, qd)
    b_accel = ca.jtimes(b_rate, q, qd) + ca.jtimes(b_of_q, q, qdd)
    substitution = [p, p_dot, p_ddot]
    values = [ca.vertcat(b_of_q, q), ca.vertcat(b_rate, qd), ca.vertcat(b_accel, qdd)]

    def in_joint_space(*expressions: ca.SX) -> list[ca.SX]:
        return ca.substitute(list(expressions), substitution, values)

    inputs, names = [q, qd, qdd, par.vector], ["q", "qd", "qdd", "parameters"]
    torque = ca.Function(
        "torque",
        inputs,
        in_joint_space(tau_0, tau_smooth, tau_exact),
        names,
        ["frictionless", "friction_smooth", "friction_exact"],
    )
    multipliers = ca.Function(
        "multipliers",
        inputs,
        in_joint_space(lam_0, lam_smooth, lam_exact),
        names,
        ["frictionless", "friction_smooth", "friction_exact"],
    )
    energy = ca.Function(
        "energy",
        [q, qd, par.vector],
        in_joint_space(kinetic, potential),
        ["q", "qd", "parameters"],
        ["kinetic", "potential"],
    )
    friction_forces = ca.Function(
        "friction_forces",
        [q, qd, par.vector],
        in_joint_space(*exact_forces),
        ["q", "qd", "parameters"],
        ["upper", "lower"],
    )
    # for simulation: τ = M q̈ + bias + C σ with σ ∈ sign(A q̇), the slides' signs
    tau_joint, slide_rates, friction_map = in_joint_space(
        tau_0, ca.vertcat(slide_upper, slide_lower), ca.jacobian(tau_signed, signs)
    )
    mass = ca.jacobian(tau_joint, qdd)
    bias = ca.substitute(tau_joint, qdd, ca.DM.zeros(2))
    slide_map = ca.jacobian(slide_rates, qd)

    def flat(matrix: ca.SX) -> ca.SX:
        return ca.reshape(matrix.T, -1, 1)

    plant = ca.Function(
        "plant",
        [q, qd, par.vector],
        [flat(mass), bias, flat(slide_map), flat(friction_map)],
        ["q", "qd", "parameters"],
        ["mass", "bias", "slide_map", "friction_map"],
    )
    return _Model(torque, multipliers, energy, friction_forces, plant)


def torque_function() -> ca.Function:
    """The symbolic model's torques: (q, q̇, q̈, :func:`parameter_vector`) -> frictionless,
    smooth-friction and exact-friction parts (2 each, N·m), one sample per column."""
    return _model().torque


@cache
def _batch_torque() -> BatchFunction | None:
    return compile_batch(_model().torque)


def _torque_parts(robot: Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> list[np.ndarray]:
    """Frictionless, smooth-friction and exact-friction torques, each (N, 2), N·m."""
    arrays = np.broadcast_arrays(*(np.atleast_2d(np.asarray(a, dtype=float)) for a in (q, qd, qdd)))
    parameters = parameter_vector(robot)
    batch = _batch_torque()
    if batch is None:
        return [_rows(v) for v in _model().torque(*_columns(*arrays), parameters)]
    return batch(*arrays, parameters, shared=(3,))


def _columns(*arrays: np.ndarray) -> list[np.ndarray]:
    return [np.atleast_2d(np.asarray(a, dtype=float)).T for a in arrays]


def _rows(value: ca.DM) -> np.ndarray:
    return value.full().T


def inverse_dynamics(
    robot: Robot,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    *,
    friction: bool = True,
    exact: bool = True,
) -> np.ndarray:
    """Actuator torques (N, 2), N·m, for joint angles, rates and accelerations (N, 2) in
    rad, rad/s, rad/s².

    ``friction`` adds the platforms' Coulomb friction (Eqs. 20–22); ``exact`` uses sign(),
    otherwise the smooth sign the optimisers see.
    """
    frictionless, smooth, exact_part = _torque_parts(robot, q, qd, qdd)
    if friction:
        return frictionless + (exact_part if exact else smooth)
    return frictionless


def actuator_torque(robot: Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """What the actuators deliver (N, 2), N·m: the model's torques with exact friction,
    through the actuator's rotor inertia and gear efficiency (when the robot has them)."""
    load = inverse_dynamics(robot, q, qd, qdd, friction=True, exact=True)
    return robot.actuator.drive_torque(load, qd, qdd)


def paced_torque_terms(
    robot: Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The model's torques (each (N, 2), N·m) split by how they follow the pace of a
    motion, from one evaluation: the inertial and velocity terms M(q) q̈ + C(q, q̇) q̇,
    gravity g(q) and the platforms' exact friction; with exact friction, τ is their sum.
    Run f times as fast (q̇ → f q̇, q̈ → f² q̈), the first scales by f² and the others stay
    (the friction's sign follows the direction of motion only)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    rest = np.zeros_like(q)
    frictionless, _, exact = _torque_parts(
        robot,
        np.vstack([q, q]),
        np.vstack([np.broadcast_to(qd, q.shape), rest]),
        np.vstack([np.broadcast_to(qdd, q.shape), rest]),
    )
    samples = len(q)
    gravity = frictionless[samples:]
    return frictionless[:samples] - gravity, gravity, exact[:samples]


def friction_torque(
    robot: Robot, q: np.ndarray, qd: np.ndarray, *, exact: bool = True
) -> np.ndarray:
    """The part of the actuator torques (N, 2), N·m, that overcomes friction."""
    _, smooth, exact_part = _torque_parts(robot, q, qd, np.zeros_like(np.atleast_2d(q), float))
    return exact_part if exact else smooth


def gravity_torque(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Torques (N, 2), N·m, that hold the robot still at q."""
    zeros = np.zeros_like(np.atleast_2d(q), dtype=float)
    return inverse_dynamics(robot, q, zeros, zeros, friction=False)


def bias_torque(robot: Robot, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Coriolis and centrifugal torques (N, 2), N·m (gravity and friction excluded)."""
    zeros = np.zeros_like(np.atleast_2d(q), dtype=float)
    return inverse_dynamics(robot, q, qd, zeros, friction=False) - gravity_torque(robot, q)


def mass_matrix(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Reduced mass matrix M(q), shape (N, 2, 2), kg·m²: τ = M q̈ + bias + gravity + friction."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    zeros = np.zeros_like(q)
    columns = []
    for joint in range(2):
        unit = zeros.copy()
        unit[:, joint] = 1.0
        columns.append(
            inverse_dynamics(robot, q, zeros, unit, friction=False) - gravity_torque(robot, q)
        )
    return np.stack(columns, axis=-1)


def forward_dynamics(
    robot: Robot,
    q: np.ndarray,
    qd: np.ndarray,
    torque: np.ndarray,
    *,
    friction: bool = True,
    exact: bool = True,
) -> np.ndarray:
    """Joint accelerations (N, 2), rad/s², under actuator torques (N, 2), N·m.

    With exact friction the platforms slide (the sign is taken from the velocity); holding
    still against friction (sticking) is the simulator's business, not this function's.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    zeros = np.zeros_like(q)
    free = inverse_dynamics(robot, q, qd, zeros, friction=friction, exact=exact)
    rhs = np.atleast_2d(torque) - free
    return np.linalg.solve(mass_matrix(robot, q), rhs[..., None])[..., 0]


def multipliers(
    robot: Robot,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    *,
    friction: bool = True,
    exact: bool = True,
) -> np.ndarray:
    """Lagrange multipliers λ (N, 3) of the constraints γ1, γ2, γ3 (Eq. 7), SI."""
    frictionless, smooth, exact_part = _model().multipliers(
        *_columns(q, qd, qdd), parameter_vector(robot)
    )
    lam = _rows(frictionless)
    if friction:
        lam = lam + _rows(exact_part if exact else smooth)
    return lam


def mechanical_energy(robot: Robot, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kinetic and potential energy, each (N,), J."""
    kinetic, potential = _model().energy(*_columns(q, qd), parameter_vector(robot))
    return kinetic.full().ravel(), potential.full().ravel()


@cache
def _energy_rate() -> ca.Function:
    """d(K + U)/dt = ∂E/∂q q̇ + ∂E/∂q̇ q̈, differentiated from the energy alone."""
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)
    parameters = ca.SX.sym("parameters", _model().energy.size1_in(2))
    kinetic, potential = _model().energy(q, qd, parameters)
    total = kinetic + potential
    rate = ca.jtimes(total, q, qd) + ca.jtimes(total, qd, qdd)
    return ca.Function("energy_rate", [q, qd, qdd, parameters], [rate])


def energy_rate(robot: Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """Rate of change of the mechanical energy K + U, (N,), W, along a motion. Without
    friction it equals the actuators' power τ·θ̇ (the power balance)."""
    return _energy_rate()(*_columns(q, qd, qdd), parameter_vector(robot)).full().ravel()


def friction_forces(robot: Robot, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Friction forces (Eqs. 21–22) on the upper and lower platforms, each (N, 3), N."""
    upper, lower = _model().friction_forces(*_columns(q, qd), parameter_vector(robot))
    return _rows(upper), _rows(lower)


class PlantTerms:
    """The terms a simulator needs at one state (q, q̇), evaluated through a CasADi
    buffer (about 30 µs a call, no array conversion): the mass matrix M (2, 2), kg·m²;
    the bias torques (2,), N·m (gravity, Coriolis, centrifugal); the slide map A (2, 2)
    that gives the platforms' sliding rates A q̇, rad/s; and the friction map C (2, 2),
    N·m, so that the friction torques are C sign(A q̇)."""

    def __init__(self, robot: Robot) -> None:
        self._buffer, self._evaluate = _model().plant.buffer()
        self._q, self._qd = np.zeros(2), np.zeros(2)
        self._parameters = parameter_vector(robot)
        self._outputs = [np.zeros(4), np.zeros(2), np.zeros(4), np.zeros(4)]
        for index, array in enumerate((self._q, self._qd, self._parameters)):
            self._buffer.set_arg(index, memoryview(array))
        for index, array in enumerate(self._outputs):
            self._buffer.set_res(index, memoryview(array))

    def __call__(
        self, q: np.ndarray, qd: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        self._q[:] = q
        self._qd[:] = qd
        self._evaluate()
        mass, bias, slide_map, friction_map = self._outputs
        return (
            mass.reshape(2, 2).copy(),
            bias.copy(),
            slide_map.reshape(2, 2).copy(),
            friction_map.reshape(2, 2).copy(),
        )
