"""A motion that follows the planned contour exactly and stops at every landmark: the
kinematically feasible starting point of the optimal-control planners.

On each segment the cut point moves along the great-circle arc with the arc-length fraction
of a rest-to-rest quintic, s(τ) = 10τ³ − 15τ⁴ + 6τ⁵; the joint angles come from the inverse
kinematics and their rates from the derivatives of s by the chain rule (numerically along
the arc).
"""

from __future__ import annotations

import numpy as np

from spm_opt.problem.problem import Problem

_STEP = 1e-6
"""Arc-length fraction of the central differences along a segment."""


def _fraction(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest-to-rest quintic: s, ds/dτ, d²s/dτ² at τ in [0, 1]."""
    s = tau**3 * (10 - 15 * tau + 6 * tau**2)
    ds = 30 * tau**2 * (1 - tau) ** 2
    dds = 60 * tau * (1 - tau) * (1 - 2 * tau)
    return s, ds, dds


def _angles(problem: Problem, segment: int, fraction: np.ndarray) -> np.ndarray:
    start, end = problem.contour.landmark_arc_lengths[segment : segment + 2]
    return problem.contour_angles(start + np.clip(fraction, 0.0, 1.0) * (end - start))


def segment_motion(
    problem: Problem, segment: int, tau: np.ndarray, duration: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint angles, rates and accelerations (N, 2) at normalised times τ (N,) in [0, 1] of
    one segment that lasts ``duration`` s."""
    s, ds, dds = _fraction(np.asarray(tau, dtype=float))
    q = _angles(problem, segment, s)
    q[tau <= 0.0] = problem.waypoint_angles[segment]
    q[tau >= 1.0] = problem.waypoint_angles[segment + 1]
    ahead = _angles(problem, segment, s + _STEP)
    behind = _angles(problem, segment, s - _STEP)
    # one-sided at the ends of the segment, where the clip makes one side a copy
    width = np.where((s + _STEP > 1.0) | (s - _STEP < 0.0), _STEP, 2 * _STEP)[:, None]
    dq_ds = (ahead - behind) / width
    d2q_ds2 = (ahead - 2 * q + behind) / _STEP**2
    d2q_ds2[(s + _STEP > 1.0) | (s - _STEP < 0.0)] = 0.0
    qd = dq_ds * ds[:, None] / duration
    qdd = (d2q_ds2 * ds[:, None] ** 2 + dq_ds * dds[:, None]) / duration**2
    return q, qd, qdd
