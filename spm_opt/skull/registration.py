"""From the image to the robot: a rigid transform given as a matrix, or fitted to fiducials
located in both.

Every transform here is a homogeneous matrix (4, 4) taking the image's RAS coordinates, mm,
to the robot's frame, mm.
"""

from __future__ import annotations

import math

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import excerpt
from spm_opt.model.rigid import Registration, best_rigid_fit

MAX_FIDUCIAL_CONDITION = 10.0
"""Largest condition number of a set of fiducials: the ratio of the two largest singular
values of their centred coordinates, their spread along their best line over their spread
across it (infinite on a line). Measured: four fiducials 150 mm along a line, each located
with 0.5 mm of noise, turn the fitted rotation by 0.6° RMS at a condition number of 2,
2.6° at 10, 5.2° at 20 and 31° at 100 (a rotation of 2.6° moves a point 80 mm away by
3.6 mm). The generated example's four (front, left, right, top) have 1.2."""
ORTHONORMAL_TOLERANCE = 1e-6
"""Largest entry of ``RᵀR - I`` of a rotation given as a matrix."""
_RIGID = "a rigid transform: rotation and translation in mm; a mirror or scale is not allowed"


def fit_rigid(image_mm: np.ndarray, robot_mm: np.ndarray, field: str) -> Registration:
    """The rigid transform that best takes the image fiducials (n, 3), mm, onto the robot
    fiducials (n, 3), mm, in the least-squares sense (:func:`spm_opt.model.rigid.best_rigid_fit`:
    a rotation, never a mirror); its matrix is from the image's RAS coordinates to the
    robot's frame, its RMS the fiducial registration error.

    Raises InputError naming ``field`` for fewer than 3 fiducials, different counts,
    values that are not finite, or fiducials near one line (a condition number above
    :data:`MAX_FIDUCIAL_CONDITION`).
    """
    image = _fiducials(image_mm, field, "image")
    robot = _fiducials(robot_mm, field, "robot")
    if len(image) != len(robot):
        raise InputError(
            f"{field}: {len(image)} image fiducials but {len(robot)} robot fiducials; "
            "expected the same points located in both"
        )
    return best_rigid_fit(image, robot)


def _fiducials(value: np.ndarray, field: str, kind: str) -> np.ndarray:
    """``value`` as at least 3 finite points (n, 3), mm, not all on one line."""
    try:
        points = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        points = np.empty(0)
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise InputError(
            f"{field}: the {kind} fiducials {excerpt(_shown(value))}: expected a list of [x, y, z] "
            "points in mm, all finite"
        )
    if len(points) < 3:
        raise InputError(
            f"{field}: {len(points)} {kind} fiducials; expected at least 3, not on one line"
        )
    condition = fiducial_condition(points)
    if not condition <= MAX_FIDUCIAL_CONDITION:
        raise InputError(
            f"{field}: the {len(points)} {kind} fiducials are degenerate: they lie near one "
            f"line (condition number {condition:.3g}, their spread along it over their spread "
            f"across it; at most {MAX_FIDUCIAL_CONDITION:g}), which leaves the rotation about "
            "it undetermined: expected at least 3 points spread well away from one line"
        )
    return points


def fiducial_condition(points_mm: np.ndarray) -> float:
    """The condition number of fiducials (n, 3), mm: the largest singular value of their
    centred coordinates over the second largest (see :data:`MAX_FIDUCIAL_CONDITION`);
    infinite when they lie on one line."""
    centred = points_mm - points_mm.mean(axis=0)
    singular = np.linalg.svd(centred, compute_uv=False)
    return float(singular[0] / singular[1]) if singular[1] > 0.0 else math.inf


def check_residuals(registration: Registration, max_residual_mm: float, field: str) -> None:
    """Refuse a fit whose largest residual (the distance from a robot fiducial to its image
    fiducial once the fit is applied) exceeds ``max_residual_mm`` (mm): one line naming
    ``field`` (the bound's key), the fiducial (1-based, in the order listed) and every
    residual, in mm."""
    residuals = registration.residuals_mm
    worst = int(np.argmax(residuals))
    if residuals[worst] <= max_residual_mm:
        return
    listed = ", ".join(f"{r:.2f}" for r in residuals)
    raise InputError(
        f"{field} = {max_residual_mm:g}: fiducial {worst + 1} of {len(residuals)} has the "
        f"largest residual, {residuals[worst]:.2f} mm (each: {listed} mm; RMS "
        f"{registration.rms_mm:.2f} mm); expected at most {max_residual_mm:g} mm: check where "
        "the fiducials were located in both frames (the fit spreads one's error over others)"
    )


def check_transform(matrix: object, field: str) -> np.ndarray:
    """A user's image-to-robot matrix (4, 4), mm, checked to be a rigid transform: finite,
    last row [0, 0, 0, 1], and its upper 3 × 3 a rotation (orthonormal to
    :data:`ORTHONORMAL_TOLERANCE`, determinant +1). Returns it as an array."""
    try:
        array = np.array(matrix, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(
            f"{field} = {excerpt(_shown(matrix))}: expected 4 rows of 4 numbers"
        ) from None
    if array.shape != (4, 4):
        raise InputError(
            f"{field} = {excerpt(_shown(matrix))}: shape {array.shape}; expected 4 rows of 4 "
            "numbers"
        )
    if not np.all(np.isfinite(array)):
        raise InputError(f"{field} = {excerpt(array.tolist())}: expected finite numbers")
    if not np.array_equal(array[3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(f"{field}: last row {array[3].tolist()}; expected [0, 0, 0, 1] ({_RIGID})")
    rotation = array[:3, :3]
    error = np.max(np.abs(rotation.T @ rotation - np.eye(3)))
    if error > ORTHONORMAL_TOLERANCE:
        raise InputError(
            f"{field}: the upper 3x3 is not orthonormal (RᵀR differs from I by {error:.3g}); "
            f"expected {_RIGID}"
        )
    if np.linalg.det(rotation) < 0:
        raise InputError(f"{field}: the upper 3x3 has determinant -1 (a mirror); expected {_RIGID}")
    return array


def _shown(value: object) -> object:
    """``value`` for a message: an array as a list (whose excerpt is one line)."""
    return value.tolist() if isinstance(value, np.ndarray) else value
