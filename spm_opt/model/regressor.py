"""The actuator torques as linear in the robot's inertial and friction parameters,
τ = Y(q, q̇, q̈) π + τ_payload, from the one symbolic model (:mod:`spm_opt.model.dynamics`).

The standard parameters π (:data:`STANDARD_PARAMETERS`, SI):

- each body's mass (its mass centre at the robot's fixed ``com_radius``) and the six entries
  of its inertia tensor about that centre, in the body's frame: 28. A body turning about
  the isocenter shows the mass through its first moment (gravity) and its inertia about
  the isocenter, both linear in the mass once the radius is fixed;
- the rails' friction, one per platform: φ_u = μ (m_u + m_payload) and φ_L = μ m_L, kg.
  The model's friction torque is μ times a platform's mass times a function of the motion
  (Eqs. 20–22), so it is linear in these products, not in μ and the masses apart;
- per actuator, at its output: the reflected rotor inertia J (kg·m²), viscous friction f_v
  (N·m·s/rad), Coulomb friction f_c (N·m) and a constant offset o (N·m, e.g. of the
  current sensor): 8. The model has J, f_v and f_c (the actuator's
  ``rotor_inertia_kg_m2``, ``viscous_friction_nm_s_per_rad`` and ``coulomb_friction_nm``):
  o is 0 in :func:`standard_parameters`. A
  gear efficiency below 1 makes the torque piecewise in the sign of the power, not
  linear: the regressor is for η = 1.

The lengths, gravity and the payload (a known tool: its mass and offset) stay fixed;
τ_payload is the payload's torque without friction. The bodies' columns of Y are CasADi's
exact derivatives of the model's frictionless torque with respect to their parameters
(the torque is linear in them: the derivatives hold none of them, which the tests check);
the rails' columns are the model's exact-friction torque with μ = 1 and a unit mass on one
platform. Y is evaluated over many samples by the compiled batch path
(:mod:`spm_opt.model.compiled`).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.model import dynamics
from spm_opt.model.compiled import BatchFunction, compile_batch
from spm_opt.model.params import Robot

BODIES = ("upper_platform", "lower_platform", "upper_arc", "lower_arc")
INERTIA_ENTRIES = ("xx", "yy", "zz", "xy", "xz", "yz")
_BODY_PARAMETERS = tuple(f"{body}.mass" for body in BODIES) + tuple(
    f"{body}.inertia.{ij}" for body in BODIES for ij in INERTIA_ENTRIES
)
RAIL_PARAMETERS = ("rail_friction.upper", "rail_friction.lower")
DRIVE_PARAMETERS = tuple(
    f"{term}.theta{joint}"
    for joint in (1, 2)
    for term in ("rotor_inertia", "viscous_friction", "coulomb_friction", "offset")
)
DRIVE_TERMS = 4
"""Drive parameters per joint."""
STANDARD_PARAMETERS = _BODY_PARAMETERS + RAIL_PARAMETERS + DRIVE_PARAMETERS
"""Names of π's entries, in order (38)."""
UNITS = {
    "mass": "kg",
    "inertia": "kg·m²",
    "rail_friction": "kg",
    "rotor_inertia": "kg·m²",
    "viscous_friction": "N·m·s/rad",
    "coulomb_friction": "N·m",
    "offset": "N·m",
}
"""Unit of each kind of parameter (the name's first part, or its second for a body)."""


def unit(name: str) -> str:
    """The unit of the standard parameter called ``name``."""
    parts = name.split(".")
    return UNITS[parts[1] if parts[0] in BODIES else parts[0]]


def standard_parameters(robot: Robot) -> np.ndarray:
    """π of ``robot`` (:data:`STANDARD_PARAMETERS`), SI; the drives' offsets are 0 (the
    model has none)."""
    bodies = [getattr(robot, name) for name in BODIES]
    inertias = [
        [body.inertia[0, 0], body.inertia[1, 1], body.inertia[2, 2]]
        + [body.inertia[0, 1], body.inertia[0, 2], body.inertia[1, 2]]
        for body in bodies
    ]
    mu = robot.friction.mu
    rails = [
        mu * (robot.upper_platform.mass + robot.payload.mass),
        mu * robot.lower_platform.mass,
    ]
    actuator = robot.actuator
    drive = [
        value
        for viscous, coulomb in zip(
            actuator.viscous_friction_nm_s_rad, actuator.coulomb_friction_nm, strict=True
        )
        for value in (actuator.rotor_inertia_kg_m2, viscous, coulomb, 0.0)
    ]
    return np.array([body.mass for body in bodies] + sum(inertias, []) + rails + drive, dtype=float)


@cache
def link_function() -> ca.Function:
    """(q, q̇, q̈, the model's parameter vector) -> vec(Y) of the bodies' and rails'
    columns (2 × 30, column-major) and τ_payload (2); only the vector's fixed entries
    (lengths, payload, gravity) matter."""
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)
    names = dynamics.PARAMETER_NAMES
    parameters = ca.SX.sym("parameters", len(names))
    at = {name: parameters[k] for k, name in enumerate(names)}
    frictionless, _, friction = dynamics.torque_function()(q, qd, qdd, parameters)
    linear = ca.vertcat(*(at[name] for name in _BODY_PARAMETERS))
    body_columns = ca.jacobian(frictionless, linear)
    masses = [at[f"{body}.mass"] for body in BODIES]

    def with_masses(expression: ca.SX, values: list[float], mu: float) -> ca.SX:
        symbols = ca.vertcat(*masses, at["payload.mass"], at["mu"])
        return ca.substitute(expression, symbols, ca.DM([*values, 0.0, mu]))

    rail_columns = ca.horzcat(
        with_masses(friction, [1.0, 0.0, 0.0, 0.0], 1.0),
        with_masses(friction, [0.0, 1.0, 0.0, 0.0], 1.0),
    )
    inertias = ca.vertcat(*(at[name] for name in _BODY_PARAMETERS[len(BODIES) :]))
    payload = ca.substitute(
        ca.substitute(frictionless, ca.vertcat(*masses), ca.DM.zeros(len(BODIES))),
        inertias,
        ca.DM.zeros(inertias.numel()),
    )
    columns = ca.horzcat(body_columns, rail_columns)
    return ca.Function(
        "link_regressor",
        [q, qd, qdd, parameters],
        [ca.densify(ca.vec(columns)), ca.densify(payload)],
        ["q", "qd", "qdd", "parameters"],
        ["columns", "payload"],
    )


@cache
def _batch() -> BatchFunction | None:
    return compile_batch(link_function())


def regressor(
    robot: Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Y (N, 2, 38) and τ_payload (N, 2), N·m, at joint angles, rates and accelerations
    (N, 2) in rad, rad/s, rad/s², for ``robot``'s lengths, gravity and payload: the
    actuator torques are Y @ π + τ_payload with π = :func:`standard_parameters`."""
    arrays = np.broadcast_arrays(*(np.atleast_2d(np.asarray(a, dtype=float)) for a in (q, qd, qdd)))
    fixed = dynamics.parameter_vector(robot)
    batch = _batch()
    if batch is None:
        columns, payload = (
            value.full().T
            for value in link_function()(*(a.T for a in arrays), np.asarray(fixed)[:, None])
        )
    else:
        columns, payload = batch(*arrays, fixed, shared=(3,))
    n = arrays[0].shape[0]
    links = columns.reshape(n, -1, 2).transpose(0, 2, 1)
    drive = np.zeros((n, 2, len(DRIVE_PARAMETERS)))
    _, qd_, qdd_ = arrays
    for joint in range(2):
        terms = drive_columns(qd_[:, joint], qdd_[:, joint], np.sign(qd_[:, joint]))
        for k, value in enumerate(terms):
            drive[:, joint, DRIVE_TERMS * joint + k] = value
    return np.concatenate([links, drive], axis=2), payload


def drive_columns(qd: Any, qdd: Any, sliding: Any) -> tuple[Any, Any, Any, float]:
    """One joint's drive columns of Y in :data:`DRIVE_PARAMETERS`' order (rotor inertia,
    viscous and Coulomb friction, offset): q̈, q̇, ``sliding`` (sign(q̇), or a smooth
    stand-in) and 1; numpy arrays or CasADi expressions."""
    return qdd, qd, sliding, 1.0
