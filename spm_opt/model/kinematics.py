"""Kinematics of the spherical parallel manipulator (paper Eqs. 1, 2, 5, 17, 18).

Conventions (``docs/conventions.md``): the isocenter is the origin, z up; the
upper input arc turns about x by θ1, the lower arc about y by θ2; the upper platform's
mass centre B lies on the sphere |B| = r_u.

Every expression is written once, on 3-vectors held as tuples of components, through a
math namespace: the same code runs on numpy arrays (any shape, vectorised over samples)
and on CasADi symbols (for the dynamics and the optimiser). The public functions below
are the numpy face: joint angles as arrays of shape (N, 2) in rad, points as (N, 3) in m.
:func:`symbolic` gives the CasADi face.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.base.errors import UnreachableError

NUMPY = SimpleNamespace(sin=np.sin, cos=np.cos, sqrt=np.sqrt, atan2=np.arctan2)
CASADI = SimpleNamespace(sin=ca.sin, cos=ca.cos, sqrt=ca.sqrt, atan2=ca.atan2)

Vec = tuple[Any, Any, Any]


def _math(x: Any) -> SimpleNamespace:
    return CASADI if isinstance(x, ca.SX | ca.MX | ca.DM) else NUMPY


def cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a: Vec, b: Vec) -> Any:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def scale(a: Vec, s: Any) -> Vec:
    return (a[0] * s, a[1] * s, a[2] * s)


def add(a: Vec, b: Vec) -> Vec:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


# --- the expressions, written once -------------------------------------------------


def project_landmark(a: Vec, r_u: Any) -> Vec:
    """Eq. 1: landmark A projected radially onto the platform sphere of radius r_u."""
    m = _math(a[0])
    return scale(a, r_u / m.sqrt(dot(a, a)))


def inverse(b: Vec) -> tuple[Any, Any]:
    """Eq. 2 with atan2: joint angles (θ1, θ2) that put the platform at B (B_z > 0)."""
    m = _math(b[0])
    return m.atan2(-b[1], b[2]), m.atan2(b[0], b[2])


def arc_normals(theta1: Any, theta2: Any) -> tuple[Vec, Vec]:
    """Unit normals N_u = (0, C1, S1) and N_L = (C2, 0, −S2) of the two arc planes."""
    m = _math(theta1)
    c1, s1, c2, s2 = m.cos(theta1), m.sin(theta1), m.cos(theta2), m.sin(theta2)
    zero = 0.0 * theta1
    return (zero, c1, s1), (c2, zero, -s2)


def direction(theta1: Any, theta2: Any) -> Vec:
    """Eq. 5 divided by r_u: the unit vector b = N_L × N_u / |N_L × N_u| (b_z > 0)."""
    m = _math(theta1)
    n_u, n_l = arc_normals(theta1, theta2)
    u = cross(n_l, n_u)
    return scale(u, 1.0 / m.sqrt(dot(u, u)))


def direction_jacobian(theta1: Any, theta2: Any) -> tuple[Vec, Vec]:
    """Columns ∂b/∂θ1 and ∂b/∂θ2 of the unit direction b(θ); dB/dθ = r_u times these."""
    return direction_and_jacobian(theta1, theta2)[1:]


def direction_and_jacobian(theta1: Any, theta2: Any) -> tuple[Vec, Vec, Vec]:
    """The unit direction b(θ) (the values :func:`direction` gives) and the columns ∂b/∂θ1
    and ∂b/∂θ2, from one evaluation of the sines and cosines."""
    m = _math(theta1)
    c1, s1, c2, s2 = m.cos(theta1), m.sin(theta1), m.cos(theta2), m.sin(theta2)
    u = (c1 * s2, -s1 * c2, c1 * c2)
    norm = m.sqrt(dot(u, u))
    b = scale(u, 1.0 / norm)
    du = ((-s1 * s2, -c1 * c2, -s1 * c2), (c1 * c2, s1 * s2, -c1 * s2))
    j1, j2 = (scale(add(d, scale(b, -dot(b, d))), 1.0 / norm) for d in du)
    return b, j1, j2


def frames(theta1: Any, theta2: Any) -> tuple[tuple[Vec, Vec, Vec], tuple[Vec, Vec, Vec]]:
    """Eq. 17: the columns (x, y, z) of the upper and lower platform rotation matrices.

    Upper: y_u = N_u, z_u = B/r_u, x_u = y_u × z_u. Lower: x_L = N_L, z_L = B/r_u,
    y_L = z_L × x_L.
    """
    return frames_at(direction(theta1, theta2), theta1, theta2)


def frames_at(
    b: Vec, theta1: Any, theta2: Any
) -> tuple[tuple[Vec, Vec, Vec], tuple[Vec, Vec, Vec]]:
    """Eq. 17 as the paper writes it, in the redundant coordinates: columns of the upper and
    lower platform rotation matrices for a unit direction b = B / r_u and joint angles θ."""
    n_u, n_l = arc_normals(theta1, theta2)
    return (cross(n_u, b), n_u, b), (n_l, cross(b, n_l), b)


def frame_rates(
    theta1: Any, theta2: Any, rate1: Any, rate2: Any
) -> tuple[tuple[Vec, Vec, Vec], tuple[Vec, Vec, Vec]]:
    """Time derivatives of the columns of :func:`frames` for joint rates (θ̇1, θ̇2)."""
    m = _math(theta1)
    n_u, n_l = arc_normals(theta1, theta2)
    b = direction(theta1, theta2)
    j1, j2 = direction_jacobian(theta1, theta2)
    b_dot = add(scale(j1, rate1), scale(j2, rate2))
    zero = 0.0 * theta1
    n_u_dot = (zero, -m.sin(theta1) * rate1, m.cos(theta1) * rate1)
    n_l_dot = (-m.sin(theta2) * rate2, zero, -m.cos(theta2) * rate2)
    upper = (add(cross(n_u_dot, b), cross(n_u, b_dot)), n_u_dot, b_dot)
    lower = (n_l_dot, add(cross(b_dot, n_l), cross(b, n_l_dot)), b_dot)
    return upper, lower


def angular_velocity(columns: tuple[Vec, Vec, Vec], column_rates: tuple[Vec, Vec, Vec]) -> Vec:
    """Eq. 18: w with [w]× = Ṙ Rᵀ, computed as ½ Σ_i e_i × ė_i over the columns e_i."""
    total = (0.0, 0.0, 0.0)
    for e, e_dot in zip(columns, column_rates, strict=True):
        total = add(total, cross(e, e_dot))
    return scale(total, 0.5)


def singularity_margin(theta1: Any, theta2: Any) -> Any:
    """Smallest singular value of ∂b/∂θ (dB/dθ over r_u): 1 at θ = 0, 0 at a singularity."""
    return jacobian_margin(*direction_jacobian(theta1, theta2))


def jacobian_margin(j1: Vec, j2: Vec) -> Any:
    """:func:`singularity_margin` from the columns ∂b/∂θ1 and ∂b/∂θ2."""
    m = _math(j1[0])
    a, b, c = dot(j1, j1), dot(j1, j2), dot(j2, j2)
    half_sum, half_diff = (a + c) / 2, (a - c) / 2
    # smaller eigenvalue of [[a, b], [b, c]] as det / larger one: no cancellation near 0
    determinant = dot(cross(j1, j2), cross(j1, j2))
    return m.sqrt(determinant / (half_sum + m.sqrt(half_diff * half_diff + b * b)))


# --- the numpy face ----------------------------------------------------------------


def _columns(points: np.ndarray) -> Vec:
    points = np.asarray(points, dtype=float)
    return points[..., 0], points[..., 1], points[..., 2]


def _stack(v: Vec) -> np.ndarray:
    return np.stack(np.broadcast_arrays(*v), axis=-1)


def _angles(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    q = np.asarray(q, dtype=float)
    return q[..., 0], q[..., 1]


def project_landmarks(landmarks: np.ndarray, r_u: float) -> np.ndarray:
    """Eq. 1 over landmarks of shape (N, 3), m: their points on the platform sphere."""
    return _stack(project_landmark(_columns(landmarks), r_u))


def inverse_kinematics(points: np.ndarray) -> np.ndarray:
    """Eq. 2: joint angles (N, 2), rad, for platform points (N, 3) with B_z > 0.

    Raises
    ------
    UnreachableError
        If a point has B_z <= 0 (at or below the isocenter plane).
    """
    b = _columns(points)
    low = np.flatnonzero(np.ravel(b[2]) <= 0.0)
    if low.size:
        raise UnreachableError(
            f"point {low[0]}: B_z = {np.ravel(b[2])[low[0]]:g} m: the platform must stay "
            "above the isocenter plane (B_z > 0)"
        )
    return np.stack(inverse(b), axis=-1)


def forward_kinematics(q: np.ndarray, r_u: float) -> np.ndarray:
    """Eq. 5: platform points B (N, 3), m, for joint angles (N, 2), rad."""
    return _stack(direction(*_angles(q))) * r_u


def platform_jacobian(q: np.ndarray, r_u: float) -> np.ndarray:
    """dB/dθ, shape (N, 3, 2), m/rad."""
    j1, j2 = direction_jacobian(*_angles(q))
    return np.stack([_stack(j1), _stack(j2)], axis=-1) * r_u


def motion_directions(q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For joint angles q (N, 2), rad, moving at q̇ (N, 2), rad/s: the platform's unit
    directions (N, 3), their rates (N, 3), 1/s, and the singularity margins (N,), from one
    evaluation of the Jacobian (the values of :func:`forward_kinematics` at r_u = 1,
    ``contour.direction_rates`` and :func:`singularity_margins`)."""
    (rate1, rate2), (b, j1, j2) = _angles(qd), direction_and_jacobian(*_angles(q))
    rates = add(scale(j1, rate1), scale(j2, rate2))
    return _stack(b), _stack(rates), jacobian_margin(j1, j2)


def platform_frames(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 17: rotation matrices of the upper and lower platforms, each (N, 3, 3)."""
    upper, lower = frames(*_angles(q))
    return (
        np.stack([_stack(c) for c in upper], axis=-1),
        np.stack([_stack(c) for c in lower], axis=-1),
    )


def platform_angular_velocities(q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 18: angular velocities of the upper and lower platforms, each (N, 3), rad/s."""
    theta1, theta2 = _angles(q)
    rate1, rate2 = _angles(qd)
    upper, lower = frames(theta1, theta2)
    upper_dot, lower_dot = frame_rates(theta1, theta2, rate1, rate2)
    return _stack(angular_velocity(upper, upper_dot)), _stack(angular_velocity(lower, lower_dot))


def singularity_margins(q: np.ndarray) -> np.ndarray:
    """:func:`singularity_margin` over joint angles (N, 2): shape (N,), dimensionless."""
    return singularity_margin(*_angles(q))


# --- the CasADi face ---------------------------------------------------------------


@dataclass(frozen=True)
class SymbolicKinematics:
    """CasADi expressions of the kinematics in the symbols ``q`` (2×1) and ``qd`` (2×1).

    ``platform`` is B / r_u (3×1); multiply by r_u for metres.
    """

    q: ca.SX
    qd: ca.SX
    direction: ca.SX
    direction_jacobian: ca.SX
    upper_frame: ca.SX
    lower_frame: ca.SX
    upper_angular_velocity: ca.SX
    lower_angular_velocity: ca.SX


def symbolic() -> SymbolicKinematics:
    """Build the kinematics as CasADi SX expressions, from the same code as the numpy face."""
    q, qd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2)
    upper, lower = frames(q[0], q[1])
    upper_dot, lower_dot = frame_rates(q[0], q[1], qd[0], qd[1])
    j1, j2 = direction_jacobian(q[0], q[1])

    def column(v: Vec) -> ca.SX:
        return ca.vertcat(*v)

    return SymbolicKinematics(
        q=q,
        qd=qd,
        direction=column(direction(q[0], q[1])),
        direction_jacobian=ca.horzcat(column(j1), column(j2)),
        upper_frame=ca.horzcat(*(column(c) for c in upper)),
        lower_frame=ca.horzcat(*(column(c) for c in lower)),
        upper_angular_velocity=column(angular_velocity(upper, upper_dot)),
        lower_angular_velocity=column(angular_velocity(lower, lower_dot)),
    )
