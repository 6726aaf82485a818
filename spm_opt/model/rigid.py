"""Rigid registration: the least-squares rotation and translation taking points in one frame
onto the same points in another (no scale, never a mirror), in mm.

The one fit behind the skull's fiducial registration (image to robot) and the motion
capture's (camera to manipulator); each checks its own points before fitting.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import svd


@dataclass(frozen=True)
class Registration:
    """A rigid transform fitted to pairs of points, source frame to target frame.

    A point maps as ``p_target = rotation @ p_source + translation_mm``.

    Attributes
    ----------
    matrix_mm : ndarray (4, 4)
        Homogeneous, from the source frame, mm, to the target frame, mm.
    rms_mm : float
        The registration error: the RMS of :attr:`residuals_mm`, mm.
    residuals_mm : ndarray (n,)
        Distance from each target point to its source point once transformed, mm.
    """

    matrix_mm: np.ndarray
    rms_mm: float
    residuals_mm: np.ndarray

    @property
    def rotation(self) -> np.ndarray:
        """The proper rotation (3, 3) from the source frame to the target frame."""
        return self.matrix_mm[:3, :3]

    @property
    def translation_mm(self) -> np.ndarray:
        """The source frame's origin in the target frame (3,), mm."""
        return self.matrix_mm[:3, 3]


def best_rigid_fit(source_mm: np.ndarray, target_mm: np.ndarray) -> Registration:
    """The rigid transform that best takes the points ``source_mm`` (n, 3), mm, onto
    ``target_mm`` (n, 3), mm, the same points in the same order: min Σ |R s_i + t − t_i|²
    over proper rotations R and translations t (Kabsch: the SVD of the cross-covariance of
    the centred points, its last singular direction flipped where the best orthogonal fit
    would be a mirror).

    The caller checks the points: finite, the same count, at least 3 and not on one line
    (else the rotation about that line is undetermined).
    """
    source = np.asarray(source_mm, dtype=float)
    target = np.asarray(target_mm, dtype=float)
    source_centre, target_centre = source.mean(axis=0), target.mean(axis=0)
    u, _, vt = svd((source - source_centre).T @ (target - target_centre))
    flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    matrix = np.eye(4)
    matrix[:3, :3] = vt.T @ flip @ u.T
    matrix[:3, 3] = target_centre - matrix[:3, :3] @ source_centre
    residuals = np.linalg.norm(apply(matrix, source) - target, axis=1)
    return Registration(_frozen(matrix), float(np.sqrt(np.mean(residuals**2))), _frozen(residuals))


def apply(matrix_mm: np.ndarray, points_mm: np.ndarray) -> np.ndarray:
    """Points (n, 3) or (3,), mm, transformed by the homogeneous matrix (4, 4), mm."""
    points = np.asarray(points_mm, dtype=float)
    return points @ matrix_mm[:3, :3].T + matrix_mm[:3, 3]


def _frozen(array: np.ndarray) -> np.ndarray:
    """``array``, read-only (a registration is a value)."""
    array.flags.writeable = False
    return array
