"""A plan checked against its problem's limits in the tests, independently of the evaluator.

Only the plan's joint angles q(t) are read, on a uniform grid; everything else is computed
here: the rates by central differences, the cut points from forward kinematics and the
skull's radius, their distance from the great-circle arcs through the landmarks, the
progress along those arcs, and the actuators' torques from the exact Lagrange model at the
differenced rates (the optimal-control planners read a B-spline table of it instead).

Why the rate limits need no allowance for the differences: each central difference is a
weighted mean, with weights ≥ 0 that sum to one, of the derivative it estimates over the
stencil (a difference of q is the integral of q̇ over its interval, and the second and
third differences are such integrals of integrals), so it never exceeds the plan's own peak
nearby; it can only miss part of a peak, by about h × the next derivative (h = 1 ms: a
speed 0.001 rad/s below its peak at the paper's 1 rad/s², 0.07 % of its speed limit).
Rounding q to 1e-16 rad moves the third difference by at most 6 × 1e-16 / 2h³ = 3e-7 rad/s³.
So every rate-type limit is allowed exactly the evaluator's
:data:`~spm_opt.judge.limits.RELATIVE_TOLERANCE`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import spm_opt as so
from spm_opt.judge.limits import RELATIVE_TOLERANCE, contour_tube, path_tolerance, torque_limit
from spm_opt.model import dynamics, kinematics
from spm_opt.model.params import MM

RATE_HZ = 1000.0
"""The grid's rate, Hz (the evaluator's)."""
ALLOWED = 1.0 + RELATIVE_TOLERANCE
"""A rate-type limit, the tube and a landmark's tolerance are allowed this factor of
themselves: the evaluator's tolerance, no more."""
HELD = 2
"""Samples of rest added at each end: the robot holds still before and after the plan, and
the jerk's stencil reaches two steps, so a start or a stop that is not smooth reads as a
large jerk (a step Δ in q̈ at an end as Δ / 2h)."""
Radius = Callable[[np.ndarray], np.ndarray]
"""The skull's radius (N,), m, along unit directions (N, 3)."""


@dataclass(frozen=True)
class Exceeded:
    """A limit the plan breaks: its worst value, what was allowed, and when (s)."""

    limit: str
    worst: float
    allowed: float
    unit: str
    time: float

    def __str__(self) -> str:
        return (
            f"{self.limit}: {self.worst:.6g} {self.unit} at {self.time:.3f} s "
            f"(allowed {self.allowed:.6g})"
        )


@dataclass(frozen=True)
class Sampled:
    """q on a uniform grid and its central differences, each (N, 2), SI."""

    t: np.ndarray
    step: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    jerk: np.ndarray
    held: np.ndarray
    """q with :data:`HELD` samples of rest at each end, (N + 2 HELD, 2), rad."""


def sample(trajectory: so.Trajectory, rate_hz: float = RATE_HZ) -> Sampled:
    """The plan's q on a grid from its start to its end at about ``rate_hz``, and q̇, q̈
    and the jerk by central differences (at rest outside the plan)."""
    count = max(int(np.ceil(trajectory.duration * rate_hz)), 2)
    h = trajectory.duration / count
    t = trajectory.start_time + h * np.arange(count + 1)
    q = np.asarray(trajectory.position(t), dtype=float)
    held = np.concatenate([np.repeat(q[:1], HELD, axis=0), q, np.repeat(q[-1:], HELD, axis=0)])
    return Sampled(
        t=t,
        step=h,
        q=q,
        qd=central_difference(held, h),
        qdd=(held[3:-1] - 2.0 * held[2:-2] + held[1:-3]) / h**2,
        jerk=(held[4:] - 2.0 * held[3:-1] + 2.0 * held[1:-3] - held[:-4]) / (2.0 * h**3),
        held=held,
    )


def central_difference(held: np.ndarray, h: float) -> np.ndarray:
    """(x[k+1] − x[k−1]) / 2h at the samples of a series held :data:`HELD` samples at each
    end (the held ones excluded)."""
    return (held[3:-1] - held[1:-3]) / (2.0 * h)


def cut_points(q: np.ndarray, radius: Radius) -> np.ndarray:
    """Where the tool meets the skull for joint angles q (N, 2): points (N, 3), m."""
    p = kinematics.forward_kinematics(q, 1.0)
    return radius(p)[:, None] * p


@dataclass(frozen=True)
class OnContour:
    """Each cut point against the contour: its distance (N,), m, from its nearest point
    (by angle) on the great-circle arcs, and that point's progress (N,), rad of arc from
    the first landmark."""

    distance: np.ndarray
    progress: np.ndarray


def on_contour(problem: so.Problem, points: np.ndarray, radius: Radius) -> OnContour:
    """Distance and progress of cut points (N, 3), m, on the contour through the landmarks:
    |ρ(p) p − ρ(c) c| with c the point of the arcs nearest to p by angle."""
    units = problem.landmarks / np.linalg.norm(problem.landmarks, axis=1, keepdims=True)
    visits = units[problem.visit_order]
    start, end = visits[:-1], visits[1:]
    normal = np.cross(start, end)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    inplane = np.cross(normal, start)
    sweep = angle_between(start, end)
    p = points / np.linalg.norm(points, axis=1, keepdims=True)
    phi = np.arctan2(p @ inplane.T, p @ start.T)  # (N, arcs), along each arc from its start
    inside = (phi >= 0.0) & (phi <= sweep)
    to_start, to_end = (angle_between(p[:, None, :], ends[None]) for ends in (start, end))
    phi = np.where(inside, phi, np.where(to_start <= to_end, 0.0, sweep))
    nearest = np.cos(phi)[..., None] * start + np.sin(phi)[..., None] * inplane
    arc = np.argmin(angle_between(p[:, None, :], nearest), axis=1)
    rows = np.arange(len(p))
    c = nearest[rows, arc]
    progress = np.concatenate([[0.0], np.cumsum(sweep)])[arc] + phi[rows, arc]
    if problem.closed:  # the last landmark is the first: a step across it is no lap
        steps = np.diff(progress)
        steps -= sweep.sum() * np.round(steps / sweep.sum())
        progress = progress[0] + np.concatenate([[0.0], np.cumsum(steps)])
    distance = np.linalg.norm(points - radius(c)[:, None] * c, axis=1)
    return OnContour(distance, progress)


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle, rad, between unit vectors along the last axis (exact near 0, unlike arccos)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def violations(
    problem: so.Problem,
    trajectory: so.Trajectory,
    *,
    radius: Radius | None = None,
    landmark_tolerance: float | None = None,
    rate_hz: float = RATE_HZ,
) -> list[Exceeded]:
    """Every limit of ``problem`` that ``trajectory`` breaks, checked here.

    ``radius`` is the skull's (default: the problem's surface); ``landmark_tolerance``, m,
    how near each landmark visit must cut (default: the problem's path tolerance).
    """
    radius = problem.surface.radius if radius is None else radius
    motion = sample(trajectory, rate_hz)
    found = joint_violations(problem, motion) + rest_violations(problem, motion)
    found += torque_violations(problem, motion)
    found += cut_violations(problem, motion, radius)
    tolerance = path_tolerance(problem) if landmark_tolerance is None else landmark_tolerance
    return found + landmark_violations(problem, trajectory, radius, tolerance)


def assert_within_limits(
    problem: so.Problem,
    trajectory: so.Trajectory,
    *,
    radius: Radius | None = None,
    landmark_tolerance: float | None = None,
) -> None:
    """Fail, naming every limit broken, unless :func:`violations` finds none."""
    found = violations(problem, trajectory, radius=radius, landmark_tolerance=landmark_tolerance)
    assert not found, "the plan breaks:\n" + "\n".join(map(str, found))


def _upper(
    limit: str, values: np.ndarray, allowed: float | None, unit: str, t: np.ndarray
) -> list[Exceeded]:
    """The worst of ``values`` (N,) at times t (N,), if above ``allowed`` (None: none)."""
    worst = int(np.argmax(values))
    if allowed is None or values[worst] <= allowed:
        return []
    return [Exceeded(limit, float(values[worst]), allowed, unit, float(t[worst]))]


def _outside(
    limit: str, values: np.ndarray, low: float, high: float, t: np.ndarray
) -> list[Exceeded]:
    """The worst of ``values`` (N,), rad, at times t (N,) outside [low, high], in deg."""
    excess = np.maximum(values - high, low - values)
    worst = int(np.argmax(excess))
    if excess[worst] <= 0.0:
        return []
    bound = high if values[worst] > high else low
    degrees = np.degrees([values[worst], bound])
    return [Exceeded(limit, float(degrees[0]), float(degrees[1]), "deg", float(t[worst]))]


def _allowed(limit: float | None) -> float | None:
    return None if limit is None else limit * ALLOWED


def joint_violations(problem: so.Problem, motion: Sampled) -> list[Exceeded]:
    """Each joint's range (hard, at the samples: a peak between them is at most
    h²/8 × |q̈| = 1e-7 rad higher), speed, acceleration and jerk."""
    limits, t, found = problem.limits, motion.t, []
    for joint, (low, high) in enumerate(problem.robot.joint_range):
        name, q = f"theta{joint + 1}", motion.q[:, joint]
        found += _outside(f"{name} range", q, low, high, t)
        for label, values, limit, unit in (
            ("speed", motion.qd, limits.max_joint_speed, "rad/s"),
            ("acceleration", motion.qdd, limits.max_joint_acceleration, "rad/s^2"),
            ("jerk", motion.jerk, limits.max_joint_jerk, "rad/s^3"),
        ):
            found += _upper(f"{name} {label}", np.abs(values[:, joint]), _allowed(limit), unit, t)
    return found


def rest_violations(problem: so.Problem, motion: Sampled) -> list[Exceeded]:
    """q̇ at both ends, by second-order one-sided differences into the plan, within one
    velocity unit of the actuators (the least rate they can be commanded, 2.1e-4 rad/s);
    the differences' error, h²/3 × |jerk| = 3.3e-6 rad/s at 10 rad/s³, is far less."""
    q, h = motion.q, motion.step
    ends = {
        "start": (-3.0 * q[0] + 4.0 * q[1] - q[2]) / (2.0 * h),
        "end": (3.0 * q[-1] - 4.0 * q[-2] + q[-3]) / (2.0 * h),
    }
    unit = float(problem.robot.actuator.rate(1))
    times = {"start": motion.t[0], "end": motion.t[-1]}
    return [
        Exceeded(f"rest at the {end}", float(np.max(np.abs(rate))), unit, "rad/s", times[end])
        for end, rate in ends.items()
        if np.max(np.abs(rate)) > unit
    ]


def torque_violations(problem: so.Problem, motion: Sampled) -> list[Exceeded]:
    """The actuators' torque: the exact Lagrange model's load (sign friction) at the
    differenced q̇, q̈ through the actuator (rotor inertia, gear friction and efficiency),
    within the torque the problem and the continuous current allow. The differences
    stray from the plan's q̈ by at most h × |jerk| / 3 (3e-3 rad/s² at 10 rad/s³), a
    torque of 3e-5 N·m on this robot's joints (inertias below 0.01 kg·m²), against an
    allowance of 0.5 % of 14 N·m."""
    robot = problem.robot
    load = dynamics.inverse_dynamics(robot, motion.q, motion.qd, motion.qdd)
    torque = np.abs(robot.actuator.drive_torque(load, motion.qd, motion.qdd))
    allowed = torque_limit(problem) * ALLOWED
    return [
        item
        for joint in range(2)
        for item in _upper(f"theta{joint + 1} torque", torque[:, joint], allowed, "N*m", motion.t)
    ]


def cut_violations(problem: so.Problem, motion: Sampled, radius: Radius) -> list[Exceeded]:
    """The tool's speed (central differences of the cut point), the contour tube, and the
    cut running back along the contour: by no more than one encoder count of a joint moves
    it (1.2e-3 mm on the paper's skull), less than the robot resolves. (The problem would
    allow its path tolerance, 60 times more on the paper's flap; the plans' own wobble
    where the cut nearly stops is far less: 7e-6 mm, the minimum-energy plan of the
    hardware flap resting at A1.)"""
    limits, t = problem.limits, motion.t
    held = cut_points(motion.held, radius)
    speed = np.linalg.norm(central_difference(held, motion.step), axis=1)
    found = _upper("tool speed", speed / MM, _allowed(_in_mm(limits.max_tool_speed)), "mm/s", t)
    points = held[HELD:-HELD]
    contour = on_contour(problem, points, radius)
    tube = contour_tube(problem)
    found += _upper("contour tube", contour.distance / MM, _allowed(_in_mm(tube)), "mm", t)
    # the progress's angle as a length on the landmarks' largest radius (the arc length on
    # the skull to within its slope: a few per cent, nothing against the tolerance)
    skull = np.max(np.linalg.norm(problem.landmarks, axis=1))
    length = skull * contour.progress
    back = np.maximum.accumulate(length) - length
    allowed = skull * 2.0 * np.pi / problem.robot.actuator.pulses_per_rev
    return found + _upper("backtracking", back / MM, allowed / MM, "mm", t)


def _in_mm(value: float | None) -> float | None:
    return None if value is None else value / MM


def landmark_violations(
    problem: so.Problem, trajectory: so.Trajectory, radius: Radius, tolerance: float
) -> list[Exceeded]:
    """At each landmark visit the plan records, the cut point within ``tolerance``, m, of
    the landmark; the visits in order, within the plan."""
    times = trajectory.metadata.get("landmark_times_s")
    assert times is not None, "the plan records no landmark times"
    times = np.asarray(times, dtype=float)
    assert len(times) == len(problem.visit_order), f"{len(times)} landmark times"
    assert np.all(np.diff(times) > 0.0), f"landmark times {times} out of order"
    assert trajectory.start_time <= times[0] and times[-1] <= trajectory.end_time
    points = cut_points(trajectory.position(times), radius)
    errors = np.linalg.norm(points - problem.landmarks[problem.visit_order], axis=1)
    allowed = tolerance * ALLOWED
    return [
        Exceeded(f"landmark {problem.landmark_names[i]} visit", e / MM, allowed / MM, "mm", t)
        for i, e, t in zip(problem.visit_order, errors, times, strict=True)
        if e > allowed
    ]
