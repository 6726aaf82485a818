"""Room for a feed hold: what a plan keeps so that a hold brings the tool to rest on its
path within the problem's bound, from any point of the plan.

A hold slows the executor's pace along the plan, the feed r = dτ/dt, from 1 to 0 (see
:mod:`spm_opt.execution.feed`). The joint motion it commands is q(τ(t)): acceleration
q″ r² + q′ ṙ and jerk q‴ r³ + 3 q″ r ṙ + q′ r̈, with q′, q″, q‴ the plan's own velocity,
acceleration and jerk at the point τ it has reached (q̇, q̈, q⃛ below).

The bound is a time, ``[limits] hold_within_s`` (T): a hold asked at full feed brings
the commanded motion to rest on the path within T. A time, not a distance: a stopping
distance bound forces the reserve to grow with the square of the speed (and caps the
speed outright), while a time bound asks for a reserve linear in it, the way a machine's
stopping time is specified (a category 2 stop). The distance then follows from the
speed the plan keeps: the reference stop below covers the path of half its duration at
full feed, 0.45 T v at tool speed v (1.35 mm at the paper's 3 mm/s and the default T).

**The reference stop.** ruckig's time-optimal change of r from 1 to 0 under |ṙ| ≤ R and
|r̈| ≤ Q: r̈ = −Q for R/Q, then ṙ = −R, then r̈ = +Q for R/Q; it lasts D = 1/R + R/Q. Its
two ramps take half of D (``RAMP_SHARE`` each), and D is ``STOP_SHARE`` of T (the rest
covers the control cycle a request waits for), so R = 4 / (3 D) and Q = 16 / (3 D²). From
a steady feed r₀ ≤ 1 the same change lasts less. Along it r ∈ [0, 1], ṙ ∈ [−R, 0],
r̈ ∈ [−Q, Q], and r |ṙ| ≤ P = R (1 − R²/(2Q)) (its largest: where ṙ reaches −R).

**What a plan keeps.** The commanded acceleration is linear in (r², ṙ), the jerk in
(r³, r ṙ, r̈): their largest magnitudes over those boxes are at the corners. So the stop
keeps the problem's limits A and J wherever the plan meets, per joint,

    acceleration: max(|q̈ − R q̇|, R |q̇|) ≤ A      (and |q̈| ≤ A, the limit's own rule)
    jerk:         max(|q⃛|, |q⃛ − 3P q̈|, 3P |q̈|) + Q |q̇| ≤ J

(q̇ along the plan's direction of travel). Met at every point, they let the stop start
anywhere: whatever point it has reached, the plan is there. The evaluator checks both on
its grid (:func:`hold_needs`; rules "hold acceleration" and "hold jerk", which judge the
cut: a hold without room ends in the safe stop, which keeps the machine safe but not the
tool on the path). A problem without an acceleration limit has no acceleration room to
keep, and the jerk room needs both limits (3P |q̈| is bounded only by A).

**What the planners keep** (:func:`planner_room`): a constant reserve, sufficient for both
conditions, at the fastest joint speed ω̂ a plan along the contour can reach (the joint
speed limit, or the tool-speed limit times the largest |dq/ds| along the contour where that
is less) and at their own acceleration bound:

    A_h = A − R ω̂,    J_h = J − 3P A_h − Q ω̂.

The default T is one second (:data:`spm_opt.problem.problem.DEFAULT_HOLD_WITHIN_S`): on the
paper's flap (ω̂ = 0.046 rad/s) it keeps 93 % of the acceleration and 63 % of the jerk, and
the time-optimal plans get 0.1–0.4 % slower; on the hardware problem (ω̂ at the 1.43 rad/s
speed limit) 79 % and 61 %, 9–20 % slower. At 0.5 s the hardware problem keeps 57 % and
20 % (toppra's plan 90 % slower), and below 0.4 s no jerk is left at all: a hold cannot be
much quicker than 3 A / J, the time to take the plan's whole acceleration away at the
jerk limit.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from spm_opt.base.errors import PlanningError
from spm_opt.problem.problem import Problem

STOP_SHARE = 0.9
"""Share of the bound the reference stop lasts; the rest covers the control cycle in which
a request waits (10 ms at 100 Hz) and the samples it is checked at."""

RAMP_SHARE = 0.25
"""Share of the reference stop each of its two jerk ramps takes: short ramps keep the
plans more acceleration, long ones more jerk (from 0.15 to 0.4 the hardware problem keeps
8.1 to 7.3 rad/s² and 57 to 65 rad/s³ of its 10 and 100)."""

_SLOPE_SAMPLES = 2001
_SLOPES: dict[tuple, float] = {}


@dataclass(frozen=True)
class HoldStop:
    """The reference stop of the feed from 1 to 0 (see the module docstring).

    Attributes
    ----------
    duration_s : float, s
        D, its length from full feed.
    rate_per_s : float, 1/s
        R, the largest |ṙ|.
    jerk_per_s2 : float, 1/s²
        Q, the largest |r̈|.
    """

    duration_s: float
    rate_per_s: float
    jerk_per_s2: float

    @property
    def peak_product_per_s(self) -> float:
        """P, the largest r |ṙ| along it, 1/s."""
        rate = self.rate_per_s
        return rate * (1.0 - rate**2 / (2.0 * self.jerk_per_s2))


def hold_stop(within_s: float) -> HoldStop:
    """The reference stop that ends within ``within_s`` (s) of a request."""
    duration = STOP_SHARE * within_s
    ramp = RAMP_SHARE * duration
    rate = 1.0 / (duration - ramp)
    return HoldStop(duration, rate, rate / ramp)


def hold_needs(
    stop: HoldStop, qd: np.ndarray, qdd: np.ndarray, jerk: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The largest joint acceleration (rad/s²) and jerk (rad/s³) the reference stop
    commands from samples of a plan's q̇, q̈, q⃛ (each (N, 2), SI), per sample and joint:
    the corners of the module docstring, beside the limits' own |q̈| and |q⃛|."""
    rate, product, rate_change = stop.rate_per_s, stop.peak_product_per_s, stop.jerk_per_s2
    acceleration = np.maximum(np.abs(qdd - rate * qd), rate * np.abs(qd))
    slowing = 3.0 * product * qdd
    corner = np.maximum.reduce([np.abs(jerk), np.abs(jerk - slowing), np.abs(slowing)])
    return acceleration, corner + rate_change * np.abs(qd)


def fastest_joint_speed(problem: Problem) -> float:
    """ω̂, rad/s: the fastest a joint turns on a plan along the contour, the joint speed
    limit or, where the tool-speed limit holds the joints slower, that limit times the
    largest |dq/ds| along the contour (sampled as :mod:`spm_opt.judge.bounds` samples it)."""
    limits = problem.limits
    if limits.max_tool_speed is None:
        return limits.max_joint_speed
    key = (problem.landmarks.tobytes(), problem.closed, problem.robot.upper_platform_radius)
    if key not in _SLOPES:
        slopes = []
        for start, end in pairwise(problem.contour.landmark_arc_lengths):
            s = np.linspace(start, end, _SLOPE_SAMPLES)
            slopes.append(np.max(np.abs(np.gradient(problem.contour_angles(s), s, axis=0))))
        _SLOPES[key] = float(max(slopes))
    return min(limits.max_joint_speed, _SLOPES[key] * limits.max_tool_speed)


def planner_room(problem: Problem) -> tuple[float | None, float | None]:
    """The joint acceleration (rad/s²) and jerk (rad/s³) bounds a planner keeps so that its
    plan leaves a hold its room: A_h and J_h of the module docstring, or the problem's
    limits where it sets no hold bound (None where it sets no limit).

    Raises
    ------
    PlanningError
        When the bound is too short for the limits to leave any motion.
    """
    limits = problem.limits
    acceleration, jerk = limits.max_joint_acceleration, limits.max_joint_jerk
    if limits.hold_within_s is None or acceleration is None:
        return acceleration, jerk
    stop = hold_stop(limits.hold_within_s)
    speed = fastest_joint_speed(problem)
    kept = acceleration - stop.rate_per_s * speed
    if jerk is not None:
        jerk -= 3.0 * stop.peak_product_per_s * kept + stop.jerk_per_s2 * speed
    if kept <= 0.0 or (jerk is not None and jerk <= 0.0):
        raise PlanningError(
            f"hold_within_s = {limits.hold_within_s:g}: a hold that quick leaves a plan no "
            "acceleration or jerk within the limits at the fastest joint speed along the "
            f"contour, {speed:.3g} rad/s; give a longer bound"
        )
    return kept, jerk


def hold_checks(
    problem: Problem, qd: np.ndarray, qdd: np.ndarray, jerk: np.ndarray
) -> list[tuple[str, str, np.ndarray, float]]:
    """What the evaluator judges of a plan's room for a hold, from samples of its q̇, q̈,
    q⃛ (each (N, 2), SI): (rule, label, values (N,), limit) for each joint, none where the
    problem sets no hold bound or no acceleration limit."""
    limits = problem.limits
    acceleration_limit, jerk_limit = limits.max_joint_acceleration, limits.max_joint_jerk
    if limits.hold_within_s is None or acceleration_limit is None:
        return []
    acceleration, jerk_need = hold_needs(hold_stop(limits.hold_within_s), qd, qdd, jerk)
    checks = []
    for joint in range(2):
        name = f"theta{joint + 1}"
        checks.append(
            (
                "hold acceleration",
                f"{name} hold acceleration",
                acceleration[:, joint],
                acceleration_limit,
            )
        )
        if jerk_limit is not None:
            checks.append(("hold jerk", f"{name} hold jerk", jerk_need[:, joint], jerk_limit))
    return checks
