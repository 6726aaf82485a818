"""What each limit means, written once: its unit, the evaluator's tolerance, what it judges,
and the bound a planner imposes for it.

Every planner and the evaluator read this module; none restates a limit.

The evaluator's tolerance, one table (:data:`RULES`):

| limit | unit | tolerance | judges |
|---|---|---|---|
| joint speed | rad/s | 0.5 % | robot |
| joint acceleration | rad/s² | 0.5 % | robot |
| joint jerk (and steps in q̈) | rad/s³ | 0.5 % | robot |
| actuator torque | N·m | 0.5 % | robot |
| motor current | A | 0.5 % | robot |
| tool speed | mm/s | 0.5 % | cut |
| contour deviation | mm | 0.5 % | cut |
| landmark visit | mm | 0.5 % | cut |
| coverage | mm | 0.5 % | cut |
| backtracking | mm | 0.5 % | cut |
| tool incidence | deg | 0.5 % | cut |
| depth speed, depth acceleration | mm/s, mm/s² | 0.5 % | cut |
| hold acceleration, hold jerk | rad/s², rad/s³ | 0.5 % | cut |
| joint range | deg | none (hard) | robot |
| singularity margin | — | none (hard) | robot |

Rate-type limits are allowed 0.5 % of the limit above it (the evaluator's grid and the
polynomials' rounding are not the robot's business); the joint range and the singularity
margin are mechanical facts with no slack. "Robot" limits protect the machine and are what
the executor checks before it moves; "cut" limits judge whether the plan cuts the planned
contour: every landmark visited in order within the path tolerance, the whole contour swept
in order, no stretch cut twice, and room left everywhere for a feed hold that stops the tool
on the path within the problem's ``hold_within_s`` (:mod:`spm_opt.judge.hold_room`; without it a
hold ends in the safe stop, which keeps the machine safe but not the tool on the path).

What planners impose (:func:`planner_bounds`): each rate-type limit less the planner's
``margin`` (a fraction kept for the motion between the points where it is imposed). The
torque limit is translated once for all of them: the evaluator judges the torque the
actuator delivers, ``actuator.drive_torque`` of the model's load torque, which adds the
reflected rotor inertia J q̈ and the joint's friction f_v q̇ + f_c sign(q̇) and costs 1/η
while driving; and the motor current the actuator's current map gives for it, within the
continuous current. A planner therefore bounds the joint side
|τ_load + J q̈ + f_v q̇ + f_c sign(q̇)| by η × min(torque limit, torque at the continuous
current): sufficient for both, and exact while the actuator drives the load.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spm_opt.judge.hold_room import planner_room
from spm_opt.model.params import MM
from spm_opt.problem.problem import Problem

RELATIVE_TOLERANCE = 0.005
"""The evaluator's allowance above every rate-type limit, as a fraction of the limit."""

DEFAULT_PATH_TOLERANCE_M = 0.1 * MM
"""How close the cut must pass each landmark, and how far it may backtrack, m, when the
problem sets no ``contour_tolerance_mm``."""

ROBOT = "robot"
CUT = "cut"


@dataclass(frozen=True)
class Rule:
    """How the evaluator judges one limit.

    Attributes
    ----------
    name : str
        The limit, as violations name it (a joint's limits add the joint: "theta1 speed").
    unit : str
        The unit of its values in reports.
    tolerance : float
        Allowance beyond the limit, a fraction of it (0: hard).
    judges : str
        "robot" (the machine's safety: checked before execution) or "cut" (the plan's cut).
    """

    name: str
    unit: str
    tolerance: float
    judges: str

    def allowed(self, limit: float, upper: bool = True) -> float:
        """The worst value that still passes: the limit plus (or, for a lower limit,
        minus) the tolerance."""
        slack = self.tolerance * abs(limit)
        return limit + slack if upper else limit - slack


RULES: dict[str, Rule] = {
    rule.name: rule
    for rule in (
        Rule("joint speed", "rad/s", RELATIVE_TOLERANCE, ROBOT),
        Rule("joint acceleration", "rad/s^2", RELATIVE_TOLERANCE, ROBOT),
        Rule("joint jerk", "rad/s^3", RELATIVE_TOLERANCE, ROBOT),
        Rule("acceleration step", "rad/s^2", RELATIVE_TOLERANCE, ROBOT),
        Rule("actuator torque", "N*m", RELATIVE_TOLERANCE, ROBOT),
        Rule("motor current", "A", RELATIVE_TOLERANCE, ROBOT),
        Rule("joint range", "deg", 0.0, ROBOT),
        Rule("singularity margin", "", 0.0, ROBOT),
        Rule("tool speed", "mm/s", RELATIVE_TOLERANCE, CUT),
        Rule("contour deviation", "mm", RELATIVE_TOLERANCE, CUT),
        Rule("landmark visit", "mm", RELATIVE_TOLERANCE, CUT),
        Rule("coverage", "mm", RELATIVE_TOLERANCE, CUT),
        Rule("backtracking", "mm", RELATIVE_TOLERANCE, CUT),
        Rule("tool incidence", "deg", RELATIVE_TOLERANCE, CUT),
        Rule("depth speed", "mm/s", RELATIVE_TOLERANCE, CUT),
        Rule("depth acceleration", "mm/s^2", RELATIVE_TOLERANCE, CUT),
        Rule("hold acceleration", "rad/s^2", RELATIVE_TOLERANCE, CUT),
        Rule("hold jerk", "rad/s^3", RELATIVE_TOLERANCE, CUT),
    )
}
"""Every limit the evaluator checks, by name."""

ROBOT_RULES = frozenset(name for name, rule in RULES.items() if rule.judges == ROBOT)
"""The rules that judge the robot (the machine's safety), by name."""


def tolerance_note() -> str:
    """One sentence for reports: the tolerance the evaluator allows."""
    return (
        f"A limit counts as violated when exceeded by more than "
        f"{100 * RELATIVE_TOLERANCE:g} % of it (the joint range and the singularity margin "
        "by any amount)."
    )


def contour_tube(problem: Problem, executed: bool = False) -> float | None:
    """The contour tolerance a cut is judged against, m (None: the problem sets none): a
    plan's is the problem's less its execution reserve, which is left for tracking; an
    executed cut (``executed``) may use the whole."""
    limits = problem.limits
    if limits.contour_tolerance is None:
        return None
    return limits.contour_tolerance - (0.0 if executed else limits.execution_reserve)


def path_tolerance(problem: Problem, executed: bool = False) -> float:
    """How close the cut must pass each landmark and how far it may backtrack, m: the
    contour tube (:func:`contour_tube`), or :data:`DEFAULT_PATH_TOLERANCE_M` when the
    problem sets no contour tolerance."""
    tube = contour_tube(problem, executed)
    return DEFAULT_PATH_TOLERANCE_M if tube is None else tube


@dataclass(frozen=True)
class PlannerBounds:
    """The problem's limits as a planner imposes them (SI), each rate-type limit less the
    planner's margin; ``None`` where the problem sets no limit.

    Attributes
    ----------
    joint_speed : float, rad/s
    joint_acceleration, joint_jerk : float or None, rad/s², rad/s³
        Less the room a feed hold needs, where the planner keeps it.
    tool_speed : float or None, m/s
    contour_tolerance : float or None, m
    load_torque : float, N·m
        Bound on the joint side |τ_load + J q̈ + f_v q̇ + f_c sign(q̇)| per joint, τ_load
        the model's inverse dynamics with
        friction (see the module docstring).
    joint_range : ndarray, shape (2, 2), rad
        [[low1, high1], [low2, high2]], hard: no margin.
    min_singularity_margin : float
        Hard: no margin.
    """

    joint_speed: float
    joint_acceleration: float | None
    joint_jerk: float | None
    tool_speed: float | None
    contour_tolerance: float | None
    load_torque: float
    joint_range: np.ndarray
    min_singularity_margin: float


def torque_limit(problem: Problem) -> float:
    """The largest torque the actuator may deliver, N·m: the problem's torque limit, or
    less if the continuous current gives less through the current map."""
    actuator = problem.robot.actuator
    at_current = float(actuator.current_map.torque(actuator.continuous_current_a))
    return min(problem.max_joint_torque, at_current)


def planner_bounds(problem: Problem, margin: float, *, hold_room: bool = True) -> PlannerBounds:
    """What a planner imposes for ``problem``'s limits, keeping ``margin`` (a fraction) of
    each rate-type limit in reserve; the joint acceleration and jerk also keep the room a
    feed hold needs (:func:`spm_opt.judge.hold_room.planner_room`) unless ``hold_room`` is False
    (a motion that cuts no contour: no hold keeps it on a path)."""
    limits, robot = problem.limits, problem.robot
    keep = 1.0 - margin
    acceleration, jerk = limits.max_joint_acceleration, limits.max_joint_jerk
    if hold_room:
        acceleration, jerk = planner_room(problem)

    def kept(value: float | None) -> float | None:
        return None if value is None else value * keep

    actuator = robot.actuator
    return PlannerBounds(
        joint_speed=limits.max_joint_speed * keep,
        joint_acceleration=kept(acceleration),
        joint_jerk=kept(jerk),
        tool_speed=kept(limits.max_tool_speed),
        contour_tolerance=kept(contour_tube(problem)),
        load_torque=actuator.gear_efficiency * torque_limit(problem) * keep,
        joint_range=np.asarray(robot.joint_range, dtype=float),
        min_singularity_margin=robot.min_singularity_margin,
    )
