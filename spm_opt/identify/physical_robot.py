"""Standard parameters fitted under physical constraints: the base parameters' physically
consistent estimate, and the identified robot.

Physical consistency (Wensing, Kim and Slotine, RA-L 2017; Sousa and Cortesão, IJRR 2014):
each body's mass at least :data:`MASS_FLOOR` of the prior's (a mass > 0); its inertia about
its mass centre I_c positive definite with its principal moments obeying the triangle
inequalities, which is Σ_c = ½ tr(I_c)·1 − I_c positive definite (the pseudo-inertia's
second moment with the mass centre fixed, as the model fixes it: Rucker and Wensing,
RA-L 2022), asked as Σ_c − δ·1 positive semidefinite, δ :data:`PD_MARGIN` of the prior's
largest moment: its seven principal minors ≥ 0 (CasADi has no semidefinite solver; the
minors are smooth constraints IPOPT takes, and a body whose minors bind has a triangle
inequality holding with equality); friction and rotor inertia ≥ 0. :func:`physical_fit`
minimises the weighted torques' misfit plus a Gaussian prior on π under these constraints
with CasADi + IPOPT, and says which constraints hold the solution back. (Two other forms
were tried on synthetic torques: Σ_c − δ·1 = L Lᵀ as equality constraints left IPOPT's
restoration phase failing with 1e-4 N·m of noise, and π's inertias as functions of a
Cholesky or L D Lᵀ factor with bounds alone crawled for thousands of iterations on a 32 s
log; the minors converged in 30 to 80.)

:func:`~spm_opt.identify.estimate.identify` calls it twice. With a negligible prior
(:data:`~spm_opt.identify.estimate.PRIOR_WEIGHT`), its π gives the base parameters'
physically consistent estimate β = K π; what the torques leave open (the standard
parameters no motion shows, the splits of a combination) the prior settles. For the robot
file (:func:`standard_estimate`), with the prior at its weight 1 and a standard deviation of
:data:`PRIOR_SHARE` of each prior value (or a floor per kind of parameter), the products of
inertia held at the prior's (a few-mm offset of a 0.1 kg body makes ~1e-5 kg·m², far below
what current-based torques resolve), in what a robot file holds: one rotor inertia for both
joints and one rail friction coefficient μ, φ_u = μ (m_u + m_payload) and φ_L = μ m_L,
bilinear in μ and the masses, all solved at once. (With the earlier scipy solve, fixing the
masses and solving again until they settled drifted to m_u = 0 and μ = 0.07 on four of eight
emulator logs of a plant equal to the model, whose μ is 0.24; solving for the masses and μ
together gave m_u 0.087–0.095 kg, 0.0878 in the model, and μ 0.16–0.24 on all eight.) The
drives' offsets, which the robot file cannot hold, are in its comments
(:mod:`spm_opt.identify.robot_file`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import casadi as ca
import numpy as np

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
_NOT_NEGATIVE = ("mass", "rail_friction", "rotor_inertia", "viscous_friction", "coulomb_friction")
MASS_FLOOR = 1e-3
"""A body's mass is at least this share of the prior's (masses > 0)."""
PD_MARGIN = 1e-6
"""Σ_c − δ·1 is positive semidefinite with δ this share of the prior body's largest principal
moment: its inertia positive definite, the triangle inequalities strict. The prototype's
upper arc, nearly flat, has Σ_c's smallest eigenvalue 1.7e-5 of its largest moment."""
MINOR_TOLERANCE = 1e-9
"""A body's principal minor (in units of its prior's largest moment) below 0 by at most this
is the interior point's round-off; further below, the fit failed."""
RANK_TOLERANCE = 1e-10
"""Singular values of the weighted rows below this share of the largest are round-off."""
INERTIA_SCALE_FLOOR = 1e-9
"""The scale of a body's inertia (kg·m²) where the prior's is smaller."""
ACTIVE_MULTIPLIER = 1e-2
"""A bound holds the solution back when its multiplier is above this: relaxing it by one
prior standard deviation (a body's minors by one unit) would lower the objective, in
squared weighted residuals, by that much (a bound that does not bind has only the interior
point's barrier multiplier, μ / distance)."""
MU_LIMIT = 2.0
"""The largest rail friction coefficient a robot file holds
(:func:`~spm_opt.model.params.load_robot`)."""
_MU_SPREAD = 0.05
"""The scale of the rails' friction coefficient μ in the robot file's fit (1)."""
_TRIANGLE_WORDS = "inertia's principal moments on a triangle inequality (I_c > 0)"
_IPOPT = {
    "print_level": 0,
    "sb": "yes",
    "tol": 1e-9,
    "acceptable_tol": 1e-5,
    "acceptable_iter": 5,
    "max_iter": 1000,
    "bound_relax_factor": 0.0,
}
"""IPOPT's settings: bounds kept exactly; five iterations in a row within 1e-5 suffice (a
synthetic log's fit converged to 6e-6 and then stalled in its line search, and IPOPT's
restoration phase left it worse)."""
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
the constrained solve, set to 0; further below, an error."""


@dataclass(frozen=True)
class PhysicalFit:
    """Standard parameters fitted under the physical constraints.

    Attributes
    ----------
    standard : ndarray, shape (38,)
        π (:data:`STANDARD_PARAMETERS`), SI.
    active : list of str
        The constraints that hold π back at the solution, in words (e.g.
        ``viscous_friction.theta1 >= 0``, ``upper_arc: inertia's triangle inequality``).
    stopped : str
        "" when IPOPT converged; otherwise why it stopped (π is physical, checked, if perhaps
        not the closest fit).
    """

    standard: np.ndarray
    active: list[str]
    stopped: str


def physical_fit(
    robot: Robot,
    weighted: np.ndarray,
    rhs: np.ndarray,
    spread: np.ndarray,
    prior_weight: float,
    file_structure: bool,
) -> PhysicalFit:
    """π (38,) minimising ‖weighted π − rhs‖² + w ‖(π − prior) / spread‖² under the physical
    constraints (module docstring) by CasADi + IPOPT: ``weighted`` the rows of the
    standard regressor (both joints' rows, each divided by its joint's residual standard
    deviation), ``rhs`` their weighted torques, N·m, ``spread`` the prior's standard
    deviation of each parameter (38,), SI, w ``prior_weight``; with ``file_structure``, in
    what a robot file holds (one rotor inertia, one rail friction coefficient μ)."""
    prior = standard_parameters(robot)
    # the misfit as ‖F (π − π_ls)‖² about a least-squares solution π_ls, F from the
    # weighted rows' singular values above round-off: a sum of squares, never below 0
    _, singular, right = np.linalg.svd(weighted, full_matrices=False)
    kept = singular > RANK_TOLERANCE * singular[0]
    factor_rows = singular[kept, None] * right[kept]
    solution_ls = np.linalg.lstsq(weighted, rhs, rcond=None)[0]
    x = ca.SX.sym("x", len(prior))  # π = prior + spread x (μ in the upper rail's slot)
    free = prior + spread * x
    entries = [free[k] for k in range(len(prior))]
    low = (_lower_bounds(prior) - prior) / spread
    high = np.full(len(prior), np.inf)
    if file_structure:
        mu = robot.friction.mu + _MU_SPREAD * x[_RAILS[0]]
        low[_RAILS[0]] = -robot.friction.mu / _MU_SPREAD
        high[_RAILS[0]] = (MU_LIMIT - robot.friction.mu) / _MU_SPREAD
        entries[_RAILS[0]] = mu * (free[_UPPER_MASS] + robot.payload.mass)
        entries[_RAILS[1]] = mu * free[_LOWER_MASS]
        entries[_ROTOR[1]] = free[_ROTOR[0]]
        held = [k for k, name in enumerate(STANDARD_PARAMETERS) if _product_of_inertia(name)]
        for tied in (_RAILS[1], _ROTOR[1], *held):  # the products of inertia the prior's
            low[tied] = high[tied] = 0.0
    standard = ca.vertcat(*entries)
    deviation = (standard - prior) / spread
    offset = standard - solution_ls
    misfit = ca.mtimes(ca.DM(factor_rows), offset)
    objective = ca.dot(misfit, misfit) + prior_weight * ca.dot(deviation, deviation)
    minors = ca.vertcat(*(_minors(body, standard, prior) for body in BODIES))
    solver = ca.nlpsol(
        "physical_fit",
        "ipopt",
        {"x": x, "f": objective, "g": minors},
        {"ipopt": _IPOPT, "print_time": False},
    )
    result = solver(x0=np.zeros(len(prior)), lbx=low, ubx=high, lbg=0.0, ubg=np.inf)
    values = np.asarray(result["x"]).ravel()
    stats = solver.stats()
    if not np.all(np.isfinite(values)):
        raise SpmOptError(
            f"identification: the physically constrained fit failed ({stats['return_status']})"
        )
    stopped = (
        ""
        if stats["success"]
        else f"IPOPT stopped ({stats['return_status']}, {stats['iter_count']} iterations)"
    )
    if float(np.min(np.asarray(result["g"]))) < -MINOR_TOLERANCE:
        raise SpmOptError(
            "identification: the physically constrained fit ended outside the constraints "
            f"({stats['return_status']}); the logs may not excite the robot"
        )
    multipliers = np.asarray(result["lam_x"]).ravel()
    free_slots = low < high  # a variable fixed at the prior's has its gradient as multiplier
    at_bound = free_slots & (-multipliers > ACTIVE_MULTIPLIER)
    at_top = free_slots & (multipliers > ACTIVE_MULTIPLIER)
    values[at_bound] = low[at_bound]  # the interior point stops just short of the bound
    values[at_top] = high[at_top]
    fitted = np.asarray(ca.Function("pi", [x], [standard])(values)).ravel()
    bodies_held = np.any(
        (-np.asarray(result["lam_g"]).ravel() > ACTIVE_MULTIPLIER).reshape(len(BODIES), -1), axis=1
    )
    names = _bound_names(file_structure)
    active = [names[k] for k in np.flatnonzero(at_bound) if names[k]]
    active += [
        f"friction.mu <= {MU_LIMIT:g} (a robot file's limit)" for _ in np.flatnonzero(at_top)
    ]
    active += [
        f"{body}: {_TRIANGLE_WORDS}" for body, on in zip(BODIES, bodies_held, strict=True) if on
    ]
    return PhysicalFit(fitted, active, stopped)


def standard_estimate(robot: Robot, weighted: np.ndarray, rhs: np.ndarray) -> PhysicalFit:
    """The robot file's π (38,): the fit closest to the prior robot's under the physical
    constraints, in what a robot file holds (:func:`physical_fit` with a prior of
    :data:`PRIOR_SHARE`; module docstring), from the weighted rows of the standard regressor
    and their weighted torques ``rhs``, N·m."""
    spread = prior_spread(standard_parameters(robot))
    return physical_fit(robot, weighted, rhs, spread, 1.0, file_structure=True)


def _minors(body: str, standard: ca.SX, prior: np.ndarray) -> ca.SX:
    """The 7 principal minors of ``body``'s (Σ_c − δ·1) / c, all ≥ 0 exactly where it is
    positive semidefinite: Σ_c = ½ tr(I_c)·1 − I_c positive definite, I_c's principal moments
    obeying the triangle inequalities (c the prior's largest principal moment, δ
    :data:`PD_MARGIN` of it; I_c from π, ``standard``)."""

    def tensor(values: ca.SX | np.ndarray) -> ca.SX:
        xx, yy, zz, xy, xz, yz = (
            values[STANDARD_PARAMETERS.index(f"{body}.inertia.{ij}")] for ij in INERTIA_ENTRIES
        )
        return ca.blockcat([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])

    prior_moments = np.linalg.eigvalsh(np.array(ca.DM(tensor(prior))))
    scale = max(float(np.max(np.abs(prior_moments))), INERTIA_SCALE_FLOOR)
    inertia = tensor(standard)
    m = (0.5 * ca.trace(inertia) * ca.DM.eye(3) - inertia) / scale - PD_MARGIN * ca.DM.eye(3)
    return ca.vertcat(
        m[0, 0],
        m[1, 1],
        m[2, 2],
        m[0, 0] * m[1, 1] - m[0, 1] ** 2,
        m[0, 0] * m[2, 2] - m[0, 2] ** 2,
        m[1, 1] * m[2, 2] - m[1, 2] ** 2,
        ca.det(m),
    )


def _bound_names(file_structure: bool) -> list[str]:
    """The constraint each entry of x's lower bound stands for, in words ("" for none)."""
    names = []
    for k, name in enumerate(STANDARD_PARAMETERS):
        bounded = _kind(name) in _NOT_NEGATIVE
        if file_structure and k == _RAILS[0]:
            names.append("friction.mu >= 0")
        elif file_structure and k in (_RAILS[1], _ROTOR[1]):
            names.append("")
        elif bounded:
            names.append(f"{name} {'> 0' if _kind(name) == 'mass' else '>= 0'}")
        else:
            names.append("")
    return names


def prior_spread(prior: np.ndarray) -> np.ndarray:
    """The prior's standard deviation s_k of each standard parameter (38,), SI:
    :data:`PRIOR_SHARE` of its value or :data:`PRIOR_FLOOR` of its kind."""
    return np.array(
        [
            max(PRIOR_SHARE * abs(value), PRIOR_FLOOR[_kind(name)])
            for name, value in zip(STANDARD_PARAMETERS, prior, strict=True)
        ]
    )


def _lower_bounds(prior: np.ndarray) -> np.ndarray:
    """The lower bound of each standard parameter (38,): :data:`MASS_FLOOR` of the prior's
    for masses, 0 for friction and rotor inertia, −inf for the others (the inertias are
    bounded by their triangle inequalities)."""
    return np.array(
        [
            MASS_FLOOR * value
            if _kind(name) == "mass"
            else (0.0 if _kind(name) in _NOT_NEGATIVE else -np.inf)
            for name, value in zip(STANDARD_PARAMETERS, prior, strict=True)
        ]
    )


def not_negative(name: str) -> bool:
    """Whether the physical constraints keep the standard parameter ``name`` ≥ 0: a mass,
    friction, a rotor inertia or a diagonal entry of an inertia (positive definite)."""
    return _kind(name) in _NOT_NEGATIVE or _diagonal_inertia(name)


def _kind(name: str) -> str:
    parts = name.split(".")
    return parts[1] if parts[0] in BODIES else parts[0]


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
