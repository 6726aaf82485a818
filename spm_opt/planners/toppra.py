"""Time-optimal motion along the planned contour (toppra), made jerk-limited.

Path. The contour has a corner at every landmark, so the cut stops there: each segment
between consecutive landmark visits is its own path, from rest to rest, and the segments are
chained. Along a segment the cut point's arc length s (mm, from the segment's first
landmark) parameterises the joint angles q(s): a cubic spline through the inverse kinematics
of ``path_samples`` points of the great-circle arc, exact at the landmarks. q varies on the
scale of the skull's radius (~70 mm), so 100 samples keep it within 1e-8 mm of the arc.

Limits, as toppra's linear constraints in the path acceleration u = s̈ and x = ṡ², at
``gridpoints`` points per segment (spaced as s ∝ ξ² at the ends, where the cut starts and
stops) and, by toppra's interpolation scheme, again at the next gridpoint:

- joint speed |q'| ṡ ≤ ω and tool speed k(s) ṡ ≤ v, with k the cut point's speed per unit
  ṡ as the contour measures it (ρ|ṗ| and ρ' φ̇): bounds on x;
- joint acceleration q̈ = q' u + q'' x within ±a;
- actuator torque from the one model, τ = (M + J)(q' u + q'' x) + h(q, q') x + g(q) + f:
  M the mass matrix, J the reflected rotor inertia, h(q, q') x the Coriolis and centrifugal
  torque (quadratic in q̇ = q' ṡ), g gravity with the payload, f the platforms' friction.
  The model's friction has a weight-only normal force and the sign of the sliding velocity,
  so for ṡ > 0 it does not depend on ṡ: f(q, q' ṡ) = f(q, q') is a constant per gridpoint,
  exact in toppra's form. Only where the sliding direction reverses between gridpoints is it
  bounded: each gridpoint's bound allows every friction value of it and its neighbours (and
  0, at rest, at the ends). The bound on |τ| is :mod:`spm_opt.limits`' load-torque bound
  (the gear efficiency and the continuous current taken into account there).

toppra works in σ = s / ℓ, ℓ the largest speed allowed (mm per s), so that σ̇ ≤ 1: with
ṡ² up to 1e4 mm²/s² its LP solver fails on the finest gridpoints.

Jerk. toppra's s̈ is constant between gridpoints; its steps would be steps of the joint
acceleration. Its ṡ(t), piecewise linear, is resampled on a uniform grid of ``time_step_s``
(each step's s̈ the mean of toppra's over it), then s(t) is replaced by its moving average
over a window T_w of whole steps. Then ṡ and s̈ are window averages of feasible ones,
s⃛ = (s̈(t) − s̈(t − T_w)) / T_w is bounded by the largest change of s̈ within a window over
T_w, the motion stays monotone, starts and ends at rest with zero acceleration, and lasts
T_w longer. T_w starts at a / j and is rescaled by the peak joint jerk of the averaged
motion, q⃛ = q' s⃛ + 3 q'' ṡ s̈ + q''' ṡ³, until it is the fewest steps within the limit.
Starting and stopping at joint acceleration a cost t_a = ω_c / a over the cruise (ω_c the
fastest joint's cruise speed at the segment's ends) and the average adds T_w ≈ a / j, least
in sum at a = √(ω_c j), where the averaged start is the jerk-limited time-optimal one (a
triangle of acceleration): toppra is given that acceleration, or the limit if lower.

No limit is trusted to these arguments: the smoothed motion is measured (speeds,
acceleration, torque with exact friction) and toppra runs again with the share of any
exceeded limit cut by the excess; acceleration, torque and jerk keep ``margin`` in reserve
from the start. The acceleration and jerk are the bounds that keep a feed hold its room
(:func:`spm_opt.limits.planner_bounds`, :mod:`spm_opt.hold_room`).

Trajectory. The averaged s(t) is one cubic per grid step, so samples at every grid time
with q, q̇ = q' ṡ and q̈ = q' s̈ + q'' ṡ² carry every knot, and the quintic Hermite pieces
through them have the motion's jerk. Landmark visits are the segments' ends, at rest.

Guess. :func:`time_optimal_guess` is the start of the minimum-time optimal control, in
milliseconds: the first toppra run of every segment with the same limits and shares, on a
coarse grid (``GUESS_GRIDPOINTS`` gridpoints, a path through ``GUESS_PATH_SAMPLES``
samples; the model evaluated once for all segments), and toppra's own motion (no uniform
time grid) averaged once over the first window, max(a / j, ``min_smoothing_s``). Left out:
the rescaling of the window by the measured jerk, the measuring of the smoothed motion and
the runs with tighter shares, so the guess may exceed a limit by a little (the speeds by
what the average and the coarse grid add, the jerk by what the window's first estimate
misses). Its segments start and end at rest and last within 0.5 % of the plan's where the
jerk is limited; without a jerk limit toppra's ramps last a few ms, which the plan's time
grid cuts at a cost the guess does not pay (its 0.25 s segments of the hardware problem
are 0.7–1.4 % shorter than the plan's, within 0.5 % of toppra's on the fine grid).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline, PPoly

from spm_opt.errors import PlanningError
from spm_opt.limits import planner_bounds, torque_limit
from spm_opt.model import dynamics
from spm_opt.model.params import MM
from spm_opt.planners.registry import planner_options, register, settings_from_options
from spm_opt.problem import Problem
from spm_opt.trajectory import MAX_DURATION_S, Trajectory

_JERK_ITERATIONS = 8
"""Rescalings of the moving-average window before giving up."""
_ATTEMPTS = 4
"""toppra runs per segment, each with tighter shares of the limits the last one exceeded."""
_SPEED_SLACK = 1e-4
"""Relative excess of a speed limit left to rounding; shares are cut this much below it."""
GUESS_GRIDPOINTS = 30
"""toppra's gridpoints per segment in :func:`time_optimal_guess` (the planner's: 800):
enough to keep the guess's segments within 0.5 % of the plan's (20 are not: 1.2 %)."""
GUESS_PATH_SAMPLES = 30
"""Inverse-kinematics samples per segment of the guess's path (the planner's: 100)."""
_MERGED = 1e-3
"""Knots of the averaged motion closer than this fraction of the window to the one before
are not sampled: a sliver between two samples would give the quintic pieces a jerk of
rounding errors over its length cubed."""


@dataclass(frozen=True)
class ToppraSettings:
    """Discretisation settings, read from the problem's ``[planner.toppra]`` table.

    Attributes
    ----------
    gridpoints : int
        toppra's gridpoints per segment (clustered at the segment's ends).
    path_samples : int
        Inverse-kinematics samples per segment through which the joint-space spline runs.
    margin : float
        Fraction of the acceleration, torque and jerk limits kept in reserve for what the
        moving average and the gridding change.
    time_step_s : float
        Step of the uniform time grid on which the path acceleration is piecewise constant
        and the trajectory is sampled, s; the moving-average window is a whole number of
        steps.
    min_smoothing_s : float
        Shortest moving-average window, s: the only smoothing when jerk is not limited (a
        step in s̈ would be a step in the joint acceleration).
    """

    gridpoints: int = 800
    path_samples: int = 100
    margin: float = 0.01
    time_step_s: float = 0.005
    min_smoothing_s: float = 0.01

    _RANGES = {
        "gridpoints": (10, 100_000),
        "path_samples": (4, 100_000),
        "margin": (0.0, 0.5),
        "time_step_s": (1e-4, 0.1),
        "min_smoothing_s": (1e-4, 10.0),
    }

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> ToppraSettings:
        """Settings from a ``[planner.toppra]`` table over the defaults; one-line errors."""
        return settings_from_options("toppra", cls(), options, cls._RANGES)


OPTION_KEYS = tuple(f.name for f in dataclasses.fields(ToppraSettings))


@dataclass(frozen=True)
class _Segment:
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


def _segments(problem: Problem, samples: int) -> list[_Segment]:
    """Every segment's path, each through ``samples`` points of its arc (their inverse
    kinematics in one call)."""
    names, angles = problem.visit_names, problem.waypoint_angles
    ends = problem.contour.landmark_arc_lengths
    count = len(problem.segment_durations)
    s = [np.linspace(0.0, ends[k + 1] - ends[k], samples) for k in range(count)]
    arc = np.concatenate([ends[k] + s[k] for k in range(count)])
    q = np.split(problem.contour_angles(arc), count)
    for k in range(count):
        q[k][0], q[k][-1] = angles[k], angles[k + 1]
    return [
        _Segment(f"{names[k]}→{names[k + 1]}", CubicSpline(s[k] / MM, q[k])) for k in range(count)
    ]


def _gridpoints(length: float, count: int) -> np.ndarray:
    """``count`` gridpoints on [0, length] spaced as s ∝ ξ² at both ends (smoothstep)."""
    xi = np.linspace(0.0, 1.0, count)
    return length * xi**2 * (3.0 - 2.0 * xi)


@dataclass(frozen=True)
class _Shares:
    """The share of each limit given to toppra (1: the limit itself). The speeds start at
    1 (a moving average of feasible speeds stays feasible where the bound is flat); the
    acceleration and torque keep the settings' margin. Whatever the smoothed motion still
    exceeds is cut by the excess, and toppra runs again."""

    joint_speed: float = 1.0
    tool_speed: float = 1.0
    acceleration: float = 1.0
    torque: float = 1.0

    def tightened(self, excess: dict[str, float]) -> _Shares:
        """Each share in ``excess`` (limit name: peak / limit) divided by its excess."""
        cut = {k: getattr(self, k) / ratio * (1.0 - _SPEED_SLACK) for k, ratio in excess.items()}
        return dataclasses.replace(self, **cut)


@dataclass(frozen=True)
class _Constraints:
    """Every limit at N gridpoints as low ≤ a u + b x + c ≤ high, and x ≤ x_max, with u in
    mm/s² and x in mm²/s²: arrays (N, m), one column per row of ``rows`` ((what, unit)),
    whose nominal bound is ``limit`` (m,)."""

    rows: tuple[tuple[str, str], ...]
    limit: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    low: np.ndarray
    high: np.ndarray
    x_max: np.ndarray

    def per_unit(self, unit: float) -> _Constraints:
        """The same limits for the path parameter s / unit (unit in mm)."""
        return dataclasses.replace(
            self, a=self.a * unit, b=self.b * unit**2, x_max=self.x_max / unit**2
        )

    def at_rest(self, index: int) -> list[str]:
        """The rows that fail with the path at rest (u = x = 0) at gridpoint ``index``, in
        words: what they need there against their bound."""
        c, low, high = self.c[index], self.low[index], self.high[index]
        need = self.limit + np.maximum(c - high, low - c)
        return [
            f"{what} {need[k]:.4g} {unit} (allowed {self.limit[k]:.4g} {unit})"
            for k, (what, unit) in enumerate(self.rows)
            if need[k] > self.limit[k]
        ]


@dataclass(frozen=True)
class _PathPoints:
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

    def __getitem__(self, index: slice) -> _PathPoints:
        """The points ``index`` selects."""
        return _PathPoints(*(getattr(self, f.name)[index] for f in dataclasses.fields(self)))


def path_points(problem: Problem, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> _PathPoints:
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
    return _PathPoints(
        q,
        dq,
        ddq,
        mass + rotor * np.eye(2),
        moving - gravity,
        gravity,
        dynamics.friction_torque(robot, q, dq),
    )


def _friction_range(friction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest friction torque (N, 2) over each gridpoint and its neighbours,
    and 0 (at rest) at the two ends."""
    padded = np.concatenate([friction[:1], friction, friction[-1:]])
    near = np.stack([padded[:-2], padded[1:-1], padded[2:]])
    low, high = near.min(axis=0), near.max(axis=0)
    low[[0, -1]] = np.minimum(low[[0, -1]], 0.0)
    high[[0, -1]] = np.maximum(high[[0, -1]], 0.0)
    return low, high


def _speed_bound(problem: Problem, q: np.ndarray, dq: np.ndarray, shares: _Shares) -> np.ndarray:
    """Largest ṡ², mm²/s², at joint angles q (N, 2) with path tangents q' (N, 2), rad/mm:
    each joint within its speed limit and the cut point within the tool-speed limit."""
    bounds = planner_bounds(problem, 0.0)
    pace = np.max(np.abs(dq), axis=1) / (bounds.joint_speed * shares.joint_speed)  # s/mm
    if bounds.tool_speed is not None:
        stretch = problem.contour.joint_tool_speed(q, dq) / MM
        pace = np.maximum(pace, stretch / (bounds.tool_speed / MM * shares.tool_speed))
    return 1.0 / pace**2


def _constraints(
    problem: Problem,
    points: _PathPoints,
    x_max: np.ndarray,
    acceleration: float | None,
    shares: _Shares,
) -> _Constraints:
    """The limits at one segment's gridpoints (``points``), with x_max (N,) their largest
    ṡ², mm²/s², and ``acceleration`` the joint acceleration bound given to toppra, rad/s²
    (None: unlimited)."""
    q, dq, ddq = points.q, points.dq, points.ddq
    friction_low, friction_high = _friction_range(points.friction)
    torque = planner_bounds(problem, 0.0).load_torque * shares.torque
    rows = (("actuator 1 torque", "N·m"), ("actuator 2 torque", "N·m"))
    limit = np.full(2, torque)
    a = np.einsum("nij,nj->ni", points.inertia, dq)
    b = np.einsum("nij,nj->ni", points.inertia, ddq) + points.bias
    c = points.gravity
    low, high = -torque - friction_low, torque - friction_high
    if acceleration is not None:
        rows += (("theta1 acceleration", "rad/s²"), ("theta2 acceleration", "rad/s²"))
        limit = np.append(limit, [acceleration, acceleration])
        a, b, c = np.hstack([a, dq]), np.hstack([b, ddq]), np.hstack([c, np.zeros_like(c)])
        low, high = (
            np.hstack([low, np.full_like(q, -acceleration)]),
            np.hstack([high, np.full_like(q, acceleration)]),
        )
    return _Constraints(rows, limit, a, b, c, low, high, x_max)


@cache
def _path_limits_class() -> type:
    """toppra's constraint interface over :class:`_Constraints`, built on first use (toppra
    is imported lazily: its algorithm module imports matplotlib)."""
    from toppra.constraint import (
        DiscretizationType,
        LinearConstraint,
        canlinear_colloc_to_interpolate,
    )

    class PathLimits(LinearConstraint):
        """Precomputed coefficients, imposed in toppra's interpolation scheme."""

        def __init__(self, limits: _Constraints) -> None:
            super().__init__()
            self.limits = limits
            self.set_discretization_type(DiscretizationType.Interpolation)

        def compute_constraint_params(self, path: Any, gridpoints: np.ndarray) -> tuple:
            k = self.limits
            m = k.a.shape[1]
            f = np.broadcast_to(np.vstack([np.eye(m), -np.eye(m)]), (len(gridpoints), 2 * m, m))
            g = np.hstack([k.high, -k.low])
            a, b, c, f, g, _, _ = canlinear_colloc_to_interpolate(
                k.a, k.b, k.c, f, g, None, None, gridpoints, identical=False
            )
            xbound = np.column_stack([np.zeros_like(k.x_max), k.x_max])
            return a, b, c, f, g, None, xbound  # toppra's order: ..., ubound, xbound

    return PathLimits


@dataclass(frozen=True)
class _Span:
    """All that toppra's algorithm reads of a path whose constraints come precomputed: the
    range of its parameter (a spline through the path would only cost its construction)."""

    path_interval: np.ndarray


def _check_rest(problem: Problem, segment: int, limits: _Constraints) -> None:
    """Refuse a segment at whose end landmarks the robot cannot be held still (every segment
    starts and ends at rest)."""
    names = problem.visit_names
    for index, landmark in ((0, names[segment]), (-1, names[segment + 1])):
        failing = limits.at_rest(index)
        if failing:
            raise PlanningError(
                f"max_joint_torque_nm = {problem.max_joint_torque:g}: holding the robot still "
                f"at {landmark} against gravity and friction takes {'; '.join(failing)}"
            )


def _parameterise(segment: _Segment, s: np.ndarray, limits: _Constraints) -> np.ndarray:
    """toppra's time-optimal path speeds ṡ (N,), mm/s, at gridpoints s (N,), mm, from rest
    to rest; a PlanningError naming the place and the likely culprit if it fails.

    toppra works in the path parameter σ = s / ℓ with ℓ, mm, the largest speed allowed in
    1 s: then σ̇² ≤ 1, which keeps its LPs well scaled (with s in mm and ṡ² up to 1e4
    mm²/s², its solver fails on the finest gridpoints).
    """
    import toppra
    from toppra.algorithm import ParameterizationReturnCode

    unit = math.sqrt(float(np.max(limits.x_max)))
    gridpoints = s / unit
    instance = toppra.algorithm.TOPPRA(
        [_path_limits_class()(limits.per_unit(unit))],
        _Span(gridpoints[[0, -1]]),
        gridpoints=gridpoints,
        solver_wrapper="seidel",
    )
    _, speed, _, controllable = instance.compute_parameterization(0.0, 0.0, return_data=True)
    code = instance.problem_data.return_code
    if code == ParameterizationReturnCode.Ok and np.all(np.isfinite(speed)):
        return np.asarray(speed, dtype=float) * unit
    lost = np.flatnonzero(np.any(np.isnan(controllable), axis=1))
    raise PlanningError(_failure(code.value, segment, s, limits, int(lost[-1]) if lost.size else 0))


def _failure(code: str, segment: _Segment, s: np.ndarray, limits: _Constraints, where: int) -> str:
    """toppra's failure in words: where on the segment, and the likely culprit."""
    failing = limits.at_rest(where)
    culprit = (
        f"there, gravity and friction alone need {'; '.join(failing)}"
        if failing
        else "no limit fails there at rest: the joint acceleration and actuator torque "
        "limits together leave no path acceleration that keeps the motion going"
    )
    return (
        f"toppra: {code} in segment {segment.name} at {s[where]:.4g} mm of "
        f"{segment.length:.4g} mm; {culprit}"
    )


def _toppra_steps(s: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Durations (N - 1,), s, of toppra's steps between gridpoints s (N,), mm, at its path
    speeds (N,), mm/s (the path acceleration constant on each); a PlanningError where the
    motion stalls or would last more than ``MAX_DURATION_S``."""
    durations = 2.0 * np.diff(s) / (speed[:-1] + speed[1:])
    if not np.all(np.isfinite(durations)):
        raise PlanningError("toppra: the path speed is zero between two gridpoints")
    total = float(np.sum(durations))
    if total > MAX_DURATION_S:
        raise PlanningError(
            f"toppra: a segment would last {total:.4g} s, more than {MAX_DURATION_S:g} s; "
            "are the limits in their units?"
        )
    return durations


def _path_profile(steps: np.ndarray, speed: np.ndarray, start: np.ndarray, end: float) -> PPoly:
    """s(t), mm, over consecutive ``steps`` (M,), s, from t = 0: from ``start`` (M,), mm,
    at each step's start, at path speeds ``speed`` (M + 1,), mm/s, at the steps' ends, with
    a constant path acceleration on each step. At rest, at 0 before and at ``end``, mm,
    after (extrapolated so)."""
    times = np.concatenate([[0.0], np.cumsum(steps)])
    zero = np.zeros(1)
    coefficients = np.vstack(
        [
            np.concatenate([zero, np.diff(speed) / steps / 2.0, zero]),
            np.concatenate([zero, speed[:-1], zero]),
            np.concatenate([zero, start, [end]]),
        ]
    )
    return PPoly(coefficients, np.concatenate([[-1.0], times, [times[-1] + 1.0]]))


def _uniform_profile(s: np.ndarray, speed: np.ndarray, step: float) -> PPoly:
    """s(t), mm, on a uniform time grid of about ``step`` s, from toppra's path speeds (N,),
    mm/s, at gridpoints s (N,), mm.

    toppra's motion has a constant s̈ between gridpoints, so ṡ is piecewise linear in time;
    it is sampled at the grid's times and joined linearly again (each step's s̈ is the mean
    of toppra's over that step). Where that cuts a corner of ṡ(t) the path would end short
    (by parts per million here), so the grid is stretched in time until it ends exactly at
    the path's end: the speeds stay toppra's, the accelerations shrink. At rest, and
    extrapolated so, before 0 and after the end.
    """
    knots = np.concatenate([[0.0], np.cumsum(_toppra_steps(s, speed))])
    times = np.linspace(0.0, knots[-1], max(1, math.ceil(knots[-1] / step)) + 1)
    rate = np.interp(times, knots, speed)
    rate[[0, -1]] = 0.0
    steps = np.diff(times) * s[-1] / np.trapezoid(rate, times)
    distance = np.concatenate([[0.0], np.cumsum(steps * (rate[:-1] + rate[1:]) / 2.0)])
    return _path_profile(steps, rate, distance[:-1], float(s[-1]))


def _moving_average(profile: PPoly, width: float, t: np.ndarray) -> list[np.ndarray]:
    """The moving average of s(t) (``profile``, mm) over ``width`` s, s_w(t) = (1/T_w) ∫ s
    over [t − T_w, t], and its derivatives at times t (N,): s_w, ṡ_w, s̈_w and s⃛_w in mm,
    mm/s, mm/s², mm/s³."""
    integral = profile.antiderivative()
    values = [(integral(t) - integral(t - width)) / width]
    for order in range(3):
        derivative = profile.derivative(order) if order else profile
        values.append((derivative(t) - derivative(t - width)) / width)
    return values


@dataclass(frozen=True)
class _Averaged:
    """The moving average of s(t) over ``window`` grid steps: s_w(t) = (1/T_w) ∫ s over
    [t − T_w, t]. It is one cubic on each step, from 0 to the profile's end plus T_w."""

    profile: PPoly
    window: int

    @property
    def step(self) -> float:
        """Length of a grid step, s."""
        return float(self.profile.x[2] - self.profile.x[1])

    @property
    def times(self) -> np.ndarray:
        """The grid's times, s: every knot of s_w."""
        steps = len(self.profile.x) - 3 + self.window
        return np.linspace(0.0, self.profile.x[-2] + self.window * self.step, steps + 1)

    def __call__(self, t: np.ndarray) -> list[np.ndarray]:
        """s_w, ṡ_w, s̈_w and s⃛_w at times t (N,): mm, mm/s, mm/s², mm/s³."""
        return _moving_average(self.profile, self.window * self.step, t)


def _peak_jerk(segment: _Segment, motion: _Averaged) -> float:
    """Largest joint jerk, rad/s³, of the averaged motion: q⃛ = q' s⃛ + 3 q'' ṡ s̈ + q''' ṡ³,
    in the middle of every grid step (s⃛ is constant on each)."""
    t = motion.times
    s, sd, sdd, sddd = motion((t[:-1] + t[1:]) / 2.0)
    _, dq, ddq, dddq = segment.derivatives(s, orders=4)
    jerk = dq * sddd[:, None] + 3.0 * ddq * (sd * sdd)[:, None] + dddq * sd[:, None] ** 3
    return float(np.max(np.abs(jerk)))


def _smoothed(
    segment: _Segment, profile: PPoly, first: float, jerk: float | None, shortest: float
) -> _Averaged:
    """The moving average whose peak joint jerk is within ``jerk``, rad/s³ (None: the
    ``shortest`` window, s): from ``first`` s, the window is rescaled by the measured peak
    jerk (which falls as 1 / window) until it is the fewest grid steps that fit."""
    step = float(profile.x[2] - profile.x[1])
    fewest = max(1, math.ceil(shortest / step * (1.0 - 1e-3)))
    window = max(fewest, math.ceil(first / step * (1.0 - 1e-3)))
    fits, too_short = None, 0
    for _ in range(_JERK_ITERATIONS):
        motion = _Averaged(profile, window)
        if jerk is None:
            return motion
        peak = _peak_jerk(segment, motion)
        if peak <= jerk:
            fits = motion
        else:
            too_short = max(too_short, window)
        window = max(fewest, too_short + 1, math.ceil(window * peak / jerk - 1e-9))
        if fits is not None and window >= fits.window:
            return fits
    if fits is not None:
        return fits
    raise PlanningError(
        f"toppra: segment {segment.name}: no moving-average window found that keeps the "
        f"joint jerk within {jerk:g} rad/s³ (last {window * step:.4g} s, peak {peak:.4g})"
    )


def _toppra_acceleration(
    problem: Problem, dq: np.ndarray, x_max: np.ndarray, shares: _Shares, jerk: float | None
) -> float | None:
    """The joint acceleration bound, rad/s², given to toppra: the limit, or less where the
    jerk limit (rad/s³, None: unlimited) makes a gentler start faster (a = √(ω_c j), see
    the module docstring), with ω_c from the path tangents q' (2, 2), rad/mm, and the
    largest ṡ² (2,), mm²/s², at the segment's two ends."""
    limit = planner_bounds(problem, 0.0).joint_acceleration
    bound = None if limit is None else limit * shares.acceleration
    if jerk is None:
        return bound
    cruise = float(np.max(np.abs(dq) * np.sqrt(x_max)[:, None]))
    gentle = math.sqrt(cruise * jerk)
    return gentle if bound is None else min(bound, gentle)


@dataclass(frozen=True)
class _Piece:
    """One segment's motion: samples (t from 0, s; q, qd, qdd (n, 2), SI) and figures."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    toppra_duration: float
    window: float
    acceleration: float | None
    runs: int = 1


def _jerk_bound(problem: Problem, settings: ToppraSettings) -> float | None:
    """The joint jerk the smoothing keeps within, rad/s³ (None: unlimited)."""
    limit = planner_bounds(problem, 0.0).joint_jerk
    return None if limit is None else limit * (1.0 - settings.margin)


def _toppra_limits(
    problem: Problem,
    index: int,
    points: _PathPoints,
    x_max: np.ndarray,
    shares: _Shares,
    jerk: float | None,
) -> tuple[_Constraints, float | None]:
    """The limits toppra gets on segment ``index`` at its gridpoints (``points``, with
    their largest ṡ² x_max (N,), mm²/s²), once the robot is known to rest at its ends; and
    the joint acceleration bound among them, rad/s² (None: unlimited)."""
    ends = [0, -1]
    acceleration = _toppra_acceleration(problem, points.dq[ends], x_max[ends], shares, jerk)
    limits = _constraints(problem, points, x_max, acceleration, shares)
    _check_rest(problem, index, limits)
    return limits, acceleration


def _joint_samples(
    problem: Problem, index: int, segment: _Segment, s: np.ndarray, sd: np.ndarray, sdd: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, q̇, q̈ (N, 2), SI, along segment ``index`` at path positions s (N,), mm, speeds ṡ
    (N,), mm/s, and accelerations s̈ (N,), mm/s², from its first landmark to its last, both
    at rest and exact."""
    q, dq, ddq = segment.derivatives(s)
    q[[0, -1]] = problem.waypoint_angles[index : index + 2]
    qd = dq * sd[:, None]
    qdd = dq * sdd[:, None] + ddq * sd[:, None] ** 2
    qd[[0, -1]] = qdd[[0, -1]] = 0.0
    return q, qd, qdd


def _attempt(
    problem: Problem,
    index: int,
    segment: _Segment,
    s: np.ndarray,
    points: _PathPoints,
    settings: ToppraSettings,
    shares: _Shares,
) -> _Piece:
    """toppra on one segment at gridpoints s (N,), mm (``points`` there) within ``shares``
    of the limits, then smoothed and sampled."""
    jerk = _jerk_bound(problem, settings)
    x_max = _speed_bound(problem, points.q, points.dq, shares)
    limits, acceleration = _toppra_limits(problem, index, points, x_max, shares, jerk)
    profile = _uniform_profile(s, _parameterise(segment, s, limits), settings.time_step_s)
    first = 0.0 if jerk is None or acceleration is None else acceleration / jerk
    motion = _smoothed(segment, profile, first, jerk, settings.min_smoothing_s)
    t = motion.times
    path_s, sd, sdd, _ = motion(t)
    q, qd, qdd = _joint_samples(problem, index, segment, path_s, sd, sdd)
    return _Piece(t, q, qd, qdd, float(profile.x[-2]), motion.window * motion.step, acceleration)


def _excess(problem: Problem, piece: _Piece) -> dict[str, float]:
    """The limits the sampled motion exceeds (beyond ``_SPEED_SLACK`` for the speeds), by
    name: peak / limit. Torques from the model with exact friction, as the actuators
    deliver them."""
    limits, robot = problem.limits, problem.robot
    acceleration = planner_bounds(problem, 0.0).joint_acceleration
    torque = dynamics.actuator_torque(robot, piece.q, piece.qd, piece.qdd)
    peaks = {
        "joint_speed": (np.max(np.abs(piece.qd)) / limits.max_joint_speed, _SPEED_SLACK),
        "torque": (np.max(np.abs(torque)) / torque_limit(problem), 0.0),
    }
    if limits.max_tool_speed is not None:
        speed = problem.contour.joint_tool_speed(piece.q, piece.qd)
        peaks["tool_speed"] = (np.max(speed) / limits.max_tool_speed, _SPEED_SLACK)
    if acceleration is not None:
        peaks["acceleration"] = (np.max(np.abs(piece.qdd)) / acceleration, 0.0)
    return {name: float(peak) for name, (peak, slack) in peaks.items() if peak > 1.0 + slack}


def _first_shares(settings: ToppraSettings) -> _Shares:
    """The shares of the limits toppra gets first: the acceleration and torque keep the
    settings' margin."""
    keep = 1.0 - settings.margin
    return _Shares(acceleration=keep, torque=keep)


def _segment_motion(
    problem: Problem, index: int, segment: _Segment, settings: ToppraSettings
) -> _Piece:
    """The motion along segment ``index`` within every limit: toppra and smoothing, again
    with tighter shares of whatever limit the smoothed motion still exceeds."""
    s = _gridpoints(segment.length, settings.gridpoints)
    points = path_points(problem, *segment.derivatives(s))
    shares = _first_shares(settings)
    for run in range(1, _ATTEMPTS + 1):
        piece = _attempt(problem, index, segment, s, points, settings, shares)
        excess = _excess(problem, piece)
        if not excess:
            return dataclasses.replace(piece, runs=run)
        shares = shares.tightened(excess)
    worst = ", ".join(f"{name} {ratio:.4g} times its limit" for name, ratio in excess.items())
    raise PlanningError(
        f"toppra: segment {segment.name}: the smoothed motion still reaches {worst} after "
        f"{_ATTEMPTS} attempts with tighter limits; raise planner.toppra.margin"
    )


def _chain(
    pieces: list[_Piece], starts: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The segments' samples one after the other, each from its start time (s); the landmark
    between two segments (at rest in both) once."""
    t = [pieces[0].t[:1]] + [p.t[1:] + start for p, start in zip(pieces, starts, strict=True)]
    q, qd, qdd = (
        np.vstack([getattr(pieces[0], name)[:1]] + [getattr(p, name)[1:] for p in pieces])
        for name in ("q", "qd", "qdd")
    )
    return np.concatenate(t), q, qd, qdd


def time_optimal_guess(problem: Problem) -> Trajectory:
    """A near-time-optimal motion along the contour, at rest at every landmark, in a few
    milliseconds: the start for the minimum-time optimal control (see the module docstring,
    Guess). Its metadata has ``landmark_times_s`` (s), ``landmarks`` and ``statistics``.

    Raises
    ------
    PlanningError
        Where the toppra planner's first run fails (the same messages).
    """
    settings = ToppraPlanner().settings(problem)
    started = time.perf_counter()
    pieces = _rough_pieces(problem, settings)
    durations = np.array([piece.t[-1] for piece in pieces])
    starts = np.concatenate([[0.0], np.cumsum(durations)])
    samples = _chain(pieces, starts[:-1])
    statistics = {
        "solve_time_s": time.perf_counter() - started,
        "gridpoints": GUESS_GRIDPOINTS,
        "samples": int(samples[0].size),
        "segment_durations_s": durations.tolist(),
        "toppra_durations_s": [piece.toppra_duration for piece in pieces],
        "smoothing_windows_s": [piece.window for piece in pieces],
        "toppra_accelerations_rad_s2": [piece.acceleration for piece in pieces],
    }
    metadata = {
        "landmark_times_s": starts.tolist(),
        "landmarks": problem.visit_names,
        "statistics": statistics,
    }
    return Trajectory.from_samples(*samples, metadata=metadata)


def _rough_pieces(problem: Problem, settings: ToppraSettings) -> list[_Piece]:
    """Every segment's motion for the guess: toppra on the coarse grid within the first
    shares of the limits, averaged over the first window; the model evaluated once for all
    segments."""
    shares, jerk = _first_shares(settings), _jerk_bound(problem, settings)
    segments = _segments(problem, GUESS_PATH_SAMPLES)
    grids = [_gridpoints(segment.length, GUESS_GRIDPOINTS) for segment in segments]
    derivatives = [segment.derivatives(s) for segment, s in zip(segments, grids, strict=True)]
    points = path_points(problem, *(np.vstack(order) for order in zip(*derivatives, strict=True)))
    x_max = _speed_bound(problem, points.q, points.dq, shares)
    pieces = []
    for k, (segment, s) in enumerate(zip(segments, grids, strict=True)):
        part = slice(k * GUESS_GRIDPOINTS, (k + 1) * GUESS_GRIDPOINTS)
        limits, acceleration = _toppra_limits(problem, k, points[part], x_max[part], shares, jerk)
        first = 0.0 if jerk is None or acceleration is None else acceleration / jerk
        width = max(first, settings.min_smoothing_s)
        pieces.append(_rough_piece(problem, k, segment, s, limits, acceleration, width))
    return pieces


def _rough_piece(
    problem: Problem,
    index: int,
    segment: _Segment,
    s: np.ndarray,
    limits: _Constraints,
    acceleration: float | None,
    width: float,
) -> _Piece:
    """toppra's motion along segment ``index`` at gridpoints s (N,), mm, within ``limits``
    (``acceleration`` the joint acceleration bound among them, rad/s²), averaged over
    ``width`` s and sampled at every knot of the average."""
    speed = _parameterise(segment, s, limits)
    profile = _path_profile(_toppra_steps(s, speed), speed, s[:-1], float(s[-1]))
    t = _average_knots(profile.x[1:-1], width)
    path_s, sd, sdd, _ = _moving_average(profile, width, t)
    q, qd, qdd = _joint_samples(problem, index, segment, path_s, sd, sdd)
    return _Piece(t, q, qd, qdd, float(profile.x[-2]), width, acceleration)


def _average_knots(knots: np.ndarray, width: float) -> np.ndarray:
    """The times, s, where the average over ``width`` s of a motion with ``knots`` (M,), s,
    from 0, changes its cubic: the knots and the knots + width, from 0 to the end, without
    those within ``_MERGED`` of the width of the one before or of the end."""
    t = np.sort(np.concatenate([knots, knots + width]))
    inner = t[1:-1]
    apart = (inner - t[:-2] > _MERGED * width) & (t[-1] - inner > _MERGED * width)
    return np.concatenate([t[:1], inner[apart], t[-1:]])


class ToppraPlanner:
    """Time-optimal motion along the planned contour, at rest at every landmark, within every
    limit of the problem; see the module docstring."""

    name = "toppra"

    def settings(self, problem: Problem) -> ToppraSettings:
        return ToppraSettings.from_options(planner_options(problem, self.name, OPTION_KEYS))

    def plan(self, problem: Problem) -> Trajectory:
        settings = self.settings(problem)
        started = time.perf_counter()
        pieces = [
            _segment_motion(problem, k, segment, settings)
            for k, segment in enumerate(_segments(problem, settings.path_samples))
        ]
        durations = np.array([piece.t[-1] for piece in pieces])
        starts = np.concatenate([[0.0], np.cumsum(durations)])
        samples = _chain(pieces, starts[:-1])
        statistics = {
            "status": "Ok",
            "solve_time_s": time.perf_counter() - started,
            "gridpoints": settings.gridpoints,
            "samples": int(samples[0].size),
            "segment_durations_s": durations.tolist(),
            "toppra_durations_s": [piece.toppra_duration for piece in pieces],
            "smoothing_windows_s": [piece.window for piece in pieces],
            "toppra_accelerations_rad_s2": [piece.acceleration for piece in pieces],
            "toppra_runs": [piece.runs for piece in pieces],
            "settings": dataclasses.asdict(settings),
        }
        metadata = {
            "landmark_times_s": starts.tolist(),
            "landmarks": problem.visit_names,
            "statistics": statistics,
        }
        return Trajectory.from_samples(*samples, metadata=metadata)


register(ToppraPlanner())
