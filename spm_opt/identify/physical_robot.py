"""The identified robot: the standard parameters closest to the prior's under physical bounds.

The robot file is the estimate of the standard parameters π closest to the problem's robot,
at the η it carries (:func:`spm_opt.identify.estimate.identify`): the weighted rows and, for
each parameter, a row (π_k − prior_k) / s_k
with s_k half the prior's value (or a floor per kind of parameter; the products of inertia
kept): a prior of 50 % uncertainty that settles what the logs leave open, solved under the
physical bounds (masses, diagonal inertias, friction and rotor inertia not negative) with
``scipy.optimize.lsq_linear``, in what a robot file holds: one rotor inertia for both
joints and one rail friction coefficient μ, φ_u = μ (m_u + m_payload) and φ_L = μ m_L.
These are bilinear in μ and the masses, so the linear solve at the prior's masses starts
``scipy.optimize.least_squares`` over all of them at once. Solving again at the last
solution's masses until they settled instead (a fixed point that ignores how the rails'
rows pull on the masses) drifted to m_u = 0 and μ = 0.07 on four of eight emulator logs
of a plant equal to the model (μ 0.24), and that file predicted the torques worse than the
model; the joint solve gave m_u 0.087–0.095 kg (0.0878) and μ 0.16–0.24 on all eight.
Splitting a free fit's two rails into one μ afterwards, the other parameters
fitted to the split they had, made the validation error two to three times larger. The
drives' offsets, which the robot file cannot hold, are in its comments
(:mod:`spm_opt.identify.robot_file`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.optimize

from spm_opt.base.errors import SpmOptError
from spm_opt.model.params import Robot
from spm_opt.model.regressor import (
    BODIES,
    INERTIA_ENTRIES,
    STANDARD_PARAMETERS,
    standard_parameters,
)

PRIOR_SHARE = 0.5
"""The prior's standard deviation as a share of each prior value."""
PRIOR_FLOOR = {
    "mass": 0.05,
    "inertia": 1e-5,
    "rail_friction": 0.01,
    "rotor_inertia": 1e-3,
    "viscous_friction": 0.05,
    "coulomb_friction": 0.05,
    "offset": 0.05,
}
"""The prior's standard deviation where the prior value is small, per kind (SI)."""
PRODUCT_SPREAD = 1e-9
"""The prior's standard deviation of the products of inertia, kg·m²: kept at the prior's
(a few-mm offset of a 0.1 kg body makes ~1e-5 kg·m², far below what current-based torques
resolve)."""
_NOT_NEGATIVE = ("mass", "rail_friction", "rotor_inertia", "viscous_friction", "coulomb_friction")
_UPPER_MASS = STANDARD_PARAMETERS.index("upper_platform.mass")
_LOWER_MASS = STANDARD_PARAMETERS.index("lower_platform.mass")
_RAILS = (
    STANDARD_PARAMETERS.index("rail_friction.upper"),
    STANDARD_PARAMETERS.index("rail_friction.lower"),
)
_ROTOR = (
    STANDARD_PARAMETERS.index("rotor_inertia.theta1"),
    STANDARD_PARAMETERS.index("rotor_inertia.theta2"),
)
INERTIA_ROUND_OFF = 1e-6
"""A body's inertia eigenvalue below 0 by at most this share of its largest is round-off of
the bounded solve (a flat body's smallest is 0), set to 0; further below, an error."""


def standard_estimate(robot: Robot, weighted: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """π (38,) closest to the prior robot's under the physical bounds, in what a robot file
    holds (:func:`_file_basis`; module docstring), from the weighted rows of the standard
    regressor (both joints' rows stacked, each divided by its joint's residual standard
    deviation) and their weighted torques ``rhs``, N·m."""
    prior = standard_parameters(robot)
    spread = _prior_spread(prior)
    a = np.vstack([weighted, np.diag(1.0 / spread)])
    b = np.concatenate([rhs, prior / spread])
    low = _lower_bounds()
    masses = (robot.upper_platform.mass, robot.lower_platform.mass)
    basis, kept = _file_basis(masses, robot.payload.mass)
    start = scipy.optimize.lsq_linear(a @ basis, b, bounds=(low[kept], np.inf)).x
    at = {index: k for k, index in enumerate(kept)}
    upper, lower, mu = at[_UPPER_MASS], at[_LOWER_MASS], at[_RAILS[0]]

    def file_basis(z: np.ndarray) -> np.ndarray:
        return _file_basis((z[upper], z[lower]), robot.payload.mass)[0]

    def jacobian(z: np.ndarray) -> np.ndarray:
        d_standard = file_basis(z)  # π = N(m) z, and the rails' rows μ m also move with m
        d_standard[_RAILS[0], upper] += z[mu]
        d_standard[_RAILS[1], lower] += z[mu]
        return a @ d_standard

    solution = scipy.optimize.least_squares(
        lambda z: a @ (file_basis(z) @ z) - b,
        start,
        jac=jacobian,
        bounds=(low[kept], np.inf),
        x_scale="jac",
    )
    return file_basis(solution.x) @ solution.x


def _prior_spread(prior: np.ndarray) -> np.ndarray:
    """The prior's standard deviation s_k of each standard parameter (38,), SI."""
    return np.array(
        [
            PRODUCT_SPREAD
            if _product_of_inertia(name)
            else max(PRIOR_SHARE * abs(value), PRIOR_FLOOR[_kind(name)])
            for name, value in zip(STANDARD_PARAMETERS, prior, strict=True)
        ]
    )


def _lower_bounds() -> np.ndarray:
    """The physical lower bound of each standard parameter (38,): 0 for masses, diagonal
    inertias, friction and rotor inertia, −inf for the others."""
    return np.array(
        [
            0.0 if _kind(n) in _NOT_NEGATIVE or _diagonal_inertia(n) else -np.inf
            for n in STANDARD_PARAMETERS
        ]
    )


def _kind(name: str) -> str:
    parts = name.split(".")
    return parts[1] if parts[0] in BODIES else parts[0]


def _file_basis(masses: tuple[float, float], payload_kg: float) -> tuple[np.ndarray, np.ndarray]:
    """N (38, 36), π = N z, and the indices of π that z keeps: what a robot file holds,
    one rotor inertia for both joints and the rails' friction from one μ (φ_u = μ (m_u +
    m_payload), φ_L = μ m_L at the platforms' ``masses`` m_u, m_L, kg), z's entries of
    those μ and J, the others π's."""
    basis = np.eye(len(STANDARD_PARAMETERS))
    basis[_ROTOR[1], _ROTOR[0]] = 1.0
    basis[_RAILS[0], _RAILS[0]] = masses[0] + payload_kg
    basis[_RAILS[1], _RAILS[0]] = masses[1]
    kept = np.delete(np.arange(len(STANDARD_PARAMETERS)), [_ROTOR[1], _RAILS[1]])
    return basis[:, kept], kept


def _diagonal_inertia(name: str) -> bool:
    return _kind(name) == "inertia" and name.split(".")[-1] in ("xx", "yy", "zz")


def _product_of_inertia(name: str) -> bool:
    return _kind(name) == "inertia" and not _diagonal_inertia(name)


def robot_with_parameters(robot: Robot, standard: np.ndarray, efficiency: float) -> Robot:
    """``robot`` with the standard parameters π (masses, inertias, μ from the rails'
    friction, the rotor inertia as the mean of the joints', each joint's viscous friction)
    and the gear efficiency η; an error if an inertia tensor is not physical."""
    at = dict(zip(STANDARD_PARAMETERS, standard, strict=True))
    bodies = {
        body: dataclasses.replace(
            getattr(robot, body), mass=at[f"{body}.mass"], inertia=_physical_inertia(body, at)
        )
        for body in BODIES
    }
    masses = at["upper_platform.mass"] + robot.payload.mass + at["lower_platform.mass"]
    rails = at["rail_friction.upper"] + at["rail_friction.lower"]
    friction = dataclasses.replace(robot.friction, mu=rails / masses if masses > 0 else 0.0)
    actuator = dataclasses.replace(
        robot.actuator,
        rotor_inertia_kg_m2=0.5 * (at["rotor_inertia.theta1"] + at["rotor_inertia.theta2"]),
        viscous_friction_nm_s_rad=(at["viscous_friction.theta1"], at["viscous_friction.theta2"]),
        coulomb_friction_nm=(at["coulomb_friction.theta1"], at["coulomb_friction.theta2"]),
        gear_efficiency=efficiency,
    )
    return dataclasses.replace(robot, **bodies, friction=friction, actuator=actuator)


def _physical_inertia(body: str, at: dict[str, float]) -> np.ndarray:
    """The inertia tensor (3, 3), kg·m², of ``body`` from the standard parameters by name
    ``at``, its round-off below 0 set to 0; an error if it is not positive semi-definite."""
    xx, yy, zz, xy, xz, yz = (at[f"{body}.inertia.{ij}"] for ij in INERTIA_ENTRIES)
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    values, vectors = np.linalg.eigh(inertia)
    if np.min(values) < -INERTIA_ROUND_OFF * max(np.max(np.abs(values)), 1e-300):
        raise SpmOptError(
            f"identification: the inertia of {body} comes out not positive semi-definite "
            f"(eigenvalues {values}); the logs do not determine it"
        )
    return (vectors * np.maximum(values, 0.0)) @ vectors.T  # round-off below 0 → 0
