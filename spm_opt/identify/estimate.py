"""The robot's base parameters and gear efficiency estimated from execution logs.

    spm-opt identify LOG.csv [LOG.csv ...] --problem P.toml --out identified.toml
                     [--holdout 0.2] [--validate LOG.csv] [--cutoff-hz 2] [--decimation N]
                     [--min-speed 0.02]

The identified robot's standard parameters come from :mod:`spm_opt.identify.physical_robot`;
the robot file it writes (:mod:`spm_opt.identify.robot_file`) also carries each actuator's
position and velocity loop, which :mod:`spm_opt.identify.loop` estimates from the logs'
goals and positions; :mod:`spm_opt.identify.validate` checks its torque predictions and
:mod:`spm_opt.identify.report` writes its summary and figure.

The logs' samples (:mod:`spm_opt.identify.samples`) give τ_j − τ_payload = Y_b(q, q̇, q̈) β,
the base parameters of the problem's robot (:mod:`spm_opt.model.base_parameters`), both
sides through the same low-pass filter (parallel filtering). τ_j is the torque at the
joints; the actuators measure the motor's, τ_m, and through a gear train of efficiency η,
τ_j = η τ_m where the motor drives its load and τ_m / η where the load drives it back
(:meth:`~spm_opt.model.actuator.Actuator.drive_torque`). A log whose current is a
period's mean holds its reads' two sides (:mod:`spm_opt.execution.torque_sides`): τ_j is
η times the side that turns the way the joint does plus the other over η, however the
velocity loop swings the torque within the period
(:meth:`~spm_opt.identify.samples.Samples.joint_torque`). Where the model
decides which of the two (a log without the sides, and to express residuals in motor
torque): where the joint torque of a fit with η = 1 has the rate's sign (the measured
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
correlated, :func:`~spm_opt.identify.samples.correlation_factor`: 2.0 to 2.5 measured);
without it the standard errors came out 1.4 to 1.5 times smaller than the estimates'
scatter over repeated logs.

The base parameters reported are physically consistent: β = K π of the standard parameters
π closest to the weighted least squares under the physical constraints, with a negligible
prior (:data:`PRIOR_WEIGHT`) to settle what the torques leave open
(:func:`~spm_opt.identify.physical_robot.physical_fit`). Where a constraint binds, the
estimate moves off the unconstrained one; the standard errors stay those of the
unconstrained weighted least squares. A parameter the constraints hold at its bound
(:attr:`Identification.at_bound`), or move by more than :data:`MOVED_SIGMAS` standard errors,
is not identified, and :meth:`Identification.reasons` says so, with how many standard errors
the unconstrained estimate lay beyond the bound.

A base parameter counts as identified when, besides, its 95 % interval, two standard errors,
lies within 10 % of its value: each such estimate is within 10 % of the truth in 19 of 20
logs (measured before the constraints).
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

Measured, before the constraints, on the simulated robot whose plant is
``prototype_plant.toml`` (a 120 s
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

from dataclasses import dataclass

import numpy as np
import scipy.optimize

from spm_opt.base.errors import InputError
from spm_opt.identify.physical_robot import (
    not_negative,
    physical_fit,
    prior_spread,
    robot_with_parameters,
    standard_estimate,
)
from spm_opt.identify.samples import Samples, correlation_factor
from spm_opt.model.base_parameters import BaseParameters, base_parameters
from spm_opt.model.params import Robot
from spm_opt.model.regressor import STANDARD_PARAMETERS, regressor, standard_parameters, unit

IDENTIFIED_RELATIVE_ERROR = 0.1
"""A base parameter is identified when :data:`IDENTIFIED_SIGMAS` standard errors are at
most this share of it."""
IDENTIFIED_SIGMAS = 2.0
"""Standard errors that must fit within :data:`IDENTIFIED_RELATIVE_ERROR` of a value (a
95 % interval)."""
MAX_CONDITION = 1e6
"""Above this condition number the logs do not determine the base parameters at all."""
EFFICIENCY_BOUNDS = (0.5, 1.0)
"""The gear efficiencies η searched."""
EFFICIENCY_STEP = 0.01
"""Step in η of the finite differences of the motor-torque misfit (its curvature) and of
the estimate (its slope)."""
PRIOR_WEIGHT = 1e-6
"""The prior's weight in the base parameters' physically consistent fit, relative to the
curvature of the data's misfit in its least determined direction (in units of the prior's
spread), so that the problem is as well conditioned whatever the noise: enough to settle
what the torques leave open, too little to move a base parameter by a measurable share of
its standard error. Where no constraint bound, the estimates moved from the unconstrained
ones by 2.0e-6 and 2.9e-4 of their standard errors at most: the torques of prototype.toml
with a rotor inertia of 0.002 kg·m², viscous friction 0.1 N·m·s/rad and Coulomb friction
0.02 N·m, at the motion of tests/test_identify.py's ``synthetic_samples``, with 1e-5 and
1e-4 N·m of noise."""
AT_BOUND_SIGMAS = 0.01
"""A bounded base parameter within this many standard errors of 0 sits at its bound."""
MOVED_SIGMAS = 2.0
"""A base parameter the constraints moved by more than this many standard errors from the
unconstrained estimate is not identified."""
LIVELIER = 10.0
"""A parameter that would need a log this many times longer needs a livelier motion."""
LOSS_SIGNIFICANCE = 2.0
"""The robot file carries the estimated η when the loss 1 − η is at least this many
standard errors; below, the logs do not tell its gear train from a lossless one and it
keeps η = 1."""


@dataclass(frozen=True)
class Identification:
    """What the logs determine, and the robot they give.

    Attributes
    ----------
    names : list of str
        Each base parameter as its combination of standard parameters.
    units : list of str
    prior, unconstrained, estimate, standard_error : ndarray, shape (r,)
        β of the problem's robot; β from weighted least squares; β physically consistent
        (:func:`~spm_opt.identify.physical_robot.physical_fit` with a negligible prior); the
        weighted least squares' standard errors.
    bounded : ndarray of bool, shape (r,)
        The base parameters the physical constraints keep ≥ 0 (sums of parameters each ≥ 0).
    active : list of str
        The physical constraints that hold the consistent estimate back (and, when IPOPT
        stopped short of converging, why).
    identified : ndarray of bool, shape (r,)
        Off its bound, not moved by the constraints (:attr:`moved`), and two standard
        errors at most 10 % of the estimate.
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
    file_active : list of str
        The physical constraints that hold the robot file's fit back (and, when IPOPT
        stopped short of converging, why).
    robot : Robot
        The identified robot, its actuator loops the prior's
        (:func:`~spm_opt.identify.robot_file.robot_file_text` writes them as
        :mod:`spm_opt.identify.loop` estimates them).
    """

    names: list[str]
    units: list[str]
    prior: np.ndarray
    unconstrained: np.ndarray
    estimate: np.ndarray
    standard_error: np.ndarray
    bounded: np.ndarray
    active: list[str]
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
    file_active: list[str]
    robot: Robot

    @property
    def shift_sigmas(self) -> np.ndarray:
        """(r,) How far the constraints moved each estimate from the unconstrained one, in
        standard errors (signed)."""
        return (self.estimate - self.unconstrained) / self.standard_error

    @property
    def at_bound(self) -> np.ndarray:
        """(r,) bool: a bounded parameter the constraints hold at 0 (within
        :data:`AT_BOUND_SIGMAS` standard errors)."""
        return self.bounded & (self.estimate <= AT_BOUND_SIGMAS * self.standard_error)

    @property
    def moved(self) -> np.ndarray:
        """(r,) bool: off its own bound, but moved more than :data:`MOVED_SIGMAS` standard
        errors by the constraints on others."""
        return ~self.at_bound & (np.abs(self.shift_sigmas) > MOVED_SIGMAS)

    @property
    def identified(self) -> np.ndarray:
        """(r,) bool: neither at its bound nor moved, and two standard errors within 10 %
        of the estimate."""
        precise = IDENTIFIED_SIGMAS * self.standard_error <= IDENTIFIED_RELATIVE_ERROR * np.abs(
            self.estimate
        )
        return precise & ~self.at_bound & ~self.moved

    def reasons(self) -> list[str]:
        """Per base parameter, why it is identified or not, in words."""
        seconds = self.seconds_for_identification()
        share = np.divide(
            IDENTIFIED_SIGMAS * self.standard_error,
            np.abs(self.estimate),
            out=np.full(self.estimate.shape, np.inf),
            where=self.estimate != 0.0,
        )
        words = []
        for k, name in enumerate(self.names):
            shift = abs(self.shift_sigmas[k])
            moved = f"; the constraints moved it {shift:.1f} s.e." if shift >= 0.1 else ""
            if self.at_bound[k]:
                side = (
                    "beyond"
                    if self.shift_sigmas[k] > 0.0
                    else "inside it; the constraints on others hold it there"
                )
                words.append(
                    f"at its bound ({name} ≥ 0): the unconstrained fit, "
                    f"{self.unconstrained[k]:.3g}, lay {abs(self.shift_sigmas[k]):.1f} s.e. {side}"
                )
            elif self.moved[k]:
                words.append(
                    f"moved {abs(self.shift_sigmas[k]):.1f} s.e. by the physical constraints "
                    "that bind"
                )
            elif self.identified[k]:
                words.append(f"2 s.e. within 10 % ({100 * share[k]:.2g} %){moved}")
            elif not np.isfinite(share[k]) or seconds[k] > LIVELIER * self.duration_s:
                words.append(
                    f"2 s.e. are {_share(share[k])} it: its torques are below the noise, "
                    f"a livelier motion shows it{moved}"
                )
            else:
                more = seconds[k] - self.duration_s
                words.append(f"2 s.e. are {_share(share[k])} it: log {more:.3g} s more{moved}")
        return words

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


def _share(share: float) -> str:
    """Two standard errors' share of an estimate in words: "40 % of", "1.2e+03 times" (from
    10 times on)."""
    if not np.isfinite(share):
        return "not within any multiple of"
    return f"{100 * share:.3g} % of" if share < 10.0 else f"{share:.2g} times"


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
        joint = self.samples.joint_torque(self.driving, efficiency)
        return self.samples.parallel(joint - self.payload)

    def fit(self, efficiency: float) -> np.ndarray:
        """β (r,) by weighted least squares at η."""
        target = self.target(efficiency)
        weighted, rhs = _stacked(self.columns, target, _residual_std(self.columns, target))
        return np.linalg.lstsq(weighted, rhs, rcond=None)[0]

    def residual(self, efficiency: float) -> np.ndarray:
        """The residuals at η in motor torque, (τ_j − Y_b β − τ_payload) / (τ_j / τ_m) (τ_j
        :meth:`~spm_opt.identify.samples.Samples.joint_torque`; without the torques' sides,
        τ_m − (Y_b β + τ_payload) / (τ_j / τ_m)), through the parallel filter and divided by
        the weights (M, 2)."""
        joint = self.raw_columns @ self.fit(efficiency) + self.payload
        motor = self.samples.motor_error(self.driving, efficiency, joint)
        return self.samples.parallel(motor) / self.weights

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
        :func:`~spm_opt.identify.samples.correlation_factor` of the residuals at η.
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
    estimate, *_ = np.linalg.lstsq(weighted, rhs, rcond=None)  # unconstrained
    variance = float(np.sum((rhs - weighted @ estimate) ** 2) / max(len(rhs) - base.rank, 1))
    covariance = efficiency.correlation * variance * np.linalg.inv(weighted.T @ weighted)
    errors = np.sqrt(np.diag(covariance))
    if efficiency.significant:  # β's errors at a given η, and η's through dβ/dη
        errors = np.hypot(errors, efficiency.slope * efficiency.error)
    rows = _stacked(filtered, target, residual_std)
    prior = standard_parameters(robot)
    spread = prior_spread(prior)
    curvatures = np.linalg.eigvalsh((rows[0] * spread).T @ (rows[0] * spread))  # ascending
    weight = PRIOR_WEIGHT * float(curvatures[-base.rank])  # the data's weakest direction's
    consistent = physical_fit(robot, *rows, spread, weight, file_structure=False)
    fitted = standard_estimate(robot, *rows)
    return Identification(
        names=base.names(),
        units=[unit(STANDARD_PARAMETERS[k]) for k in base.independent],
        prior=base.values(prior),
        unconstrained=estimate,
        estimate=base.values(consistent.standard),
        standard_error=errors,
        bounded=_bounded(base),
        active=consistent.active + ([consistent.stopped] if consistent.stopped else []),
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
        standard=fitted.standard,
        file_active=fitted.active + ([fitted.stopped] if fitted.stopped else []),
        robot=robot_with_parameters(robot, fitted.standard, used),
    )


def _bounded(base: BaseParameters) -> np.ndarray:
    """(r,) bool: the base parameters the physical constraints keep ≥ 0, sums of standard
    parameters that are each ≥ 0 (masses, friction, rotor inertias, diagonal inertias),
    with positive weights."""
    flags = []
    for row, index in enumerate(base.independent):
        terms = [index, *base.dependent[base.combination[row] != 0.0]]
        weights = base.combination[row][base.combination[row] != 0.0]
        flags.append(
            all(not_negative(STANDARD_PARAMETERS[k]) for k in terms) and np.all(weights > 0)
        )
    return np.array(flags, dtype=bool)


def _condition(columns: np.ndarray, weights_std: np.ndarray) -> float:
    """The condition number of the weighted rows with their columns scaled to unit norm."""
    stacked, _ = _stacked(columns, np.zeros(columns.shape[:2]), weights_std)
    norms = np.linalg.norm(stacked, axis=0)
    return float(np.linalg.cond(stacked / np.where(norms > 0, norms, 1.0)))


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
