"""Calibration poses chosen, not guessed: a pool of reachable poses, and the subset a
D-optimal design picks from it.

The pool is a square grid of joint angles within ``reach`` of θ = 0, kept where the robot
can take them (joint range less :data:`RANGE_CLEARANCE_RAD`, singularity margin). The
design adds, one at a time, the pool's pose that most raises log det(JᵀJ) of the scaled
identification Jacobian (:mod:`spm_opt.calibration.identifiability`) of every unknown, at
the ideal robot: a greedy D-optimal design (Fedorov's exchange without the exchange). It
starts from the four poses farthest from the centre along the diagonals.
"""

from __future__ import annotations

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.calibration.identifiability import column_scales
from spm_opt.calibration.measurement import UNKNOWNS, marker_model, start_vector
from spm_opt.model.params import Robot

RANGE_CLEARANCE_RAD = np.radians(2.0)
"""Room kept inside each joint's range by the pool's poses, rad."""

RIDGE = 1e-12
"""Added to JᵀJ's diagonal (scaled units, m²) while fewer poses than unknowns are chosen."""


def pose_pool(robot: Robot, reach_rad: float, per_axis: int) -> np.ndarray:
    """Joint angles (n, 2), rad: a ``per_axis`` × ``per_axis`` grid over ±``reach_rad``,
    kept where ``robot`` can take them."""
    if per_axis < 2:
        raise InputError(f"calibration pool: per_axis = {per_axis}; allowed: at least 2")
    axis = np.linspace(-reach_rad, reach_rad, per_axis)
    grid = np.stack(np.meshgrid(axis, axis, indexing="ij"), axis=-1).reshape(-1, 2)
    low = robot.joint_range[:, 0] + RANGE_CLEARANCE_RAD
    high = robot.joint_range[:, 1] - RANGE_CLEARANCE_RAD
    inside = np.all((grid >= low) & (grid <= high), axis=1)
    grid = grid[inside]
    reachable = [reason is None for reason in robot.unreachable_reason(grid)]
    return grid[np.asarray(reachable, dtype=bool)]


def _pose_information(pool: np.ndarray, marker_distance_m: float) -> np.ndarray:
    """Each pose's scaled Jacobian rows (n, 3, len(UNKNOWNS))."""
    _, jacobian = marker_model(start_vector(marker_distance_m), np.eye(3), pool)
    scaled = jacobian / column_scales(marker_distance_m)
    return scaled.reshape(len(pool), 3, len(UNKNOWNS))


def d_optimal(pool: np.ndarray, count: int, marker_distance_m: float) -> np.ndarray:
    """Indices into ``pool`` of ``count`` poses chosen greedily for log det(JᵀJ)."""
    if not len(UNKNOWNS) // 3 + 1 <= count <= len(pool):
        raise InputError(
            f"calibration poses: {count}; allowed: {len(UNKNOWNS) // 3 + 1} to the pool's "
            f"{len(pool)}"
        )
    rows = _pose_information(pool, marker_distance_m)
    radius = np.hypot(pool[:, 0], pool[:, 1])
    chosen: list[int] = []
    for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        score = np.where(np.sign(pool[:, 0]) * sx > 0, 1.0, 0.0) * np.where(
            np.sign(pool[:, 1]) * sy > 0, 1.0, 0.0
        )
        candidate = int(np.argmax(score * radius))
        if candidate not in chosen and len(chosen) < count:
            chosen.append(candidate)
    information = sum(rows[i].T @ rows[i] for i in chosen) + RIDGE * np.eye(len(UNKNOWNS))
    while len(chosen) < count:
        inverse = np.linalg.inv(information)
        # det(A + RᵀR) = det(A) det(I + R A⁻¹ Rᵀ): the gain of each pose, from 3×3 blocks
        gains = np.linalg.slogdet(np.eye(3) + rows @ inverse @ rows.transpose(0, 2, 1))[1]
        gains[chosen] = -np.inf
        best = int(np.argmax(gains))
        chosen.append(best)
        information = information + rows[best].T @ rows[best]
    return np.asarray(chosen)


def uniform_grid(robot: Robot, reach_rad: float, count: int) -> np.ndarray:
    """About ``count`` poses (n, 2), rad, on the square grid over ±``reach_rad`` with the
    nearest side that gives at least that many reachable poses (the design's reference)."""
    side = 2
    while len(grid := pose_pool(robot, reach_rad, side)) < count:
        side += 1
    return grid
