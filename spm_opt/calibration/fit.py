"""The fit: the tracker-to-robot registration and the robot's error angles together, by
nonlinear least squares, judged at poses it never saw.

From a first rigid registration of the measured marker positions onto the ideal robot's
(:func:`spm_opt.model.rigid.best_rigid_fit`), ``scipy.optimize.least_squares``
(Levenberg–Marquardt) estimates the unknowns of :mod:`~spm_opt.calibration.measurement`
that the poses identify (:mod:`~spm_opt.calibration.identifiability`); the others stay at 0.
Standard errors are σ̂ √diag((JᵀJ)⁻¹) at the solution, with σ̂² the residuals' sum of
squares over their 3m − p degrees of freedom.

The held-out error is measured, not inferred: the fitted model's marker positions at poses
the fit never saw against the tracker's there (a target registration error; the fit's own
residual, the FRE, does not predict it). Beside it, Fitzpatrick's prediction of the rigid
registration's TRE at those poses from the localisation error (1998, Eq. 46, as
scikit-surgerycore computes it), with the per-coordinate σ̂ the fit measured.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from sksurgerycore.algorithms.errors import compute_tre_from_fle

from spm_opt.base.errors import InputError
from spm_opt.calibration.identifiability import Observability, observability
from spm_opt.calibration.measurement import (
    GEOMETRY_START,
    UNKNOWNS,
    marker_model,
    rotation,
    start_vector,
)
from spm_opt.model import geometry, kinematics
from spm_opt.model.geometry import Geometry
from spm_opt.model.rigid import best_rigid_fit

MM = 1e-3

MIN_POSES = 6
"""Fewest poses a fit takes: 3 per pose against 14 unknowns, with room for a residual."""

ABSURD_RESIDUAL_M = 0.005
"""A fit whose residual RMS exceeds this, m, is not a calibration: the units or the pairing
of poses and measurements are wrong."""


MARKER_DISTANCE_SLACK = 0.2
"""Largest share by which the marker's fitted distance may differ from the nominal one:
more means the tracker's lengths are in other units (the distance absorbs a scale)."""


@dataclass(frozen=True)
class PoseMeasurements:
    """Per pose: the encoder readings (m, 2), rad, and the marker's mean position in the
    tracker's frame (m, 3), m."""

    readings_rad: np.ndarray
    marker_m: np.ndarray


@dataclass(frozen=True)
class CalibrationFit:
    """The fitted registration and geometry.

    Attributes
    ----------
    unknowns : ndarray (len(UNKNOWNS),)
    standard_errors : ndarray (len(UNKNOWNS),)
        NaN where an unknown was not estimated.
    first_rotation : ndarray (3, 3)
        The first guess R0 the Cayley vector turns.
    observability : Observability
        Of the fitted poses, at the solution.
    residual_rms_m : float
        RMS over the poses of the marker's distance from the fit's, m.
    residuals_m : ndarray (m, 3)
    """

    unknowns: np.ndarray
    standard_errors: np.ndarray
    first_rotation: np.ndarray
    observability: Observability
    residual_rms_m: float
    residuals_m: np.ndarray

    @property
    def geometry(self) -> Geometry:
        """The robot's fitted error angles."""
        return Geometry.from_vector(self.unknowns[GEOMETRY_START:])

    @property
    def geometry_standard_errors(self) -> np.ndarray:
        """Their standard errors (7,), rad (NaN: not identified)."""
        return self.standard_errors[GEOMETRY_START:]

    @property
    def marker_distance_m(self) -> float:
        """The marker's fitted distance from the isocenter, m."""
        return float(self.unknowns[6])

    @property
    def sigma_m(self) -> float:
        """σ̂, the residuals' standard deviation per coordinate, m."""
        dof = self.residuals_m.size - len(self.observability.estimated)
        return float(np.sqrt(np.sum(self.residuals_m**2) / max(dof, 1)))

    def marker(self, readings_rad: np.ndarray) -> np.ndarray:
        """The fitted model's marker positions (m, 3), m, in the tracker's frame."""
        return marker_model(self.unknowns, self.first_rotation, readings_rad)[0]

    def tool_point(self, readings_rad: np.ndarray, radius_m: float) -> np.ndarray:
        """The tool's point at ``radius_m`` (m, 3), m, in the robot's frame, as the fit
        sees it at encoder readings (m, 2), rad."""
        g = self.geometry
        return geometry.tool_directions(np.asarray(readings_rad) - g.encoder_zero, g) * radius_m

    def registration(self) -> tuple[np.ndarray, np.ndarray]:
        """The robot-to-tracker rotation (3, 3) and translation (3,), m."""
        return rotation(self.unknowns, self.first_rotation), self.unknowns[3:6].copy()


def _check(data: PoseMeasurements, what: str) -> None:
    readings, marker = np.asarray(data.readings_rad), np.asarray(data.marker_m)
    if readings.ndim != 2 or readings.shape[1] != 2 or marker.shape != (len(readings), 3):
        raise InputError(
            f"{what}: {readings.shape} readings against {marker.shape} marker positions; "
            "expected (m, 2) and (m, 3)"
        )
    if not (np.all(np.isfinite(readings)) and np.all(np.isfinite(marker))):
        raise InputError(f"{what}: a reading or a marker position is not a finite number")


def fit(data: PoseMeasurements, marker_distance_m: float) -> CalibrationFit:
    """Fit the registration and the identifiable error angles to ``data``, from the
    marker's nominal distance ``marker_distance_m``, m.

    Raises
    ------
    InputError
        Fewer than :data:`MIN_POSES` poses, or a residual RMS above
        :data:`ABSURD_RESIDUAL_M` (units or pose pairing wrong).
    """
    _check(data, "calibration measurements")
    readings, measured = np.asarray(data.readings_rad), np.asarray(data.marker_m)
    if len(readings) < MIN_POSES:
        raise InputError(
            f"calibration measurements: {len(readings)} poses; at least {MIN_POSES} needed"
        )
    ideal = kinematics.forward_kinematics(readings, marker_distance_m)
    first = best_rigid_fit(ideal / MM, measured / MM)
    start = start_vector(marker_distance_m, first.translation_mm * MM)
    first_rotation = np.array(first.rotation)
    _, jacobian = marker_model(start, first_rotation, readings)
    estimated = list(observability(jacobian, marker_distance_m, len(readings)).estimated)

    def residual(values: np.ndarray) -> np.ndarray:
        x = start.copy()
        x[estimated] = values
        return (marker_model(x, first_rotation, readings)[0] - measured).ravel()

    def jac(values: np.ndarray) -> np.ndarray:
        x = start.copy()
        x[estimated] = values
        return marker_model(x, first_rotation, readings)[1][:, estimated]

    solution = least_squares(residual, start[estimated], jac=jac, method="lm", xtol=1e-14)
    unknowns = start.copy()
    unknowns[estimated] = solution.x
    residuals = solution.fun.reshape(-1, 3)
    rms = float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))
    if rms > ABSURD_RESIDUAL_M:
        raise InputError(
            f"calibration measurements: the fit leaves {rms / MM:.2f} mm RMS between the "
            f"tracker and the robot (at most {ABSURD_RESIDUAL_M / MM:g} mm is a calibration): "
            "check the tracker file's length units and that its still windows pair with "
            "the plan's poses"
        )
    if abs(unknowns[6] - marker_distance_m) > MARKER_DISTANCE_SLACK * marker_distance_m:
        raise InputError(
            f"calibration measurements: the marker fits at {unknowns[6] / MM:.4g} mm from the "
            f"isocenter, nominally {marker_distance_m / MM:g} mm (within "
            f"{MARKER_DISTANCE_SLACK:.0%}): check the tracker file's length units and "
            "--marker-distance-mm"
        )
    _, final_jacobian = marker_model(unknowns, first_rotation, readings)
    seen = observability(final_jacobian, unknowns[6], len(readings))
    dof = residuals.size - len(estimated)
    sigma2 = float(np.sum(residuals**2)) / max(dof, 1)
    block = final_jacobian[:, estimated]
    errors = np.full(len(UNKNOWNS), np.nan)
    errors[estimated] = np.sqrt(sigma2 * np.diag(np.linalg.inv(block.T @ block)))
    return CalibrationFit(unknowns, errors, first_rotation, seen, rms, residuals)


@dataclass(frozen=True)
class HeldOut:
    """The fit judged at poses it never saw.

    Attributes
    ----------
    errors_m : ndarray (k,)
        Distance of the tracker's marker from the fit's at each held-out pose, m.
    predicted_tre_m : ndarray (k,)
        Fitzpatrick's TRE there for the fit's poses as fiducials and FLE² = 3σ̂², m.
    """

    errors_m: np.ndarray
    predicted_tre_m: np.ndarray

    @property
    def rms_m(self) -> float:
        """RMS of :attr:`errors_m`, m."""
        return float(np.sqrt(np.mean(self.errors_m**2)))


def held_out(result: CalibrationFit, fitted: PoseMeasurements, data: PoseMeasurements) -> HeldOut:
    """The measured and the predicted target registration error at ``data``'s poses."""
    _check(data, "held-out measurements")
    predicted = result.marker(np.asarray(data.readings_rad))
    errors = np.linalg.norm(predicted - np.asarray(data.marker_m), axis=1)
    fiducials = np.asarray(fitted.marker_m) / MM
    fle2 = 3.0 * (result.sigma_m / MM) ** 2
    tre = [
        float(np.sqrt(compute_tre_from_fle(fiducials, fle2, point[None, :] / MM))) * MM
        for point in np.asarray(data.marker_m)
    ]
    return HeldOut(errors, np.asarray(tre))
