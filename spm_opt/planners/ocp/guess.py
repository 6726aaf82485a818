"""Where a solve starts: a given motion re-timed onto the grid segment by segment, or the
contour-following motion (:mod:`spm_opt.planners.contour_guess`)."""

from __future__ import annotations

import numpy as np

from spm_opt.planners.contour_guess import segment_motion
from spm_opt.planners.ocp.transcription import Grid
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory


def _visits(start: Trajectory | None, segments: int) -> np.ndarray | None:
    """The landmark times of ``start`` (s), if it visits ``segments`` + 1 landmarks."""
    visits = None if start is None else start.metadata.get("landmark_times_s")
    if visits is None or len(visits) != segments + 1:
        return None
    return np.asarray(visits, dtype=float)


def _retimed(
    start: Trajectory, visits: np.ndarray, t: np.ndarray, landmarks: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, q̇, q̈ (N, 2) at times t of ``start`` (landmark times ``visits``) stretched
    segment by segment onto the landmark times ``landmarks``."""
    segment = np.clip(np.searchsorted(landmarks, t, side="right") - 1, 0, len(landmarks) - 2)
    rate = np.diff(visits)[segment] / np.diff(landmarks)[segment]  # start's s per s
    source = np.clip(visits[segment] + (t - landmarks[segment]) * rate, visits[0], visits[-1])
    rate = rate[:, None]
    return (
        start.position(source),
        start.velocity(source) * rate,
        start.acceleration(source) * rate**2,
    )


def initial_guess(
    problem: Problem, grid: Grid, segment_durations: np.ndarray, start: Trajectory | None
) -> np.ndarray:
    """The initial x over ``segment_durations`` (s): ``start`` re-timed onto them when it
    visits the same landmarks, else the contour-following motion."""
    phases = grid.phase_durations(segment_durations)
    t = grid.node_times(phases)
    landmarks = t[grid.landmark_nodes]
    visits = _visits(start, grid.segments)
    if start is not None and visits is not None:
        q, qd, qdd = _retimed(start, visits, t, landmarks)
    else:
        parts = []
        for k in range(grid.segments):
            inside = slice(grid.landmark_nodes[k], grid.landmark_nodes[k + 1] + 1)
            duration = landmarks[k + 1] - landmarks[k]
            tau = (t[inside] - landmarks[k]) / duration
            parts.append(np.hstack(segment_motion(problem, k, tau, duration))[:-1])
        last = np.hstack([problem.waypoint_angles[-1], np.zeros(4)])
        q, qd, qdd = np.hsplit(np.vstack([*parts, last]), [2, 4])
    jerks = np.diff(qdd, axis=0) / np.diff(t)[:, None]
    return np.concatenate([np.hstack([q, qd, qdd]).ravel(), jerks.ravel(), phases])


def segment_durations(
    problem: Problem, timing: str, need: np.ndarray, start: Trajectory | None
) -> np.ndarray:
    """The segments' durations (s) the initial guess takes: the problem's when fixed,
    else the start's (scaled to the problem's total when that is kept or exceeded), else
    from the lower bounds ``need`` (s)."""
    given = float(np.sum(problem.segment_durations))
    visits = _visits(start, len(need))
    if timing == "segments":
        return problem.segment_durations
    if visits is None:
        return 1.3 * need if timing == "free" else need * given / np.sum(need)
    durations = np.diff(visits)
    if timing == "total" or (timing == "bounded" and np.sum(durations) > given):
        return durations * given / np.sum(durations)
    return durations
