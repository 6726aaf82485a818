"""Jerk-limited, time-synchronised segments between the landmarks (ruckig, computed locally).

Method. Each segment, from one landmark visit to the next, is one ruckig problem for both
joints: from the landmark's joint angles and via velocity to the next's, at rest in
acceleration at both ends, within per-joint speed caps and the problem's acceleration and
jerk limits. Ruckig returns the time-optimal, jerk-limited profile: piecewise constant
jerk, so q(t) is a piecewise cubic. The segments are chained one after the other; the
problem's ``segment_durations`` are not used (every segment is as fast as the limits
allow). Where the problem leaves acceleration or jerk open, ruckig still needs a finite
limit: the settings' ``default_acceleration_rad_s2`` and ``default_jerk_rad_s3`` (1 rad/s²
and 10 rad/s³, the gentle limits of the project's problem files) stand in for them.

Via points (``via_points`` in ``[planner.ruckig]``). "stop" (the default): the joints come
to rest at every landmark, and both joints are phase-synchronised, so each segment runs
along the straight line between its landmarks in joint space. "pass-through": a joint keeps
moving through a landmark when it moves the same way on both sides of it, at the smaller
of its two neighbouring segments' speed caps, and no faster than a speed from which it
could still stop within half of either neighbouring segment; a joint that turns back
passes at rest. The segments are then time-synchronised (no longer on the line).

Tool speed. On the line θ(s) = θ_k + s Δθ, s from 0 to 1, the cut point moves at
ṡ |dP/ds|, where |dP/ds| is measured as the evaluator measures tool speed
(:meth:`Contour.tool_speed`) at the joint rate Δθ. With G the largest |dP/ds| on the line
(sampled at ``LINE_SAMPLES`` points), ṡ ≤ v_tool / G keeps the tool within its limit; so
joint i gets the speed cap |Δθ_i| ṡ_max, with ṡ_max also small enough for the joint-speed
limit. Phase synchronisation keeps θ̇ = ṡ Δθ, so the cap holds on every stop segment. A
pass-through segment keeps each joint within its caps (the via velocities are within both
neighbouring segments' caps), but leaves the line near its ends, where the joint rates no
longer keep the line's ratio; the tool speed there can exceed the line's only through the
cross term of the platform Jacobian. So every segment is checked on a 1 kHz grid (with
every switch time) and the caps of a segment whose tool speed exceeds the limit are scaled
down by the excess, via velocities re-chosen and all segments solved again, until none
exceeds it (at most ``MAX_ROUNDS``). On the project's problems no cap has needed lowering.

Torque. Ruckig knows no dynamics: the whole plan's actuator torque (the model through the
actuator, as the evaluator measures it) is checked on a 1 kHz grid, and while it exceeds
the limit (:func:`spm_opt.judge.limits.torque_limit`) the acceleration and jerk limits are
lowered by ``TORQUE_STEP`` and every segment solved again (at most ``MAX_ROUNDS``).

Local only. Ruckig's community edition sends problems with intermediate waypoints to a
remote service. Every call goes through :func:`calculate_locally`, which refuses an input
with intermediate positions and builds the generator without waypoint capacity: one
segment per call, chained here.

Output. The switch times of both joints' profiles split each segment into pieces of
constant jerk; the state at each switch time and the jerk between them give the cubic
pieces exactly, which the :class:`Trajectory` holds as they are (no resampling).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import ruckig
from scipy.interpolate import PPoly

from spm_opt.base.errors import PlanningError
from spm_opt.base.ruckig_local import calculate_locally
from spm_opt.judge.limits import planner_bounds, torque_limit
from spm_opt.model import dynamics
from spm_opt.model.params import MM
from spm_opt.planners.registry import planner_options, register, settings_from_options
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

VIA_POINTS = ("stop", "pass-through")
LINE_SAMPLES = 2001
"""Points on each segment's joint-space line at which |dP/ds| is measured."""
CHECK_RATE_HZ = 1000.0
"""Rate, Hz, of the grid on which each segment's tool speed is checked."""
TOOL_SPEED_SLACK = 1e-4
"""Fraction by which a checked tool speed may exceed the limit before caps are lowered."""
MAX_ROUNDS = 10
"""Most rounds of lowering speed caps for the tool-speed limit."""
TORQUE_STEP = 0.8
"""Factor on the acceleration and jerk limits for each round in which the plan's actuator
torque exceeds its limit (ruckig knows no dynamics)."""
MIN_PIECE_S = 1e-9
"""Switch times closer than this, s, are merged (their jerk is averaged, within limits)."""


@dataclass(frozen=True)
class RuckigSettings:
    """Settings read from the problem's ``[planner.ruckig]`` table.

    Attributes
    ----------
    via_points : str
        "stop" (rest at every landmark) or "pass-through" (keep moving where possible).
    default_acceleration_rad_s2 : float, rad/s²
        Acceleration limit used when the problem sets none.
    default_jerk_rad_s3 : float, rad/s³
        Jerk limit used when the problem sets none.
    """

    via_points: str = "stop"
    default_acceleration_rad_s2: float = 1.0
    default_jerk_rad_s3: float = 10.0

    _RANGES = {"default_acceleration_rad_s2": (1e-6, 1e4), "default_jerk_rad_s3": (1e-6, 1e6)}

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> RuckigSettings:
        """Settings from a ``[planner.ruckig]`` table; one-line errors for bad values."""
        choices = {"via_points": VIA_POINTS}
        return settings_from_options("ruckig", cls(), options, cls._RANGES, choices)


OPTION_KEYS = tuple(f.name for f in dataclasses.fields(RuckigSettings))


def stop_speed(distance: np.ndarray, acceleration: float, jerk: float) -> np.ndarray:
    """Largest speed, rad/s, from which a joint at zero acceleration can come to rest within
    ``distance`` (rad), under ``acceleration`` (rad/s²) and ``jerk`` (rad/s³) limits."""
    distance = np.asarray(distance, dtype=float)
    jerk_limited = np.cbrt(distance**2 * jerk)
    ramp = acceleration**2 / (2 * jerk)
    accelerated = -ramp + np.sqrt(ramp**2 + 2 * acceleration * distance)
    return np.where(distance <= acceleration**3 / jerk**2, jerk_limited, accelerated)


def line_speed_caps(problem: Problem) -> np.ndarray:
    """Per-joint speed caps (segments, 2), rad/s, that keep a motion along each segment's
    joint-space line within the joint-speed and tool-speed limits."""
    bounds, contour = planner_bounds(problem, 0.0), problem.contour
    waypoints = problem.waypoint_angles
    s = np.linspace(0.0, 1.0, LINE_SAMPLES)[:, None]
    caps = []
    for start, step in zip(waypoints[:-1], np.diff(waypoints, axis=0), strict=True):
        rate = bounds.joint_speed / np.max(np.abs(step))  # line parameter per s
        if bounds.tool_speed is not None:
            gain = np.max(contour.joint_tool_speed(start + s * step, step))  # m per unit s
            rate = min(rate, bounds.tool_speed / gain)
        caps.append(rate * np.abs(step))
    return np.array(caps)


def via_velocities(
    waypoints: np.ndarray, caps: np.ndarray, acceleration: float, jerk: float
) -> np.ndarray:
    """Joint velocities (segments + 1, 2), rad/s, at the landmark visits in pass-through mode.

    A joint moving the same way on both sides of a landmark passes it at the smaller of the
    two segments' caps, no faster than it could stop within half of either segment; else
    at rest. The cut starts and ends at rest.
    """
    steps = np.diff(waypoints, axis=0)
    before, after = steps[:-1], steps[1:]
    speed = np.minimum.reduce(
        [
            caps[:-1],
            caps[1:],
            stop_speed(np.abs(before) / 2, acceleration, jerk),
            stop_speed(np.abs(after) / 2, acceleration, jerk),
        ]
    )
    same_way = np.sign(before) * np.sign(after) > 0
    velocities = np.zeros_like(waypoints)
    velocities[1:-1] = np.where(same_way, np.sign(after) * speed, 0.0)
    return velocities


def _segment_input(
    start: np.ndarray,
    end: np.ndarray,
    start_velocity: np.ndarray,
    end_velocity: np.ndarray,
    caps: np.ndarray,
    acceleration: float,
    jerk: float,
) -> ruckig.InputParameter:
    inp = ruckig.InputParameter(2)
    inp.current_position, inp.target_position = start.tolist(), end.tolist()
    inp.current_velocity, inp.target_velocity = start_velocity.tolist(), end_velocity.tolist()
    inp.current_acceleration = inp.target_acceleration = [0.0, 0.0]
    inp.max_velocity = caps.tolist()
    inp.max_acceleration = [acceleration] * 2
    inp.max_jerk = [jerk] * 2
    inp.synchronization = ruckig.Synchronization.Phase  # falls back to time if it must
    return inp


def cubic_pieces(trajectory: ruckig.Trajectory) -> PPoly:
    """Ruckig's profile for both joints as cubic pieces in its own time (from 0), exactly:
    one piece between consecutive switch times of either joint."""
    duration = trajectory.duration
    switches = [0.0, duration]
    for profile in trajectory.profiles[0]:
        switches += np.cumsum(profile.brake.t).tolist()
        switches += (profile.brake.duration + np.cumsum(profile.t)).tolist()
    times = np.unique(np.clip(switches, 0.0, duration))
    times = np.concatenate([times[:1], times[1:][np.diff(times) > MIN_PIECE_S]])
    times[-1] = duration
    states = np.array([trajectory.at_time(t) for t in times])  # (pieces + 1, 3, 2)
    position, velocity, acceleration = states[:, 0], states[:, 1], states[:, 2]
    jerk = np.diff(acceleration, axis=0) / np.diff(times)[:, None]
    coefficients = np.stack([jerk / 6, acceleration[:-1] / 2, velocity[:-1], position[:-1]])
    return PPoly(coefficients, times)


def _peak_tool_speed(problem: Problem, piece: PPoly) -> float:
    """Largest tool speed, m/s, of one segment on a grid at CHECK_RATE_HZ with its switches."""
    segment = Trajectory(piece)
    return float(np.max(segment.tool_speed(problem.contour, segment.time_grid(CHECK_RATE_HZ))))


@dataclass(frozen=True)
class _Plan:
    """Each segment's cubic pieces and the velocities and caps they were solved with."""

    pieces: list[PPoly]
    via_velocities: np.ndarray
    caps: np.ndarray


def _solve_segments(
    problem: Problem, caps: np.ndarray, settings: RuckigSettings, acceleration: float, jerk: float
) -> _Plan:
    waypoints, names = problem.waypoint_angles, problem.visit_names
    if settings.via_points == "pass-through":
        velocities = via_velocities(waypoints, caps, acceleration, jerk)
    else:
        velocities = np.zeros_like(waypoints)
    pieces = []
    for k in range(len(caps)):
        inp = _segment_input(
            waypoints[k],
            waypoints[k + 1],
            velocities[k],
            velocities[k + 1],
            caps[k],
            acceleration,
            jerk,
        )
        label = f"segment {k + 1} ({names[k]} -> {names[k + 1]})"
        pieces.append(cubic_pieces(calculate_locally(inp, label)))
    return _Plan(pieces, velocities, caps)


def join_pieces(pieces: list[PPoly]) -> tuple[PPoly, np.ndarray]:
    """Segments one after another: the whole motion and the landmark visit times, s."""
    offsets = np.concatenate([[0.0], np.cumsum([p.x[-1] for p in pieces])])
    breaks = [p.x[1:] + o for p, o in zip(pieces, offsets[:-1], strict=True)]
    coefficients = np.concatenate([p.c for p in pieces], axis=1)
    return PPoly(coefficients, np.concatenate([[0.0], *breaks])), offsets


def _solve_within_tool_speed(
    problem: Problem, settings: RuckigSettings, acceleration: float, jerk: float
) -> tuple[_Plan, int]:
    """Every segment solved, the caps of any that exceeds the tool-speed limit lowered by
    its excess until none does; the plan and the number of rounds it took."""
    limit = planner_bounds(problem, 0.0).tool_speed
    caps = line_speed_caps(problem)
    for rounds in range(1, MAX_ROUNDS + 1):
        plan = _solve_segments(problem, caps, settings, acceleration, jerk)
        if limit is None:
            return plan, rounds
        peaks = np.array([_peak_tool_speed(problem, p) for p in plan.pieces])
        over = peaks > limit * (1 + TOOL_SPEED_SLACK)
        if not np.any(over):
            return plan, rounds
        caps = np.where(over[:, None], caps * (limit / peaks)[:, None], caps)
    raise PlanningError(
        f"ruckig: the tool speed still exceeds {limit / MM:g} mm/s after {MAX_ROUNDS} "
        "rounds of lowering the joints' speed caps"
    )


def _peak_torque(problem: Problem, positions: PPoly) -> float:
    """Largest actuator torque, N·m, of the motion ``positions`` on a 1 kHz grid."""
    motion = Trajectory(positions)
    t = motion.time_grid(CHECK_RATE_HZ)
    state = motion.position(t), motion.velocity(t), motion.acceleration(t)
    return float(np.max(np.abs(dynamics.actuator_torque(problem.robot, *state))))


class RuckigPlanner:
    """Time-optimal jerk-limited segments between the landmarks, within the tool-speed limit."""

    name = "ruckig"

    def plan(self, problem: Problem) -> Trajectory:
        settings = RuckigSettings.from_options(planner_options(problem, self.name, OPTION_KEYS))
        start = time.perf_counter()
        bounds = planner_bounds(problem, 0.0)
        acceleration = bounds.joint_acceleration or settings.default_acceleration_rad_s2
        jerk = bounds.joint_jerk or settings.default_jerk_rad_s3
        for _ in range(MAX_ROUNDS):
            plan, rounds = _solve_within_tool_speed(problem, settings, acceleration, jerk)
            positions, landmark_times = join_pieces(plan.pieces)
            if _peak_torque(problem, positions) <= torque_limit(problem):
                break
            acceleration, jerk = acceleration * TORQUE_STEP, jerk * TORQUE_STEP
        else:
            raise PlanningError(
                f"ruckig: the actuator torque still exceeds {torque_limit(problem):g} N·m "
                f"after {MAX_ROUNDS} rounds of lowering the acceleration and jerk limits"
            )
        return Trajectory(
            positions,
            metadata={
                "landmark_times_s": landmark_times.tolist(),
                "landmarks": problem.visit_names,
                "statistics": {
                    "status": "solved",
                    "solve_time_s": time.perf_counter() - start,
                    "via_points": settings.via_points,
                    "segment_durations_s": np.diff(landmark_times).tolist(),
                    "via_velocities_rad_s": plan.via_velocities.tolist(),
                    "speed_caps_rad_s": plan.caps.tolist(),
                    "acceleration_limit_rad_s2": acceleration,
                    "jerk_limit_rad_s3": jerk,
                    "tool_speed_rounds": rounds,
                },
            },
        )


register(RuckigPlanner())
