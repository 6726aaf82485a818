"""The mechanism as built: the kinematics with their error parameters.

The ideal robot (:mod:`spm_opt.model.kinematics`) has the upper actuator's axis along x, the
lower's along y, each arc's plane containing its actuator's axis, and the tool along the
platform's radius B. A built robot differs from it by seven small angles, rad
(:data:`PARAMETERS`, all 0 for the ideal robot):

- ``encoder_zero_1``, ``encoder_zero_2``: what each encoder reads at θ = 0 (a reading is
  θ + zero);
- ``axis_twist``: the lower axis turned about z from y, so the two axes are 90° + twist
  apart (the frame is the upper axis's x and the plane of both axes: a rotation of the
  whole robot is the tracker's registration, not an error of the robot);
- ``upper_arc_tilt``, ``lower_arc_tilt``: each arc's plane normal tilted towards its own
  actuator's axis (the spherical five-bar's link twist angles, 90° − tilt);
- ``tool_tilt_x``, ``tool_tilt_y``: the tool axis turned about the upper platform's x and
  then y (Eq. 17's frame) from the platform's radius.

The tool's unit direction t(θ) is written once through the math namespace of
:mod:`~spm_opt.model.kinematics`, so the same code gives numpy values and CasADi symbols
(the calibration's Jacobian). With every error 0 it gives exactly the values of
:func:`kinematics.direction`.

How the rest of the program uses a calibrated geometry: the planners, the judge and the
review work in the model's joint coordinates, where the tool's direction is the ideal
:func:`kinematics.direction`; the robot's true joint angles are the ones that put its tool
on that same direction (:func:`true_joint_angles`), and its encoders read those plus the
zeros. The dynamics keep the nominal geometry: a joint differs from its model coordinate
by the errors' size, a few mrad.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.model import kinematics
from spm_opt.model.kinematics import Vec, add, cross, dot, scale

PARAMETERS = (
    "encoder_zero_1",
    "encoder_zero_2",
    "axis_twist",
    "upper_arc_tilt",
    "lower_arc_tilt",
    "tool_tilt_x",
    "tool_tilt_y",
)
"""The error parameters, rad, in the order of :meth:`Geometry.vector`."""

NEWTON_ITERATIONS = 3
"""Gauss–Newton steps of :func:`true_joint_angles` from the ideal inverse: the errors are a
few mrad, so each step about squares the residual: 5e-3, 3e-5, 1e-9, below 1e-15 rad."""


@dataclass(frozen=True)
class Geometry:
    """The seven error angles of :data:`PARAMETERS`, rad (all 0: the ideal robot)."""

    encoder_zero_1: float = 0.0
    encoder_zero_2: float = 0.0
    axis_twist: float = 0.0
    upper_arc_tilt: float = 0.0
    lower_arc_tilt: float = 0.0
    tool_tilt_x: float = 0.0
    tool_tilt_y: float = 0.0

    def vector(self) -> np.ndarray:
        """The parameters as an array (7,), rad, in the order of :data:`PARAMETERS`."""
        return np.array([getattr(self, name) for name in PARAMETERS], dtype=float)

    @classmethod
    def from_vector(cls, values: Sequence[float]) -> Geometry:
        """The geometry with ``values`` (7,), rad, in the order of :data:`PARAMETERS`."""
        return cls(**{name: float(v) for name, v in zip(PARAMETERS, values, strict=True)})

    @property
    def encoder_zero(self) -> np.ndarray:
        """What each encoder reads at θ = 0, (2,), rad."""
        return np.array([self.encoder_zero_1, self.encoder_zero_2])

    @property
    def is_ideal(self) -> bool:
        """Whether every error is exactly 0."""
        return not self.vector().any()

    @property
    def mechanism(self) -> Geometry:
        """The same geometry with the encoder zeros at 0: the mechanism alone."""
        return Geometry(0.0, 0.0, *self.vector()[2:])


IDEAL = Geometry()


# --- the expressions, written once -------------------------------------------------


def arc_normals(theta1: Any, theta2: Any, errors: Sequence[Any]) -> tuple[Vec, Vec]:
    """The arcs' plane normals N_u, N_L at true joint angles θ for the error angles
    ``errors`` (:data:`PARAMETERS`' order; the zeros are not used): the ideal
    (0, C1, S1) and (C2, 0, −S2) when the errors are 0."""
    m = kinematics._math(theta1)
    twist, tilt_u, tilt_l = errors[2], errors[3], errors[4]
    c1, s1, c2, s2 = m.cos(theta1), m.sin(theta1), m.cos(theta2), m.sin(theta2)
    zero = 0.0 * theta1
    # upper: (sin δu, cos δu, 0) turned about x by θ1
    n_u = (m.sin(tilt_u) + zero, m.cos(tilt_u) * c1, m.cos(tilt_u) * s1)
    # lower: axis a = (−sin β, cos β, 0); in-plane unit e = (cos β, sin β, 0), a × e = −z;
    # the normal cos δL e + sin δL a, turned about a by θ2 (Rodrigues)
    axis = (-m.sin(twist), m.cos(twist), zero)
    in_plane = scale((m.cos(twist), m.sin(twist), zero), m.cos(tilt_l))
    n_l = add(
        add(scale(in_plane, c2), (zero, zero, -m.cos(tilt_l) * s2)),
        scale(axis, m.sin(tilt_l)),
    )
    return n_u, n_l


def tool_direction(theta1: Any, theta2: Any, errors: Sequence[Any]) -> Vec:
    """The tool's unit direction t at true joint angles θ, rad, for ``errors``
    (:data:`PARAMETERS`' order; the zeros are not used): the platform's direction
    b = N_L × N_u / |N_L × N_u| when the errors are 0."""
    m = kinematics._math(theta1)
    n_u, n_l = arc_normals(theta1, theta2, errors)
    u = cross(n_l, n_u)
    b = scale(u, 1.0 / m.sqrt(dot(u, u)))
    tilt_x, tilt_y = errors[5], errors[6]
    local = (m.sin(tilt_y), -m.sin(tilt_x) * m.cos(tilt_y), m.cos(tilt_x) * m.cos(tilt_y))
    # the upper platform's frame (Eq. 17): x_u = N_u × b, y_u = N_u, z_u = b
    return add(add(scale(cross(n_u, b), local[0]), scale(n_u, local[1])), scale(b, local[2]))


def tool_direction_at_reading(reading1: Any, reading2: Any, errors: Sequence[Any]) -> Vec:
    """:func:`tool_direction` at encoder readings (θ + zero), rad."""
    return tool_direction(reading1 - errors[0], reading2 - errors[1], errors)


# --- the numpy face ----------------------------------------------------------------


def tool_directions(q: np.ndarray, geometry: Geometry) -> np.ndarray:
    """The tool's unit directions (N, 3) at true joint angles ``q`` (N, 2), rad."""
    q = np.asarray(q, dtype=float)
    t = tool_direction(q[..., 0], q[..., 1], geometry.vector())
    return np.stack(np.broadcast_arrays(*t), axis=-1)


@functools.lru_cache(maxsize=8)
def _direction_and_jacobian(samples: int) -> ca.Function:
    """t(θ, errors) (3,) and ∂t/∂θ (3×2) over ``samples`` columns, built once per size
    (the executor maps one sample a cycle, a plan all of its samples at once)."""
    q, e = ca.SX.sym("q", 2), ca.SX.sym("e", len(PARAMETERS))
    t = ca.vertcat(*tool_direction(q[0], q[1], ca.vertsplit(e)))
    function = ca.Function("tool_direction", [q, e], [t, ca.jacobian(t, q)])
    return function if samples == 1 else function.map(samples)


def true_joint_angles(q_model: np.ndarray, geometry: Geometry) -> np.ndarray:
    """The true joint angles (N, 2), rad, that put the built robot's tool on the direction
    the ideal model's joint coordinates ``q_model`` (N, 2), rad, give: Gauss–Newton on
    |t(θ) − b(q_model)| from θ = q_model. ``q_model`` itself when ``geometry`` is ideal."""
    q_model = np.asarray(q_model, dtype=float)
    if geometry.mechanism.is_ideal:
        return q_model.copy()
    flat = q_model.reshape(-1, 2)
    target = kinematics.forward_kinematics(flat, 1.0)
    function = _direction_and_jacobian(len(flat))
    errors = np.tile(geometry.vector()[:, None], (1, len(flat)))
    theta = flat.T.copy()
    for _ in range(NEWTON_ITERATIONS):
        t, jac = (np.asarray(v) for v in function(theta, errors))
        residual = t.T - target  # (N, 3)
        jac = jac.reshape(3, len(flat), 2).transpose(1, 0, 2)  # (N, 3, 2): blocks of 3×2
        normal = np.einsum("nij,nik->njk", jac, jac)
        step = np.linalg.solve(normal, np.einsum("nij,ni->nj", jac, residual)[..., None])
        theta -= step[..., 0].T
    return theta.T.reshape(q_model.shape)


def model_joint_angles(q_true: np.ndarray, geometry: Geometry) -> np.ndarray:
    """The model's joint coordinates (N, 2), rad, of the built robot at true joint angles
    ``q_true`` (N, 2), rad: the ideal inverse of its tool's direction."""
    q_true = np.asarray(q_true, dtype=float)
    if geometry.mechanism.is_ideal:
        return q_true.copy()
    return kinematics.inverse_kinematics(tool_directions(q_true, geometry))


def model_joint_rates(q_true: np.ndarray, rates_true: np.ndarray, geometry: Geometry) -> np.ndarray:
    """The model's joint rates (N, 2), rad/s, of the built robot at true joint angles
    ``q_true`` (N, 2), rad, turning at ``rates_true`` (N, 2), rad/s: the ideal model's
    rates that move its tool's direction as fast (least squares of ∂b q̇_model = ∂t q̇)."""
    q_true, rates_true = (np.asarray(a, dtype=float) for a in (q_true, rates_true))
    if geometry.mechanism.is_ideal:
        return rates_true.copy()
    flat, flat_rates = q_true.reshape(-1, 2), rates_true.reshape(-1, 2)
    _, jac = _direction_and_jacobian(len(flat))(
        flat.T, np.tile(geometry.vector()[:, None], (1, len(flat)))
    )
    jac_true = np.asarray(jac).reshape(3, len(flat), 2).transpose(1, 0, 2)
    jac_model = kinematics.platform_jacobian(model_joint_angles(flat, geometry), 1.0)
    moved = np.einsum("nij,nj->ni", jac_true, flat_rates)
    normal = np.einsum("nij,nik->njk", jac_model, jac_model)
    rates = np.linalg.solve(normal, np.einsum("nij,ni->nj", jac_model, moved)[..., None])
    return rates[..., 0].reshape(rates_true.shape)


def encoder_readings(q_model: np.ndarray, geometry: Geometry) -> np.ndarray:
    """What the encoders read (N, 2), rad, with the tool where ``q_model`` puts the ideal
    robot's."""
    return true_joint_angles(q_model, geometry) + geometry.encoder_zero


def model_from_readings(readings: np.ndarray, geometry: Geometry) -> np.ndarray:
    """The model's joint coordinates (N, 2), rad, of encoder ``readings`` (N, 2), rad."""
    return model_joint_angles(np.asarray(readings, dtype=float) - geometry.encoder_zero, geometry)


def degrees(geometry: Geometry) -> dict[str, float]:
    """The parameters in degrees, by name (for files and reports)."""
    return {name: math.degrees(v) for name, v in zip(PARAMETERS, geometry.vector(), strict=True)}
