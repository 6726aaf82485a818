"""The robot's dynamic parameters and gear efficiency identified from execution logs.

    spm-opt identify LOG.csv [LOG.csv ...] --problem P.toml --out identified.toml
                     [--validate LOG.csv] [--cutoff-hz 2] [--decimation N] [--min-speed 0.02]

The robot file it writes also carries each actuator's position and velocity loop, which
:mod:`spm_opt.identify_loop` estimates from the logs' goals and positions.

The logs' samples (:mod:`spm_opt.identify_samples`) give τ_j − τ_payload = Y_b(q, q̇, q̈) β,
the base parameters of the problem's robot (:mod:`spm_opt.model.base_parameters`), both
sides through the same low-pass filter (parallel filtering). τ_j is the torque at the
joints; the actuators measure the motor's, τ_m, and through a gear train of efficiency η,
τ_j = η τ_m where the motor drives its load and τ_m / η where the load drives it back
(:meth:`~spm_opt.model.actuator.Actuator.drive_torque`). Which of the two, the model
decides: where the joint torque of a fit with η = 1 has the rate's sign (the measured
torque's own sign is noise near zero, and smears a joint's Coulomb step at a reversal).

For a given η the estimate is weighted least squares: ordinary least squares first, then
each joint's rows divided by its residual standard deviation and solved again. η is the one
in [0.5, 1] whose β predicts the motor torques best: the sum of the squared residuals
τ_m − (Y_b β + τ_payload) / (τ_j / τ_m), filtered, each joint's divided by its residual
standard deviation at η = 1 (``scipy.optimize.minimize_scalar``, bounded); measured in
the joints' torques, the misfit would shrink with η along with the torques themselves.
Standard errors: η's from the curvature of that misfit, 2 σ² / misfit''; β's
σ² (W̃ᵀW̃)⁻¹ from the weighted residuals, and η's through dβ/dη. Every variance is
multiplied by the residuals' correlation factor (neighbouring filtered rows are
correlated, :func:`~spm_opt.identify_samples.correlation_factor`: 2.0 to 2.5 measured);
without it the standard errors came out 1.4 to 1.5 times smaller than the estimates'
scatter over repeated logs.

A base parameter counts as identified when its 95 % interval, two standard errors, lies
within 10 % of its value: each such estimate is within 10 % of the truth in 19 of 20 logs.
(With the usual rule, one standard error within 10 %, three of six simulated logs had an
identified parameter beyond 10 % of the truth, though within 2.3 of its standard errors:
the errors are honest, the rule too loose for its 10 %.) η counts as identified when its
two standard errors lie within 10 % of the loss 1 − η, which is what the torques show: 10 %
of η itself (±0.09) would call identified a gear train the logs cannot tell from a lossless
one. The robot
file carries the estimated η when the loss is at least :data:`LOSS_SIGNIFICANCE` standard
errors, identified or not, as it carries every base parameter's estimate; below, and where
the load never drives a motor back (the loss then only scales β), it keeps η = 1 and the
losses show as friction. The condition number is that of W̃ with its columns scaled to
unit norm.

The robot file is the estimate of the standard parameters π closest to the problem's robot,
at the η it carries: the weighted rows and, for each parameter, a row (π_k − prior_k) / s_k
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
drives' offsets, which the robot file cannot hold, are in its comments.

Measured on the simulated robot whose plant is ``prototype_plant.toml`` (a 120 s
excitation and a 30 s validation run at 500 Hz, ``tests/test_identify.py``, goals equal
to the plan: before the executor led them): η = 0.873 ±
0.016 against the plant's 0.85; the two base parameters identified, the joints' viscous
friction, 0.294 ± 0.007 and 0.299 ± 0.006 N·m·s/rad against 0.3 (with η held at 1: 0.330
and 0.341); the validation torques' RMS prediction error falls from 0.040 and 0.039 N·m
(the prior, ``prototype.toml``) to 0.0073 and 0.0057 (the plant's own model: 0.0075 and
0.0059; η held at 1: 0.0085 and 0.0082). Over eleven such excitations η comes out 0.863 on
average, scattered by 0.015, and the viscous friction 3 to 4 % low: a bias that the model's
own torques do not show (from them, η = 0.8 comes out within 0.001, ± 0.002). With the
goals led (the executor's default), η comes out 0.872 on average over the same eleven,
scattered by 0.016: the standard errors understate the scatter (3 of 11 beyond two).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from matplotlib.figure import Figure

from spm_opt.errors import InputError, SpmOptError
from spm_opt.identify_loop import LoopEstimate
from spm_opt.identify_samples import Samples, correlation_factor
from spm_opt.model import dynamics
from spm_opt.model.base_parameters import SAMPLES, base_parameters, random_states
from spm_opt.model.params import Robot, robot_toml
from spm_opt.model.regressor import (
    BODIES,
    INERTIA_ENTRIES,
    STANDARD_PARAMETERS,
    regressor,
    standard_parameters,
    unit,
)
from spm_opt.report.markdown import markdown_table

IDENTIFIED_RELATIVE_ERROR = 0.1
"""A base parameter is identified when :data:`IDENTIFIED_SIGMAS` standard errors are at
most this share of it."""
IDENTIFIED_SIGMAS = 2.0
"""Standard errors that must fit within :data:`IDENTIFIED_RELATIVE_ERROR` of a value (a
95 % interval)."""
MAX_CONDITION = 1e6
"""Above this condition number the logs do not determine the base parameters at all."""
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
EFFICIENCY_BOUNDS = (0.5, 1.0)
"""The gear efficiencies η searched."""
EFFICIENCY_STEP = 0.01
"""Step in η of the finite differences of the motor-torque misfit (its curvature) and of
the estimate (its slope)."""
LOSS_SIGNIFICANCE = 2.0
"""The robot file carries the estimated η when the loss 1 − η is at least this many
standard errors; below, the logs do not tell its gear train from a lossless one and it
keeps η = 1."""
INERTIA_ROUND_OFF = 1e-6
"""A body's inertia eigenvalue below 0 by at most this share of its largest is round-off of
the bounded solve (a flat body's smallest is 0), set to 0; further below, an error."""
TRUTH_RESIDUAL = 1e-9
"""Largest residual, relative to the largest torque, of a plant's torques in a prior's base
parameters (:func:`true_base_parameters`): above it the two robots differ in structure."""


@dataclass(frozen=True)
class Identification:
    """What the logs determine, and the robot they give.

    Attributes
    ----------
    names : list of str
        Each base parameter as its combination of standard parameters.
    units : list of str
    prior, estimate, standard_error : ndarray, shape (r,)
        β of the problem's robot, β from weighted least squares and its standard errors.
    identified : ndarray of bool, shape (r,)
    efficiency_prior, efficiency, efficiency_error : float
        The gear efficiency η of the problem's robot, η from the logs and its standard
        error (:func:`identify`).
    efficiency_identified : bool
        Whether two standard errors are at most 10 % of the loss 1 − η.
    efficiency_significant : bool
        Whether the loss is at least :data:`LOSS_SIGNIFICANCE` standard errors: the robot's
        η is the estimate, otherwise 1.
    correlation_factor : float
        How much the residuals' correlation inflates the variances (every standard error
        holds its square root).
    condition_number : float
    residual_std_nm : ndarray, shape (2,)
        Each joint's residual standard deviation (ordinary least squares, joint side),
        N·m.
    samples : int
        Samples used (after filtering, decimation and leaving out the slow ones).
    duration_s : float
        Seconds of log.
    unseen : list of str
        The standard parameters no motion shows (their regressor columns are zero).
    standard : ndarray, shape (38,)
        The robot file's standard parameters (:data:`STANDARD_PARAMETERS`).
    robot : Robot
        The identified robot, its actuator loops the prior's (:func:`robot_file_text`
        writes them as :mod:`spm_opt.identify_loop` estimates them).
    """

    names: list[str]
    units: list[str]
    prior: np.ndarray
    estimate: np.ndarray
    standard_error: np.ndarray
    identified: np.ndarray
    efficiency_prior: float
    efficiency: float
    efficiency_error: float
    efficiency_identified: bool
    efficiency_significant: bool
    correlation_factor: float
    condition_number: float
    residual_std_nm: np.ndarray
    samples: int
    duration_s: float
    unseen: list[str]
    standard: np.ndarray
    robot: Robot

    def base_rows(self) -> list[tuple[str, str, float, float, float, bool]]:
        """Per base parameter: name, unit, prior, estimate, standard error, identified."""
        return list(
            zip(
                self.names,
                self.units,
                self.prior,
                self.estimate,
                self.standard_error,
                self.identified,
                strict=True,
            )
        )

    def seconds_for_identification(self) -> np.ndarray:
        """Per base parameter, the seconds of such a log its two standard errors would need
        to fall to 10 % of it (standard errors fall as 1/√length); inf where the estimate
        is 0."""
        return _seconds(self.duration_s, self.standard_error, self.estimate)

    def efficiency_row(self) -> tuple[str, str, float, float, float, bool]:
        """The gear efficiency as :meth:`base_rows` gives a base parameter."""
        return (
            "gear_efficiency (identified on the loss 1 − η)",
            "1",
            self.efficiency_prior,
            self.efficiency,
            self.efficiency_error,
            self.efficiency_identified,
        )

    def seconds_for_efficiency(self) -> float:
        """The seconds of such a log the efficiency's two standard errors would need to fall
        to 10 % of the loss 1 − η; inf where η is 1."""
        loss = np.array([1.0 - self.efficiency])
        return float(_seconds(self.duration_s, np.array([self.efficiency_error]), loss)[0])


def _seconds(duration_s: float, errors: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The seconds of log for two errors ∝ 1/√length to fall to 10 % of the values (same
    shape); inf where a value is 0."""
    relative = np.divide(
        IDENTIFIED_SIGMAS * errors,
        IDENTIFIED_RELATIVE_ERROR * np.abs(values),
        out=np.full(errors.shape, np.inf),
        where=values != 0.0,
    )
    return duration_s * relative**2


def joint_torque(motor_nm: np.ndarray, driving: np.ndarray, efficiency: float) -> np.ndarray:
    """Joint-side torques τ_j, N·m, of motor torques τ_m (same shape): η τ_m where the
    motor drives its load (``driving``), τ_m / η where the load drives it back
    (:meth:`~spm_opt.model.actuator.Actuator.drive_torque` inverted)."""
    return motor_nm * _gear_share(driving, efficiency)


def _gear_share(driving: np.ndarray, efficiency: float) -> np.ndarray:
    """τ_j / τ_m: η where the motor drives, 1 / η where it is driven back."""
    return np.where(driving, efficiency, 1.0 / efficiency)


@dataclass(frozen=True)
class _Profile:
    """The weighted least squares at a given gear efficiency η and its misfit in motor
    torque.

    Attributes
    ----------
    samples : Samples
    columns : ndarray, shape (M, 2, r)
        Y_b through the parallel filter.
    raw_columns : ndarray, shape (N, 2, r)
        Y_b at the samples.
    payload : ndarray, shape (N, 2)
        τ_payload at the samples, N·m.
    weights : ndarray, shape (2,)
        Each joint's residual standard deviation at η = 1 (motor side), N·m.
    driving : ndarray of bool, shape (N, 2)
        Where each motor drives its load (:func:`_driving`).
    """

    samples: Samples
    columns: np.ndarray
    raw_columns: np.ndarray
    payload: np.ndarray
    weights: np.ndarray
    driving: np.ndarray

    def target(self, efficiency: float) -> np.ndarray:
        """τ_j − τ_payload at η through the parallel filter (M, 2), N·m."""
        joint = joint_torque(self.samples.torque, self.driving, efficiency)
        return self.samples.parallel(joint - self.payload)

    def fit(self, efficiency: float) -> np.ndarray:
        """β (r,) by weighted least squares at η."""
        target = self.target(efficiency)
        weighted, rhs = _stacked(self.columns, target, _residual_std(self.columns, target))
        return np.linalg.lstsq(weighted, rhs, rcond=None)[0]

    def residual(self, efficiency: float) -> np.ndarray:
        """The motor torques' residuals at η, τ_m − (Y_b β + τ_payload) / (τ_j / τ_m),
        through the parallel filter and divided by the weights (M, 2)."""
        joint = self.raw_columns @ self.fit(efficiency) + self.payload
        motor = joint / _gear_share(self.driving, efficiency)
        return self.samples.parallel(self.samples.torque - motor) / self.weights

    def misfit(self, efficiency: float) -> float:
        """Σ of the squared :meth:`residual` at η."""
        return float(np.sum(self.residual(efficiency) ** 2))


@dataclass(frozen=True)
class _Efficiency:
    """The gear efficiency the motor-torque misfit gives.

    Attributes
    ----------
    estimate, error : float
        η and its standard error.
    slope : ndarray, shape (r,)
        dβ/dη of the weighted least squares.
    correlation : float
        :func:`~spm_opt.identify_samples.correlation_factor` of the residuals at η.
    """

    estimate: float
    error: float
    slope: np.ndarray
    correlation: float

    @property
    def identified(self) -> bool:
        """Whether two errors are at most 10 % of the loss 1 − η."""
        return IDENTIFIED_SIGMAS * self.error <= IDENTIFIED_RELATIVE_ERROR * (1.0 - self.estimate)

    @property
    def significant(self) -> bool:
        """Whether the loss is at least :data:`LOSS_SIGNIFICANCE` errors, η off the
        search's lower bound."""
        off_bound = self.estimate > EFFICIENCY_BOUNDS[0] + EFFICIENCY_STEP
        return off_bound and 1.0 - self.estimate >= LOSS_SIGNIFICANCE * self.error


def _efficiency(profile: _Profile, dof: int, lags: int) -> _Efficiency:
    """η minimising the misfit; its error from the misfit's curvature, 2 κ σ² / misfit''
    with σ² = misfit / ``dof`` and κ the residuals' correlation factor over ``lags``
    rows; dβ/dη by central differences."""
    eta = scipy.optimize.minimize_scalar(
        profile.misfit, bounds=EFFICIENCY_BOUNDS, method="bounded", options={"xatol": 1e-4}
    ).x
    h = EFFICIENCY_STEP
    residual = profile.residual(eta)
    below, at, above = profile.misfit(eta - h), float(np.sum(residual**2)), profile.misfit(eta + h)
    curvature = (below - 2.0 * at + above) / h**2
    correlation = correlation_factor(residual, lags)
    variance = 2.0 * correlation * at / dof / curvature if curvature > 0.0 else np.inf
    slope = (profile.fit(eta + h) - profile.fit(eta - h)) / (2.0 * h)
    return _Efficiency(float(eta), float(np.sqrt(variance)), slope, correlation)


def _driving(
    columns: np.ndarray,
    raw_columns: np.ndarray,
    payload: np.ndarray,
    samples: Samples,
    weights_std: np.ndarray,
) -> np.ndarray:
    """(N, 2) bool: where each motor drives its load, as the model decides it
    (:meth:`~spm_opt.model.actuator.Actuator.drive_torque`): the joint torque of the
    lossless fit, Y_b β + τ_payload, times the rate positive. Not the measured torque's
    sign: its noise and a joint's Coulomb step at reversals would mislabel samples."""
    target = samples.parallel(samples.torque - payload)
    weighted, rhs = _stacked(columns, target, weights_std)
    lossless = np.linalg.lstsq(weighted, rhs, rcond=None)[0]
    return (raw_columns @ lossless + payload) * samples.qd > 0.0


def identify(robot: Robot, samples: Samples) -> Identification:
    """Identify ``robot``'s parameters (the prior) and the gear efficiency from filtered
    log samples (module docstring)."""
    base = base_parameters(robot)
    y, payload = regressor(robot, samples.q, samples.qd, samples.qdd)
    filtered = samples.parallel(y)
    columns = base.columns(filtered)
    if len(columns) < 10 * base.rank:
        raise InputError(
            f"logs: {len(columns)} moving samples after filtering, at least "
            f"{10 * base.rank} needed for {base.rank} base parameters; log a longer motion "
            "that keeps both joints turning"
        )
    weights = _residual_std(columns, samples.parallel(samples.torque - payload))
    condition = _condition(columns, weights)
    if not condition < MAX_CONDITION:
        raise InputError(
            f"logs: the motion does not excite the robot's base parameters (condition "
            f"number {condition:.3g}); log a motion that swings both joints back and forth "
            "at several speeds"
        )
    raw_columns = base.columns(y)
    driving = _driving(columns, raw_columns, payload, samples, weights)
    profile = _Profile(samples, columns, raw_columns, payload, weights, driving)
    dof = max(2 * len(columns) - base.rank - 1, 1)
    efficiency = _efficiency(profile, dof, samples.rows_per_period)
    used = efficiency.estimate if efficiency.significant else 1.0
    target = profile.target(used)
    residual_std = _residual_std(columns, target)
    weighted, rhs = _stacked(columns, target, residual_std)
    estimate, *_ = np.linalg.lstsq(weighted, rhs, rcond=None)
    variance = float(np.sum((rhs - weighted @ estimate) ** 2) / max(len(rhs) - base.rank, 1))
    covariance = efficiency.correlation * variance * np.linalg.inv(weighted.T @ weighted)
    errors = np.sqrt(np.diag(covariance))
    if efficiency.significant:  # β's errors at a given η, and η's through dβ/dη
        errors = np.hypot(errors, efficiency.slope * efficiency.error)
    standard = _standard_estimate(robot, filtered, target, residual_std)
    return Identification(
        names=base.names(),
        units=[unit(STANDARD_PARAMETERS[k]) for k in base.independent],
        prior=base.values(standard_parameters(robot)),
        estimate=estimate,
        standard_error=errors,
        identified=IDENTIFIED_SIGMAS * errors <= IDENTIFIED_RELATIVE_ERROR * np.abs(estimate),
        efficiency_prior=robot.actuator.gear_efficiency,
        efficiency=efficiency.estimate,
        efficiency_error=efficiency.error,
        efficiency_identified=efficiency.identified,
        efficiency_significant=efficiency.significant,
        correlation_factor=efficiency.correlation,
        condition_number=condition,
        residual_std_nm=residual_std,
        samples=len(target),
        duration_s=samples.duration_s,
        unseen=[STANDARD_PARAMETERS[k] for k in base.unseen],
        standard=standard,
        robot=robot_with_parameters(robot, standard, used),
    )


def _condition(columns: np.ndarray, weights_std: np.ndarray) -> float:
    """The condition number of the weighted rows with their columns scaled to unit norm."""
    stacked, _ = _stacked(columns, np.zeros(columns.shape[:2]), weights_std)
    norms = np.linalg.norm(stacked, axis=0)
    return float(np.linalg.cond(stacked / np.where(norms > 0, norms, 1.0)))


def true_base_parameters(prior: Robot, plant: Robot) -> np.ndarray:
    """β (r,) of ``plant`` in ``prior``'s base parameters: least squares of the prior's
    base columns against the plant's torques at the joints (its model torques with a
    lossless gear train, less the prior's payload torque, as :func:`identify` fits) over
    random states. The robots may differ in lengths, payload and gravity (measured: a mass
    centre's or a rail's radius, the payload's mass, gravity leave the torques linear in the
    prior's base parameters); an error if they leave a residual above round-off."""
    base = base_parameters(prior)
    q, qd, qdd = random_states(prior, SAMPLES, seed=1)
    y, payload = regressor(prior, q, qd, qdd)
    actuator = dataclasses.replace(plant.actuator, gear_efficiency=1.0)
    torque = dynamics.actuator_torque(dataclasses.replace(plant, actuator=actuator), q, qd, qdd)
    a, b = base.columns(y).reshape(-1, base.rank), (torque - payload).reshape(-1)
    beta, *_ = np.linalg.lstsq(a, b, rcond=None)
    residual = float(np.max(np.abs(a @ beta - b)))
    if residual > TRUTH_RESIDUAL * float(np.max(np.abs(b))):
        raise InputError(
            f"plant robot {plant.name}: its torques are not linear in the base parameters of "
            f"{prior.name} (residual {residual:.3g} N·m); the robots differ in structure"
        )
    return beta


def _stacked(
    columns: np.ndarray, target: np.ndarray, weights_std: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The rows of both joints, each divided by its joint's standard deviation."""
    a = np.concatenate([columns[:, j, :] / weights_std[j] for j in range(2)])
    b = np.concatenate([target[:, j] / weights_std[j] for j in range(2)])
    return a, b


def _residual_std(columns: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Each joint's residual standard deviation after ordinary least squares, N·m."""
    a, b = _stacked(columns, target, np.ones(2))
    solution, *_ = np.linalg.lstsq(a, b, rcond=None)
    residual = (b - a @ solution).reshape(2, -1)
    std = np.sqrt(np.mean(residual**2, axis=1))
    return np.maximum(std, 1e-6 * max(float(np.max(np.abs(b))), 1e-12))


def _kind(name: str) -> str:
    parts = name.split(".")
    return parts[1] if parts[0] in BODIES else parts[0]


def _standard_estimate(
    robot: Robot, y: np.ndarray, target: np.ndarray, residual_std: np.ndarray
) -> np.ndarray:
    """π closest to the prior robot's under the physical bounds, in what a robot file
    holds (:func:`_file_basis`; module docstring)."""
    prior = standard_parameters(robot)
    data, rhs = _stacked(y, target, residual_std)
    spread = np.array(
        [
            PRODUCT_SPREAD
            if _product_of_inertia(name)
            else max(PRIOR_SHARE * abs(value), PRIOR_FLOOR[_kind(name)])
            for name, value in zip(STANDARD_PARAMETERS, prior, strict=True)
        ]
    )
    a = np.vstack([data, np.diag(1.0 / spread)])
    b = np.concatenate([rhs, prior / spread])
    low = np.array(
        [
            0.0 if _kind(n) in _NOT_NEGATIVE or _diagonal_inertia(n) else -np.inf
            for n in STANDARD_PARAMETERS
        ]
    )
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
    bodies = {}
    for body in BODIES:
        xx, yy, zz, xy, xz, yz = (at[f"{body}.inertia.{ij}"] for ij in INERTIA_ENTRIES)
        inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        values, vectors = np.linalg.eigh(inertia)
        if np.min(values) < -INERTIA_ROUND_OFF * max(np.max(np.abs(values)), 1e-300):
            raise SpmOptError(
                f"identification: the inertia of {body} comes out not positive semi-definite "
                f"(eigenvalues {values}); the logs do not determine it"
            )
        inertia = (vectors * np.maximum(values, 0.0)) @ vectors.T  # round-off below 0 → 0
        part = getattr(robot, body)
        bodies[body] = dataclasses.replace(part, mass=at[f"{body}.mass"], inertia=inertia)
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


def filtered_prediction(robot: Robot, samples: Samples) -> np.ndarray:
    """The model's actuator torques of ``robot`` at the samples' motion, through the
    parallel filter (M, 2), N·m."""
    return samples.parallel(dynamics.actuator_torque(robot, samples.q, samples.qd, samples.qdd))


def prediction_rms(robot: Robot, samples: Samples) -> np.ndarray:
    """RMS of measured − predicted torque per joint (2,), N·m, both through the parallel
    filter (:func:`filtered_prediction`)."""
    error = samples.parallel(samples.torque) - filtered_prediction(robot, samples)
    return np.sqrt(np.mean(error**2, axis=0))


def robot_file_text(identification: Identification, loops: LoopEstimate, name: str) -> str:
    """The identified robot, its actuator loops from ``loops``, as the text of a robot file,
    the estimates in comments."""
    ident = identification
    lines = [
        f"# Identified by spm-opt identify from {ident.duration_s:.1f} s of log "
        f"({ident.samples} samples); condition number {ident.condition_number:.3g}; "
        f"residual standard deviations {ident.residual_std_nm[0]:.4f} and "
        f"{ident.residual_std_nm[1]:.4f} N m.",
        "# Base parameters (weighted least squares): estimate +- standard error [prior], the "
        f"errors with the residuals' correlation factor {ident.correlation_factor:.3g};",
        "# identified when two errors (a 95 % interval) are at most 10 % of the value.",
    ]
    for base_name, base_unit, prior, value, error, ok in ident.base_rows():
        status = "identified" if ok else "NOT identified"
        lines.append(
            f"#   {value: .5g} +- {error:.2g} {base_unit} [{prior:.5g}] {status}: {base_name}"
        )
    lines.append(_efficiency_comment(ident))
    drive = dict(zip(STANDARD_PARAMETERS, ident.standard, strict=True))
    lines.append(
        "# Not in the robot file: the drives' offsets "
        f"{drive['offset.theta1']:.4g} and {drive['offset.theta2']:.4g} N m."
    )
    lines += loops.comment_lines()
    return "\n".join(lines) + "\n" + robot_toml(loops.robot(ident.robot), name)


def _efficiency_comment(ident: Identification) -> str:
    """The robot file's comment on the gear efficiency."""
    return (
        f"# Gear efficiency: {ident.efficiency:.4g} +- {ident.efficiency_error:.2g} "
        f"[{ident.efficiency_prior:.4g}]. {_efficiency_sentence(ident)}"
    )


def _efficiency_sentence(ident: Identification) -> str:
    """What the logs say of the gear efficiency η, and the identified robot's."""
    loss = 1.0 - ident.efficiency
    if ident.efficiency_identified:
        return (
            "Identified (the loss 1 − η to 10 % at 95 %): the identified robot's η is "
            f"{ident.efficiency:.4g}."
        )
    if ident.efficiency_significant:
        return (
            f"Not identified to 10 % of the loss 1 − η at 95 %, but the loss is "
            f"{loss / ident.efficiency_error:.1f} standard errors: the identified robot's η is "
            f"{ident.efficiency:.4g}."
        )
    return (
        "The logs do not tell the gear train from a lossless one: the identified robot's η is "
        "1 (its losses show as friction). A motion where the load drives the motors back "
        "(braking, lowering against gravity) shows it."
    )


def report_markdown(
    identification: Identification,
    prior_rms: np.ndarray,
    identified_rms: np.ndarray,
    on: str,
    current_unit_nm: float,
) -> str:
    """The identification's summary: the base parameters, the log each would need, and the
    torque predictions; ``current_unit_nm``: one Present Current unit at the output."""
    ident = identification
    rows = [
        [
            name,
            f"{prior:.4g}",
            f"{value:.4g}",
            f"{error:.2g}",
            "yes" if ok else "no",
            f"{seconds:.3g}" if np.isfinite(seconds) else "never",
            unit_,
        ]
        for (name, unit_, prior, value, error, ok), seconds in zip(
            [*ident.base_rows(), ident.efficiency_row()],
            [*ident.seconds_for_identification(), ident.seconds_for_efficiency()],
            strict=True,
        )
    ]
    header = ["base parameter", "prior", "estimate", "std. error", "identified", "log for 10 %, s"]
    lines = [
        "# Identification",
        "",
        f"{ident.duration_s:.1f} s of log, {ident.samples} samples after filtering; condition "
        f"number {ident.condition_number:.3g}; residual standard deviations "
        f"{ident.residual_std_nm[0]:.4f} and {ident.residual_std_nm[1]:.4f} N·m, against one "
        f"current unit of {current_unit_nm:.4f} N·m at the output.",
        "",
        "A base parameter counts as identified when its 95 % interval, two standard errors, "
        "lies within 10 % of its value; the gear efficiency η when its two standard errors lie "
        "within 10 % of the loss 1 − η. The standard errors allow for the correlation of "
        f"neighbouring rows (their variances × {ident.correlation_factor:.3g}). The log for "
        "10 % extrapolates this motion's length by 1/√length; a parameter whose torques stay "
        "far below the residuals needs a livelier motion, not a longer one.",
        "",
        f"Gear efficiency: {_efficiency_sentence(ident)}",
        "",
        f"Not identifiable from any motion: {', '.join(ident.unseen) or 'none'} (they leave "
        "no trace in the torques). Every other parameter of the robot file shows only in the "
        "combinations below; the prior settles how a combination splits.",
        "",
        *markdown_table([*header, "unit"], rows),
        "",
        f"Torque prediction on {on} (RMS of measured − predicted, filtered as for the fit):",
        "",
        *markdown_table(
            ["robot", "θ1 N·m", "θ2 N·m"],
            [
                ["prior (the problem's robot)", f"{prior_rms[0]:.4f}", f"{prior_rms[1]:.4f}"],
                ["identified", f"{identified_rms[0]:.4f}", f"{identified_rms[1]:.4f}"],
            ],
        ),
    ]
    return "\n".join(lines) + "\n"


def prediction_figure(prior: Robot, identified: Robot, samples: Samples) -> Figure:
    """Measured torques against the prior's and the identified robot's predictions (N·m),
    filtered as for the fit, per joint, over the time the kept samples span (s): the
    stretches where a joint turns slower than the samples' minimum speed are left out and
    the runs follow each other."""
    figure = Figure(figsize=(9, 5.5), layout="constrained")
    axes = figure.subplots(2, 1, sharex=True)
    measured = samples.parallel(samples.torque)
    t = np.arange(len(measured)) * samples.decimation / float(np.median(samples.rates_hz))
    predictions = {
        name: filtered_prediction(robot, samples)
        for name, robot in (("prior", prior), ("identified", identified))
    }
    for joint, axis in enumerate(axes):
        axis.plot(t, measured[:, joint], "k-", lw=1.0, label="measured")
        for (name, values), style in zip(predictions.items(), ("--", "-"), strict=True):
            rms = float(np.sqrt(np.mean((measured[:, joint] - values[:, joint]) ** 2)))
            axis.plot(t, values[:, joint], style, lw=1.0, label=f"{name} (RMS error {rms:.4f} N·m)")
        axis.set_ylabel(f"τ{joint + 1} (N·m)")
        axis.set_title(f"actuator {joint + 1}", fontsize=10)
        axis.grid(True, alpha=0.3)
        axis.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8)
    axes[1].set_xlabel("time while both joints move (s)")
    figure.suptitle(
        "Torque prediction: measured against the prior and the identified robot\n"
        f"(low-passed at {samples.cutoff_hz:g} Hz as for the fit; stretches where a joint "
        f"turns slower than {samples.min_speed_rad_s:g} rad/s left out)",
        fontsize=11,
    )
    return figure
