"""A plan's rate-type limits at any pace, from one measurement of the plan: what the
evaluator would find of the plan run f times as fast, without sampling it again.

The plan run at feed f, q̃(t) = q(f t), passes the same points with q̇ scaled by f, q̈ by f²
and q⃛ by f³; its acceleration steps scale by f², its tool and depth speeds by f and its
depth acceleration by f². The torques follow the model, τ = M(q) q̈ + C(q, q̇) q̇ + g(q) +
friction: the inertial and velocity terms scale by f², gravity does not, and the
platforms' Coulomb friction (its sign only) does not for f > 0, so

    τ(f) = f² (τ₀ − g) + g + friction,

with τ₀ the frictionless torques of the plan as planned
(:func:`~spm_opt.model.dynamics.inverse_dynamics`), then through the actuators' rotor
inertia, joint friction and gear efficiency at the scaled motion. The rules of the path's
geometry (the joint range, the contour, the singularity margin) do not depend on the pace.

The figures are taken on the plan's own grid, finer in plan time than the grid the
evaluator samples a faster plan on: at a limit's edge the two may differ by what the
grids show of a peak, so a pace found this way is judged by the evaluator before it is
relied on (:func:`spm_opt.execution.ceiling.feed_ceiling`).
"""

from __future__ import annotations

import numpy as np

from spm_opt.cut.contour import surface_speed
from spm_opt.judge.depth import depth_rates
from spm_opt.judge.evaluate import DEFAULT_RATE_HZ
from spm_opt.judge.hold_room import hold_checks
from spm_opt.judge.limits import RULES
from spm_opt.model import dynamics, kinematics
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory


class PacedLimits:
    """The rate-type limits of ``trajectory`` under ``problem`` at any feed.

    Parameters
    ----------
    problem : Problem
    trajectory : Trajectory
    rate_hz : float, Hz
        The rate of the plan's grid the figures are taken on.
    """

    def __init__(
        self, problem: Problem, trajectory: Trajectory, rate_hz: float = DEFAULT_RATE_HZ
    ) -> None:
        self._problem = problem
        self.times = trajectory.time_grid(rate_hz)
        self.q, self.qd, self.qdd, self.jerk = trajectory.states(self.times)
        robot = problem.robot
        inertial, gravity, friction = dynamics.paced_torque_terms(robot, self.q, self.qd, self.qdd)
        self._inertial, self._static = inertial, gravity + friction
        _, self._steps = trajectory.acceleration_steps()
        jerk_limit = problem.limits.max_joint_jerk
        self._step_limit = None if jerk_limit is None else jerk_limit / rate_hz
        self._peaks = self._path_peaks()

    def states(
        self, feed: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The grid's samples of the plan run at ``feed``: times (N,), s, and q, q̇, q̈, q⃛
        (each (N, 2), SI)."""
        return (
            self.times / feed,
            self.q,
            feed * self.qd,
            feed**2 * self.qdd,
            feed**3 * self.jerk,
        )

    def torque(self, feed: float) -> np.ndarray:
        """The torques (N, 2), N·m, the actuators deliver along the plan run at ``feed``
        (> 0), as the evaluator takes them (:func:`~spm_opt.model.dynamics.actuator_torque`)."""
        _, _, qd, qdd, _ = self.states(feed)
        load = feed**2 * self._inertial + self._static
        return self._problem.robot.actuator.drive_torque(load, qd, qdd)

    def broken(self, feed: float) -> set[str]:
        """The rules of :data:`spm_opt.judge.limits.RULES` whose rate-type limit the plan
        run at ``feed`` (> 0) breaks, as the evaluator allows them."""
        problem, limits = self._problem, self._problem.limits
        actuator = problem.robot.actuator
        _, _, qd, qdd, jerk = self.states(feed)
        torque = self.torque(feed)
        figures = [
            ("joint speed", np.abs(qd), limits.max_joint_speed),
            ("joint acceleration", np.abs(qdd), limits.max_joint_acceleration),
            ("joint jerk", np.abs(jerk), limits.max_joint_jerk),
            ("acceleration step", feed**2 * np.abs(self._steps), self._step_limit),
            ("actuator torque", np.abs(torque), problem.max_joint_torque),
            (
                "motor current",
                np.abs(actuator.current_map.current(torque)),
                actuator.continuous_current_a,
            ),
            *(
                (rule, values, limit)
                for rule, _, values, limit in hold_checks(problem, qd, qdd, jerk)
            ),
            *((rule, feed**power * peak, limit) for rule, peak, power, limit in self._peaks),
        ]
        return {
            rule
            for rule, values, limit in figures
            if limit is not None and values.size and np.max(values) > RULES[rule].allowed(limit)
        }

    def _path_peaks(self) -> list[tuple[str, np.ndarray, int, float | None]]:
        """(rule, its peak on the plan as planned, the power of the feed it scales with,
        its limit) of the tool's speed and the depth's speed and acceleration, for the
        limits the problem sets."""
        problem, limits = self._problem, self._problem.limits
        wanted = (limits.max_tool_speed, limits.max_depth_speed, limits.max_depth_acceleration)
        if all(limit is None for limit in wanted):
            return []
        directions, rates, _ = kinematics.motion_directions(self.q, self.qd)
        radius, gradient = problem.contour.surface.radius_gradient(directions)
        peaks = [("tool speed", surface_speed(radius, gradient, rates), 1, limits.max_tool_speed)]
        if problem.inner_radius is not None:
            speed, acceleration = depth_rates(problem.inner_radius, self.times, directions, rates)
            peaks += [
                ("depth speed", speed, 1, limits.max_depth_speed),
                ("depth acceleration", acceleration, 2, limits.max_depth_acceleration),
            ]
        return [
            (rule, np.max(np.abs(values), initial=0.0), power, limit)
            for rule, values, power, limit in peaks
        ]
