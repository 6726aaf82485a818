"""The robot's dynamic parameters identified from execution logs.

    spm-opt identify LOG.csv [LOG.csv ...] --problem P.toml --out identified.toml
                     [--validate LOG.csv] [--cutoff-hz 2] [--decimation N] [--min-speed 0.02]

The logs' samples (:mod:`spm_opt.identify_samples`) give τ − τ_payload = Y_b(q, q̇, q̈) β,
the base parameters of the problem's robot (:mod:`spm_opt.model.base_parameters`), both
sides through the same low-pass filter (parallel filtering). The report's estimate is
weighted least squares: ordinary least squares first, then each joint's rows divided by its
residual standard deviation and solved again; standard errors σ² (W̃ᵀW̃)⁻¹ from the
weighted residuals; a base parameter counts as identified when its standard error is at
most 10 % of its value (the usual rule). The condition number is that of W̃ with its
columns scaled to unit norm.

The robot file is the estimate of the standard parameters π closest to the problem's robot:
the weighted rows and, for each parameter, a row (π_k − prior_k) / s_k with s_k half the
prior's value (or a floor per kind of parameter; the products of inertia kept): a prior of
50 % uncertainty that settles what the logs leave open, solved under the physical bounds
(masses, diagonal inertias, friction and rotor inertia not negative) with
``scipy.optimize.lsq_linear``. The model has one rail friction coefficient:
μ = (φ_u + φ_L) / (m_u + m_payload + m_L), and one rotor inertia (the joints' mean). The
drives' offsets, which the robot file cannot hold, are in its comments; the gear
efficiency is set to 1 (the regressor is linear only then: its losses show as friction).

Measured on the simulated robot whose plant is ``prototype_plant.toml`` (a 120 s
excitation and a 30 s validation run at 500 Hz, ``tests/test_identify.py``): the
validation torques' RMS prediction error falls from 0.040 and 0.039 N·m (the prior,
``prototype.toml``) to 0.008 and 0.007 (the plant's own model: 0.008 and 0.006). The base
parameters where the gear losses act (the rails' friction, gravity) come out biased: the
losses are not linear in the torque's sign pattern the regressor has.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from matplotlib.figure import Figure

from spm_opt.errors import InputError, SpmOptError
from spm_opt.identify_samples import Samples
from spm_opt.model import dynamics
from spm_opt.model.base_parameters import base_parameters
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
"""A base parameter is identified when its standard error is at most this share of it."""
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
    condition_number : float
    residual_std_nm : ndarray, shape (2,)
        Each joint's residual standard deviation (ordinary least squares), N·m.
    samples : int
        Samples used (after filtering, decimation and leaving out the slow ones).
    duration_s : float
        Seconds of log.
    standard : ndarray, shape (38,)
        The robot file's standard parameters (:data:`STANDARD_PARAMETERS`).
    robot : Robot
    """

    names: list[str]
    units: list[str]
    prior: np.ndarray
    estimate: np.ndarray
    standard_error: np.ndarray
    identified: np.ndarray
    condition_number: float
    residual_std_nm: np.ndarray
    samples: int
    duration_s: float
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
        """Per base parameter, the seconds of such a log its standard error would need to
        fall to 10 % of it (standard errors fall as 1/√length while the residuals stay
        uncorrelated); inf where the estimate is 0."""
        relative = np.divide(
            self.standard_error,
            IDENTIFIED_RELATIVE_ERROR * np.abs(self.estimate),
            out=np.full(self.estimate.shape, np.inf),
            where=self.estimate != 0.0,
        )
        return self.duration_s * relative**2


def identify(robot: Robot, samples: Samples) -> Identification:
    """Identify ``robot``'s parameters (the prior) from filtered log samples."""
    base = base_parameters(robot)
    y, payload = regressor(robot, samples.q, samples.qd, samples.qdd)
    y, target = samples.parallel(y), samples.parallel(samples.torque - payload)
    if len(target) < 10 * base.rank:
        raise InputError(
            f"logs: {len(target)} moving samples after filtering, at least "
            f"{10 * base.rank} needed for {base.rank} base parameters; log a longer motion "
            "that keeps both joints turning"
        )
    columns = base.columns(y)
    residual_std = _residual_std(columns, target)
    weighted, rhs = _stacked(columns, target, residual_std)
    norms = np.linalg.norm(weighted, axis=0)
    condition = float(np.linalg.cond(weighted / np.where(norms > 0, norms, 1.0)))
    if not condition < MAX_CONDITION:
        raise InputError(
            f"logs: the motion does not excite the robot's base parameters (condition "
            f"number {condition:.3g}); log a motion that swings both joints back and forth "
            "at several speeds"
        )
    estimate, *_ = np.linalg.lstsq(weighted, rhs, rcond=None)
    dof = max(len(rhs) - base.rank, 1)
    variance = float(np.sum((rhs - weighted @ estimate) ** 2) / dof)
    errors = np.sqrt(np.diag(variance * np.linalg.inv(weighted.T @ weighted)))
    standard = _standard_estimate(robot, y, target, residual_std)
    return Identification(
        names=base.names(),
        units=[unit(STANDARD_PARAMETERS[k]) for k in base.independent],
        prior=base.values(standard_parameters(robot)),
        estimate=estimate,
        standard_error=errors,
        identified=errors <= IDENTIFIED_RELATIVE_ERROR * np.abs(estimate),
        condition_number=condition,
        residual_std_nm=residual_std,
        samples=len(target),
        duration_s=samples.duration_s,
        standard=standard,
        robot=robot_with_parameters(robot, standard),
    )


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
    """π closest to the prior robot's under the physical bounds (module docstring)."""
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
    return scipy.optimize.lsq_linear(a, b, bounds=(low, np.inf)).x


def _diagonal_inertia(name: str) -> bool:
    return _kind(name) == "inertia" and name.split(".")[-1] in ("xx", "yy", "zz")


def _product_of_inertia(name: str) -> bool:
    return _kind(name) == "inertia" and not _diagonal_inertia(name)


def robot_with_parameters(robot: Robot, standard: np.ndarray) -> Robot:
    """``robot`` with the standard parameters π (masses, inertias, μ from the rails'
    friction, the rotor inertia as the mean of the joints', each joint's viscous friction)
    and a lossless gear train; an error if an inertia tensor is not physical."""
    at = dict(zip(STANDARD_PARAMETERS, standard, strict=True))
    bodies = {}
    for body in BODIES:
        xx, yy, zz, xy, xz, yz = (at[f"{body}.inertia.{ij}"] for ij in INERTIA_ENTRIES)
        inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        if np.min(np.linalg.eigvalsh(inertia)) < -1e-12:
            raise SpmOptError(
                f"identification: the inertia of {body} comes out not positive semi-definite "
                f"(eigenvalues {np.linalg.eigvalsh(inertia)}); the logs do not determine it"
            )
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
        gear_efficiency=1.0,
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


def robot_file_text(identification: Identification, name: str) -> str:
    """The identified robot as the text of a robot file, its estimates in comments."""
    ident = identification
    lines = [
        f"# Identified by spm-opt identify from {ident.duration_s:.1f} s of log "
        f"({ident.samples} samples); condition number {ident.condition_number:.3g}; "
        f"residual standard deviations {ident.residual_std_nm[0]:.4f} and "
        f"{ident.residual_std_nm[1]:.4f} N m.",
        "# Base parameters (weighted least squares): estimate +- standard error [prior];",
        "# identified when the error is at most 10 % of the value.",
    ]
    for base_name, base_unit, prior, value, error, ok in ident.base_rows():
        status = "identified" if ok else "NOT identified"
        lines.append(
            f"#   {value: .5g} +- {error:.2g} {base_unit} [{prior:.5g}] {status}: {base_name}"
        )
    drive = dict(zip(STANDARD_PARAMETERS, ident.standard, strict=True))
    lines.append(
        "# Not in the robot file: the drives' offsets "
        f"{drive['offset.theta1']:.4g} and {drive['offset.theta2']:.4g} N m."
    )
    return "\n".join(lines) + "\n" + robot_toml(ident.robot, name)


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
            ident.base_rows(), ident.seconds_for_identification(), strict=True
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
        "A base parameter counts as identified when its standard error is at most 10 % of its "
        "value. The log for 10 % extrapolates this motion's length by 1/√length; a parameter "
        "whose torques stay far below the residuals needs a livelier motion, not a longer one.",
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
    """Measured torques against the prior's and the identified robot's predictions,
    filtered as for the fit, per joint."""
    figure = Figure(figsize=(9, 5))
    axes = figure.subplots(2, 1, sharex=True)
    measured = samples.parallel(samples.torque)
    predictions = {
        name: filtered_prediction(robot, samples)
        for name, robot in (("prior", prior), ("identified", identified))
    }
    for joint, axis in enumerate(axes):
        axis.plot(measured[:, joint], "k-", lw=1.0, label="measured")
        for (name, values), style in zip(predictions.items(), ("--", "-"), strict=True):
            axis.plot(values[:, joint], style, lw=1.0, label=name)
        axis.set_ylabel(f"τ{joint + 1}, N·m")
        axis.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    axes[1].set_xlabel("sample (moving, after filtering)")
    return figure
