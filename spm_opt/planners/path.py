"""The contour as a joint path, segment by segment, and the model's terms along a joint
path: what toppra and the optimal control in path coordinates both plan along.

The contour has a corner at every landmark, so each segment between consecutive landmark
visits is its own path. Along segment k the cut point's arc length s (from the segment's
first landmark) parameterises the joint angles q(s): the inverse kinematics of points of
the great-circle arc (:func:`contour_joints`), exact at the landmarks, through which each
planner runs its own spline (toppra's :class:`JointPath`; the optimal control's adds the
lateral vectors, :mod:`spm_opt.planners.ocp.path_geometry`).

Along the path the model reads, at each point q with tangent q' and curvature q'',
τ = (M + J)(q' s̈ + q'' ṡ²) + h(q, q') ṡ² + g(q) + f: M the mass matrix, J the reflected
rotor inertia, h(q, q') ṡ² the Coriolis and centrifugal torque (quadratic in q̇ = q' ṡ), g
gravity with the payload, f the platforms' friction. The model's friction has a weight-only
normal force and the sign of the sliding velocity, so for ṡ > 0 it does not depend on ṡ:
f(q, q' ṡ) = f(q, q') (:func:`path_points`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from spm_opt.model import dynamics
from spm_opt.model.params import MM
from spm_opt.problem.problem import Problem


def contour_joints(problem: Problem, offsets: list[np.ndarray]) -> list[np.ndarray]:
    """The joint angles (N_k, 2), rad, that put the cut at arc lengths ``offsets[k]``
    (N_k,), m, from segment k's first landmark, for every segment; each segment's first and
    last sample the landmarks' angles exactly (its offsets run from 0 to its length). The
    inverse kinematics in one call."""
    ends, angles = problem.contour.landmark_arc_lengths, problem.waypoint_angles
    arc = np.concatenate([ends[k] + s for k, s in enumerate(offsets)])
    q = np.split(problem.contour_angles(arc), np.cumsum([len(s) for s in offsets[:-1]]))
    for k in range(len(offsets)):
        q[k][0], q[k][-1] = angles[k], angles[k + 1]
    return q


@dataclass(frozen=True)
class JointPath:
    """One segment's path: joint angles q(s), rad, of the arc length s, mm."""

    name: str
    spline: CubicSpline

    @property
    def length(self) -> float:
        """Arc length of the segment on the skull, mm."""
        return float(self.spline.x[-1])

    def derivatives(self, s: np.ndarray, orders: int = 3) -> list[np.ndarray]:
        """q, q', q'', ... (N, 2) at arc lengths s (N,), mm: rad, rad/mm, rad/mm², ..."""
        s = np.clip(s, 0.0, self.length)
        return [self.spline(s, order) for order in range(orders)]


def joint_paths(problem: Problem, samples: int) -> list[JointPath]:
    """Every segment's path, a cubic spline through ``samples`` points of its arc."""
    names, ends = problem.visit_names, problem.contour.landmark_arc_lengths
    count = len(problem.segment_durations)
    s = [np.linspace(0.0, ends[k + 1] - ends[k], samples) for k in range(count)]
    q = contour_joints(problem, s)
    return [
        JointPath(f"{names[k]}→{names[k + 1]}", CubicSpline(s[k] / MM, q[k])) for k in range(count)
    ]


@dataclass(frozen=True)
class PathPoints:
    """The path and the model along it at N points: q (N, 2), rad; q' and q'' (N, 2),
    rad/mm and rad/mm²; the inertia M + J (N, 2, 2), kg·m²; the Coriolis and centrifugal
    torque h(q, q') (N, 2) per unit ṡ², N·m·s²/mm²; gravity g(q) and friction f(q, q')
    (N, 2), N·m (see the module docstring)."""

    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    inertia: np.ndarray
    bias: np.ndarray
    gravity: np.ndarray
    friction: np.ndarray

    def __getitem__(self, index: slice) -> PathPoints:
        """The points ``index`` selects."""
        return PathPoints(*(getattr(self, f.name)[index] for f in dataclasses.fields(self)))


def path_points(problem: Problem, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> PathPoints:
    """The model's terms at path points q, q', q'' (N, 2): rad, rad/mm, rad/mm². Two
    evaluations of the model for any N: the frictionless torques at rest, at rest pushed by
    each unit joint acceleration and moving at q', and the friction moving at q'."""
    robot, zeros = problem.robot, np.zeros_like(q)
    push = [np.broadcast_to(unit, q.shape) for unit in np.eye(2)]
    torques = dynamics.inverse_dynamics(
        robot,
        np.tile(q, (4, 1)),
        np.vstack([zeros, zeros, zeros, dq]),
        np.vstack([zeros, *push, zeros]),
        friction=False,
    )
    gravity, first, second, moving = np.split(torques, 4)
    mass = np.stack([first - gravity, second - gravity], axis=-1)
    rotor = robot.actuator.rotor_inertia_kg_m2
    return PathPoints(
        q,
        dq,
        ddq,
        mass + rotor * np.eye(2),
        moving - gravity,
        gravity,
        dynamics.friction_torque(robot, q, dq),
    )
