"""The paper's baseline (Section 3.1, Tables II–III): one cubic per joint per segment.

Conditions (Table II): each segment starts and ends at its landmarks' joint angles, the
joints rest at the start and the end, and velocity and acceleration are continuous at
every inner landmark. With n segments that is 8n conditions on 8n coefficients (the paper's
case: 4 segments, 32×32), solved here as one linear system. Each cubic is written in the
time since its segment began, which keeps the system well conditioned for long plans;
:func:`absolute_time_coefficients` gives the paper's form in absolute time.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import Polynomial
from scipy.interpolate import PPoly

from spm_opt.base.errors import PlanningError
from spm_opt.planners.registry import planner_options, register
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory


def _position(tau: float) -> list[float]:
    return [tau**3, tau**2, tau, 1.0]


def _velocity(tau: float) -> list[float]:
    return [3 * tau**2, 2 * tau, 1.0, 0.0]


def _acceleration(tau: float) -> list[float]:
    return [6 * tau, 2.0, 0.0, 0.0]


def cubic_system(waypoints: np.ndarray, durations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The linear system D c = r of Table II for every joint at once.

    Parameters
    ----------
    waypoints : ndarray, shape (n + 1, 2), rad
        Joint angles at the segment ends.
    durations : ndarray, shape (n,), s

    Returns
    -------
    D : ndarray, shape (8n, 8n)
    r : ndarray, shape (8n,)
        Unknowns ordered as the paper's: segment j's (a, b, c, d) for θ1 then (e, f, g, h)
        for θ2, each cubic in the time since segment j began.
    """
    segments = len(durations)
    size = 8 * segments
    system, rhs = np.zeros((size, size)), np.zeros(size)
    row = 0

    def column(segment: int, joint: int) -> slice:
        start = 8 * segment + 4 * joint
        return slice(start, start + 4)

    for joint in range(2):
        for j, length in enumerate(durations):
            for tau, target in ((0.0, waypoints[j, joint]), (length, waypoints[j + 1, joint])):
                system[row, column(j, joint)] = _position(tau)
                rhs[row] = target
                row += 1
        system[row, column(0, joint)] = _velocity(0.0)
        row += 1
        system[row, column(segments - 1, joint)] = _velocity(durations[-1])
        row += 1
        for j in range(1, segments):
            for basis in (_velocity, _acceleration):
                system[row, column(j - 1, joint)] = basis(durations[j - 1])
                system[row, column(j, joint)] = -np.array(basis(0.0))
                row += 1
    return system, rhs


class CubicPlanner:
    """Cubic joint polynomials through the landmarks with the problem's segment durations."""

    name = "cubic"

    def plan(self, problem: Problem) -> Trajectory:
        planner_options(problem, self.name)
        times = problem.waypoint_times
        system, rhs = cubic_system(problem.waypoint_angles, problem.segment_durations)
        try:
            solution = np.linalg.solve(system, rhs)
        except np.linalg.LinAlgError as error:
            raise PlanningError(f"cubic: the system of Table II is singular ({error})") from None
        # (segments, joint, power) -> PPoly's (power, segment, joint), highest power first
        coefficients = solution.reshape(len(times) - 1, 2, 4).transpose(2, 0, 1)
        return Trajectory(
            PPoly(coefficients, times),
            metadata={
                "landmark_times_s": times.tolist(),
                "landmarks": problem.visit_names,
                "statistics": {"status": "solved", "unknowns": int(rhs.size)},
            },
        )


def absolute_time_coefficients(trajectory: Trajectory) -> np.ndarray:
    """Cubic pieces rewritten in absolute time, as the paper prints them.

    Returns
    -------
    ndarray, shape (segments, 2, 4)
        For each segment and joint, (a, b, c, d) with θ(t) = a t³ + b t² + c t + d, in the
        trajectory's units (rad and s).
    """
    breaks, local = trajectory.breakpoints, trajectory.local_coefficients()
    if local.shape[0] != 4:
        raise ValueError(f"expected cubic pieces, got degree {local.shape[0] - 1}")
    result = np.zeros((len(breaks) - 1, 2, 4))
    for segment, start in enumerate(breaks[:-1]):
        for joint in range(2):
            local_poly = Polynomial(local[::-1, segment, joint])
            absolute = local_poly(Polynomial([-start, 1.0]))
            result[segment, joint] = np.pad(absolute.coef, (0, 4 - absolute.coef.size))[::-1]
    return result


register(CubicPlanner())
