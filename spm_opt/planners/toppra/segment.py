"""One segment's motion within every limit: toppra's path speeds, smoothed and sampled, run
again with tighter shares of any limit the smoothed motion still exceeds; and the segments'
motions chained into a plan.

No limit is trusted to the constraints' and the smoothing's arguments: the smoothed motion
is measured (speeds, acceleration, torque with exact friction) and toppra runs again with
the share of any exceeded limit cut by the excess; acceleration, torque and jerk keep
``margin`` in reserve from the start.

Along the segment the samples at every grid time carry q, q̇ = q' ṡ and q̈ = q' s̈ + q'' ṡ²,
so the quintic Hermite pieces through them have the motion's jerk. Landmark visits are the
segments' ends, at rest.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from spm_opt.base.errors import PlanningError
from spm_opt.model import dynamics
from spm_opt.planners.path import JointPath, PathPoints, path_points
from spm_opt.planners.toppra.constraints import (
    SPEED_SLACK,
    PlanLimits,
    Shares,
    first_shares,
    speed_bound,
    toppra_constraints,
)
from spm_opt.planners.toppra.lp import path_speeds
from spm_opt.planners.toppra.settings import ToppraSettings
from spm_opt.planners.toppra.smoothing import smoothed, uniform_profile
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

_ATTEMPTS = 4
"""toppra runs per segment, each with tighter shares of the limits the last one exceeded."""


@dataclass(frozen=True)
class Piece:
    """One segment's motion: samples (t from 0, s; q, qd, qdd (n, 2), SI) and figures."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    toppra_duration: float
    window: float
    acceleration: float | None
    runs: int = 1


def gridpoints(length: float, count: int) -> np.ndarray:
    """``count`` gridpoints on [0, length] spaced as s ∝ ξ² at both ends (smoothstep),
    where the cut starts and stops."""
    xi = np.linspace(0.0, 1.0, count)
    return length * xi**2 * (3.0 - 2.0 * xi)


def joint_samples(
    problem: Problem,
    index: int,
    segment: JointPath,
    s: np.ndarray,
    sd: np.ndarray,
    sdd: np.ndarray,
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
    limits: PlanLimits,
    index: int,
    segment: JointPath,
    s: np.ndarray,
    points: PathPoints,
    settings: ToppraSettings,
    shares: Shares,
) -> Piece:
    """toppra on one segment at gridpoints s (N,), mm (``points`` there) within ``shares``
    of the limits, then smoothed and sampled."""
    jerk = limits.jerk
    x_max = speed_bound(problem, limits.bounds, points.q, points.dq, shares)
    constraints, acceleration = toppra_constraints(problem, limits, index, points, x_max, shares)
    profile = uniform_profile(s, path_speeds(segment, s, constraints), settings.time_step_s)
    first = 0.0 if jerk is None or acceleration is None else acceleration / jerk
    motion = smoothed(segment, profile, first, jerk, settings.min_smoothing_s)
    t = motion.times
    path_s, sd, sdd, _ = motion(t)
    q, qd, qdd = joint_samples(problem, index, segment, path_s, sd, sdd)
    return Piece(t, q, qd, qdd, float(profile.x[-2]), motion.window * motion.step, acceleration)


def _excess(problem: Problem, limits: PlanLimits, piece: Piece) -> dict[str, float]:
    """The limits the sampled motion exceeds (beyond ``SPEED_SLACK`` for the speeds), by
    name: peak / limit. Torques from the model with exact friction, as the actuators
    deliver them."""
    bounds = limits.bounds
    torque = dynamics.actuator_torque(problem.robot, piece.q, piece.qd, piece.qdd)
    peaks = {
        "joint_speed": (np.max(np.abs(piece.qd)) / bounds.joint_speed, SPEED_SLACK),
        "torque": (np.max(np.abs(torque)) / limits.actuator_torque, 0.0),
    }
    if bounds.tool_speed is not None:
        speed = problem.contour.joint_tool_speed(piece.q, piece.qd)
        peaks["tool_speed"] = (np.max(speed) / bounds.tool_speed, SPEED_SLACK)
    if bounds.joint_acceleration is not None:
        peaks["acceleration"] = (np.max(np.abs(piece.qdd)) / bounds.joint_acceleration, 0.0)
    return {name: float(peak) for name, (peak, slack) in peaks.items() if peak > 1.0 + slack}


def segment_motion(
    problem: Problem,
    limits: PlanLimits,
    index: int,
    segment: JointPath,
    settings: ToppraSettings,
) -> Piece:
    """The motion along segment ``index`` within every limit: toppra and smoothing, again
    with tighter shares of whatever limit the smoothed motion still exceeds."""
    s = gridpoints(segment.length, settings.gridpoints)
    points = path_points(problem, *segment.derivatives(s))
    shares = first_shares(settings)
    for run in range(1, _ATTEMPTS + 1):
        piece = _attempt(problem, limits, index, segment, s, points, settings, shares)
        excess = _excess(problem, limits, piece)
        if not excess:
            return dataclasses.replace(piece, runs=run)
        shares = shares.tightened(excess)
    worst = ", ".join(f"{name} {ratio:.4g} times its limit" for name, ratio in excess.items())
    raise PlanningError(
        f"toppra: segment {segment.name}: the smoothed motion still reaches {worst} after "
        f"{_ATTEMPTS} attempts with tighter limits; raise planner.toppra.margin"
    )


def chained(
    pieces: list[Piece],
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """The segments' samples t, q, q̇, q̈ one after the other, the landmark between two
    segments (at rest in both) once; and the landmark visits' times (segments + 1,), s."""
    durations = np.array([piece.t[-1] for piece in pieces])
    starts = np.concatenate([[0.0], np.cumsum(durations)])
    t = [pieces[0].t[:1]] + [p.t[1:] + start for p, start in zip(pieces, starts[:-1], strict=True)]
    q, qd, qdd = (
        np.vstack([getattr(pieces[0], name)[:1]] + [getattr(p, name)[1:] for p in pieces])
        for name in ("q", "qd", "qdd")
    )
    return (np.concatenate(t), q, qd, qdd), starts


def piece_statistics(pieces: list[Piece]) -> dict[str, list]:
    """The segments' figures for a plan's statistics: durations, toppra's durations,
    smoothing windows (s) and toppra's acceleration bounds (rad/s²)."""
    return {
        "segment_durations_s": np.array([piece.t[-1] for piece in pieces]).tolist(),
        "toppra_durations_s": [piece.toppra_duration for piece in pieces],
        "smoothing_windows_s": [piece.window for piece in pieces],
        "toppra_accelerations_rad_s2": [piece.acceleration for piece in pieces],
    }


def visiting_trajectory(
    problem: Problem,
    samples: tuple[np.ndarray, ...],
    starts: np.ndarray,
    statistics: dict[str, Any],
) -> Trajectory:
    """The trajectory through ``samples`` (t, q, q̇, q̈) that visits the landmarks at times
    ``starts``, s, with ``statistics`` in its metadata."""
    metadata = {
        "landmark_times_s": starts.tolist(),
        "landmarks": problem.visit_names,
        "statistics": statistics,
    }
    return Trajectory.from_samples(*samples, metadata=metadata)
