"""The calibration as a plan the executor runs: rest-to-rest moves between the poses, each
followed by a dwell in which the robot settles and the tracker is averaged.

Each move is one jerk-limited ruckig segment (the project's one local call, no waypoints),
at :data:`SPEED_FRACTION` of the planner's joint speed bound and within its acceleration
and jerk bounds; the poses are visited in a nearest-neighbour tour from the first. The
plan ignores the contour (``ignores_contour``) and is judged by the robot's limits; its
metadata's ``calibration`` entry lists each pose's joint angles, whether the fit holds it
out, and its dwell on the plan's clock, so a log of the run says which samples to average.
"""

from __future__ import annotations

import numpy as np
import ruckig
from scipy.interpolate import PPoly

from spm_opt.base.errors import InputError
from spm_opt.base.ruckig_local import calculate_locally
from spm_opt.base.version import package_version
from spm_opt.judge.limits import planner_bounds
from spm_opt.planners.ruckig import cubic_pieces, join_pieces
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

SPEED_FRACTION = 0.5
"""Share of the joint speed bound the moves between poses use: calibration is not in a
hurry, and a slower arrival settles sooner."""

MARGIN = 0.1
"""The planner margin the moves keep on the rate-type limits."""


def tour(poses: np.ndarray) -> np.ndarray:
    """An order of ``poses`` (n, 2), rad: from the first, always to the nearest not yet
    visited (by the larger of the two joints' moves, which sets a move's time)."""
    left = list(range(1, len(poses)))
    order = [0]
    while left:
        here = poses[order[-1]]
        distances = np.max(np.abs(poses[left] - here), axis=1)
        order.append(left.pop(int(np.argmin(distances))))
    return np.asarray(order)


def _move(
    start: np.ndarray, end: np.ndarray, bounds: tuple[float, float, float], label: str
) -> PPoly:
    speed, acceleration, jerk = bounds
    inp = ruckig.InputParameter(2)
    inp.current_position, inp.target_position = start.tolist(), end.tolist()
    inp.current_velocity = inp.target_velocity = [0.0, 0.0]
    inp.current_acceleration = inp.target_acceleration = [0.0, 0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = (
        [speed] * 2,
        [acceleration] * 2,
        [jerk] * 2,
    )
    return cubic_pieces(calculate_locally(inp, label))


def _dwell(pose: np.ndarray, duration_s: float) -> PPoly:
    coefficients = np.zeros((4, 1, 2))
    coefficients[3, 0] = pose
    return PPoly(coefficients, np.array([0.0, duration_s]))


def calibration_plan(
    problem: Problem,
    poses: np.ndarray,
    held_out: np.ndarray,
    dwell_s: float,
    settle_s: float,
) -> Trajectory:
    """The plan that visits ``poses`` (n, 2), rad, in a tour, dwelling ``dwell_s`` at each;
    ``held_out`` (n,) bool marks the poses the fit never sees; the first ``settle_s`` of
    each dwell is not averaged."""
    poses = np.asarray(poses, dtype=float)
    if not 0.0 <= settle_s < dwell_s:
        raise InputError(
            f"calibration: settle_s = {settle_s:g}; allowed: 0 to dwell_s ({dwell_s:g} s)"
        )
    bounds = planner_bounds(problem, MARGIN, hold_room=False)
    if bounds.joint_acceleration is None or bounds.joint_jerk is None:
        raise InputError(
            f"{problem.name}: [limits] sets no joint acceleration or jerk; a calibration "
            "plan needs both"
        )
    rates = (bounds.joint_speed * SPEED_FRACTION, bounds.joint_acceleration, bounds.joint_jerk)
    order = tour(poses)
    pieces: list[PPoly] = []
    windows: list[list[float]] = []
    elapsed = 0.0
    for step, index in enumerate(order):
        if step:
            previous = poses[order[step - 1]]
            move = _move(previous, poses[index], rates, f"calibration move to pose {index + 1}")
            pieces.append(move)
            elapsed += float(move.x[-1])
        pieces.append(_dwell(poses[index], dwell_s))
        windows.append([elapsed + settle_s, elapsed + dwell_s])
        elapsed += dwell_s
    positions, _ = join_pieces(pieces)
    metadata = {
        "planner": "calibration",
        "problem": problem.record(),
        "spm_opt_version": package_version(),
        "ignores_contour": True,
        "calibration": {
            "poses_rad": poses[order].tolist(),
            "held_out": np.asarray(held_out, dtype=bool)[order].tolist(),
            "windows_s": windows,
            "dwell_s": dwell_s,
            "settle_s": settle_s,
        },
    }
    return Trajectory(positions, metadata)
