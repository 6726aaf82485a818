"""What a tracker sees of the robot: a marker on the tool's axis, in the tracker's frame.

A marker at ``d`` from the isocenter on the tool's axis is at p = R (d t(q)) + c in the
tracker's frame, where t(q) is the tool's unit direction at encoder readings q
(:func:`spm_opt.model.geometry.tool_direction_at_reading`) and (R, c) take the robot's
frame to the tracker's. The calibration's unknowns are, in this order
(:data:`UNKNOWNS`): the registration's rotation as a Cayley vector v applied after a first
guess R0 (R = R0 C(v), C(v) = I + 2([v]× + [v]×²)/(1 + |v|²): smooth at 0, where a
rotation vector's norm is not), its translation c, m, the marker's distance d, m, and the
seven error angles of :data:`spm_opt.model.geometry.PARAMETERS`, rad.

The model is written once in CasADi; :func:`marker_model` gives the positions and their
Jacobian for any number of poses.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from spm_opt.model import geometry

REGISTRATION = ("rotation_x", "rotation_y", "rotation_z", "offset_x", "offset_y", "offset_z")
"""The registration's unknowns: Cayley vector (dimensionless), translation, m."""

UNKNOWNS = (*REGISTRATION, "marker_distance", *geometry.PARAMETERS)
"""Every unknown of the fit, in the order of its vector."""

GEOMETRY_START = len(REGISTRATION) + 1
"""Index of the first error angle in :data:`UNKNOWNS`."""


def cayley(v: ca.SX) -> ca.SX:
    """The rotation matrix C(v) (3×3) of a Cayley vector v (3×1): I at v = 0."""
    skew = ca.skew(v)
    return ca.SX.eye(3) + 2.0 * (skew + skew @ skew) / (1.0 + ca.dot(v, v))


@functools.lru_cache(maxsize=16)
def _mapped(poses: int) -> ca.Function:
    x = ca.SX.sym("x", len(UNKNOWNS))
    first = ca.SX.sym("R0", 3, 3)
    reading = ca.SX.sym("q", 2)
    t = ca.vertcat(
        *geometry.tool_direction_at_reading(
            reading[0], reading[1], ca.vertsplit(x[GEOMETRY_START:])
        )
    )
    point = first @ cayley(x[0:3]) @ (x[6] * t) + x[3:6]
    one = ca.Function("marker", [x, first, reading], [point, ca.jacobian(point, x)])
    return one.map(poses)


def marker_model(
    unknowns: np.ndarray, first_rotation: np.ndarray, readings: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The marker's positions (m, 3), m, in the tracker's frame at encoder ``readings``
    (m, 2), rad, and their Jacobian (3m, len(UNKNOWNS)) by pose, then axis."""
    readings = np.atleast_2d(np.asarray(readings, dtype=float))
    poses = len(readings)
    points, jacobian = _mapped(poses)(
        np.asarray(unknowns, dtype=float), np.asarray(first_rotation, dtype=float), readings.T
    )
    points = np.asarray(points).T
    jacobian = np.asarray(jacobian).reshape(3, poses, len(UNKNOWNS)).transpose(1, 0, 2)
    return points, jacobian.reshape(3 * poses, len(UNKNOWNS))


def start_vector(marker_distance_m: float, translation_m: np.ndarray | None = None) -> np.ndarray:
    """The unknowns at the ideal robot: no extra rotation, ``translation_m`` (3,), m (0 if
    None), the marker at ``marker_distance_m``, m, every error angle 0."""
    x = np.zeros(len(UNKNOWNS))
    x[3:6] = np.zeros(3) if translation_m is None else translation_m
    x[6] = marker_distance_m
    return x


def rotation(unknowns: np.ndarray, first_rotation: np.ndarray) -> np.ndarray:
    """The registration's rotation R = R0 C(v) (3, 3) of the unknowns."""
    v = ca.SX.sym("v", 3)
    matrix = ca.Function("cayley", [v], [cayley(v)])(np.asarray(unknowns[:3], dtype=float))
    return np.asarray(first_rotation) @ np.asarray(matrix)
