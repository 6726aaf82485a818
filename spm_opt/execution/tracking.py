"""Goals that lead the position loop's lag, and the following error a run may show.

The L54's firmware takes goal positions only: no feed-forward input, no position I or D
term. Its P position loop (gain Kp, 1/s) turns the position error into a rate command,
which the PI velocity loop follows roughly as a first-order lag of bandwidth ωv (1/s). A
joint driven by goals equal to the plan lags it by q̇/Kp (2.6° at the L54's continuous
speed with Kp = 32 1/s). To make the joint follow the reference q(t) instead, the goal is
the two loops' inverse,

    g = q + q̇/Kp + q̈/(Kp ωv),

sampled half a control period T ahead, since each goal is held for a period:
g(t + T/2) ≈ g + (q̇ + q̈/Kp) T/2. The loop's parameters are the actuator's, from the
robot file (``position_loop_gain_per_s``, ``velocity_loop_bandwidth_per_s``; ``spm-opt
identify`` estimates them from a log).

The following error is the measured position less the reference (the plan at the logged
plan time), and it may grow with the speed, as LinuxCNC's does:
``max(min_error, max_error × |q̇| / q̇_limit)`` per joint, q̇ the larger of the reference's
rate and the measured one. LinuxCNC takes the commanded speed alone; but a joint that
lags keeps its lag while the reference slows down (measured without the lead on
``craniotomy_hardware.toml``: 0.31–0.64° where the reference had slowed to 0.06–0.10
rad/s, the joint still moving faster), and the loop's lag follows the joint's own rate:
Kp × error is its rate command. A stuck or blocked joint still trips it at the
reference's speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spm_opt.base.choices import TRACKING_MODES
from spm_opt.judge.limits import RULES
from spm_opt.model.actuator import Actuator
from spm_opt.model.params import Robot
from spm_opt.problem.trajectory import Trajectory


@dataclass(frozen=True)
class Lead:
    """The goal for a reference state: g = q + ``rate_s`` q̇ + ``acceleration_s2`` q̈.

    Attributes
    ----------
    rate_s : ndarray, shape (2,), s
    acceleration_s2 : ndarray, shape (2,), s²
    """

    rate_s: np.ndarray
    acceleration_s2: np.ndarray

    @classmethod
    def for_actuator(cls, actuator: Actuator, period_s: float, mode: str) -> Lead:
        """The lead of ``actuator``'s loops for goals held ``period_s`` (s) each; ``mode``
        "none" leads by nothing."""
        if mode not in TRACKING_MODES:
            raise ValueError(f"tracking = {mode!r}: expected one of {', '.join(TRACKING_MODES)}")
        if mode == "none":
            return cls(np.zeros(2), np.zeros(2))
        position = np.asarray(actuator.position_loop_gain_per_s, dtype=float)
        velocity = np.asarray(actuator.velocity_loop_bandwidth_per_s, dtype=float)
        half = 0.5 * period_s
        return cls(1.0 / position + half, 1.0 / (position * velocity) + half / position)

    def goal(self, position: np.ndarray, rate: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
        """Goal positions, rad, for reference positions (rad), rates (rad/s) and
        accelerations (rad/s²); any leading shape (…, 2)."""
        return position + self.rate_s * rate + self.acceleration_s2 * acceleration

    def written_goal(
        self, position: np.ndarray, rate: np.ndarray, acceleration: np.ndarray, late_s: float
    ) -> np.ndarray:
        """:meth:`goal` of a reference state (rad, rad/s, rad/s²) sampled at its cycle's
        time and written ``late_s`` (s) after it, the reference carried on to the write
        (q + q̇ d + q̈ d²/2, d = ``late_s``); the lead "none" carries it too, and sends
        the plan at its write.

        The actuator takes a goal when it arrives, and a goal can be written later than
        its cycle's time: the loop writes before it reads (:mod:`spm_opt.execution.cycle`),
        but a process on a busy machine can lose its core between the wake-up and the
        write. A goal sampled at its cycle's time arrives that far behind its reference,
        and a late one makes the steps between goals uneven: a jerk the plan does not
        have. On the simulated robot with every 20th goal 6 ms late, the hardware problem's
        toppra plan, led, reached 120.5 % of its jerk limit with goals sampled at their
        cycles' time, 91.8 % with the reference carried, 91.9 % with none late
        (``tests/test_tracking.py``). The goal before a late one is still held longer,
        which carrying does not undo. Carried by q, q̇ and q̈ alone, the led goal misses the
        reference's jerk q⃛ over d by at most q⃛ (d³/6 + ``rate_s`` d²/2 +
        ``acceleration_s2`` d): 3.0e-4 rad at 100 rad/s³ and 6 ms with the prototype's lead.
        On the simulated robot computing a goal takes no time: d = 0, and the goal is
        :meth:`goal`'s.
        """
        if late_s > 0.0:
            position = position + late_s * rate + 0.5 * late_s**2 * acceleration
            rate = rate + late_s * acceleration
        return self.goal(position, rate, acceleration)

    def goal_rate(self, rate: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray) -> np.ndarray:
        """The goals' rate of change, rad/s, along a reference with these derivatives."""
        return rate + self.rate_s * acceleration + self.acceleration_s2 * jerk


def following_error_limit(
    speed: np.ndarray, speed_limit: float, least: float, most: float
) -> np.ndarray:
    """The following error allowed per joint, rad: ``least`` at rest, growing in
    proportion to ``speed`` (rad/s) to ``most`` at ``speed_limit`` (rad/s)."""
    return np.maximum(least, most * np.abs(speed) / speed_limit)


def led_goals_outside(lead: Lead, trajectory: Trajectory, robot: Robot) -> str:
    """Why the goals led from ``trajectory`` (on the evaluator's grid) leave ``robot``'s
    joint range or outrun its actuators' Velocity Limit ("" if they do neither; the limit
    allowed the evaluator's 0.5 %)."""
    times = trajectory.time_grid()
    return led_samples_outside(lead, robot, times, *trajectory.states(times))


def led_samples_outside(
    lead: Lead,
    robot: Robot,
    times: np.ndarray,
    position: np.ndarray,
    rate: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray,
) -> str:
    """:func:`led_goals_outside` of a reference sampled at ``times`` (N,), s: its
    position, rate, acceleration and jerk (each (N, 2), SI)."""
    joint_range, velocity_limit = robot.joint_range, robot.actuator.velocity_limit_rad_s
    goals = lead.goal(position, rate, acceleration)
    for joint in range(2):
        low, high = joint_range[joint]
        beyond = np.maximum(low - goals[:, joint], goals[:, joint] - high)
        worst = int(np.argmax(beyond))
        if beyond[worst] > 0.0:
            return (
                f"theta{joint + 1}'s led goal {np.degrees(goals[worst, joint]):.3f} deg at "
                f"t = {times[worst]:.3f} s is out of the joint range "
                f"[{np.degrees(low):g}, {np.degrees(high):g}] deg"
            )
    goal_rate = np.abs(lead.goal_rate(rate, acceleration, jerk))
    worst_sample, joint = np.unravel_index(int(np.argmax(goal_rate)), goal_rate.shape)
    if goal_rate[worst_sample, joint] > RULES["joint speed"].allowed(velocity_limit):
        return (
            f"theta{joint + 1}'s led goal moves at {goal_rate[worst_sample, joint]:.3f} rad/s "
            f"at t = {times[worst_sample]:.3f} s, beyond the actuators' Velocity Limit "
            f"{velocity_limit:.3f} rad/s"
        )
    return ""
