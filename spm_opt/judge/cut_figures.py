"""What a motion's cut measures on its samples: its distance from the contour, the tool's
speed and incidence, how it sweeps the contour (the largest stretch left uncut in the tube,
backtracking), its landmark visits and the depth setpoint's rates; the figures the judge
checks and reports (:func:`spm_opt.judge.judge.judge`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from spm_opt.cut.contour import row_lengths, surface_speed
from spm_opt.judge.depth import depth_rates
from spm_opt.judge.limits import RULES
from spm_opt.judge.motion import Claimed, Motion
from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.problem.problem import Problem


@dataclass(frozen=True)
class CutFigures:
    """A motion's cut, measured at its N samples.

    Attributes
    ----------
    directions, rates : ndarray (N, 3), 1, 1/s
        The cut's unit direction and its rate of change.
    margins : ndarray (N,)
        The singularity margin.
    deviation : ndarray (N,), m
        The distance on the skull from the contour.
    tool_speed : ndarray (N,), m/s
        The tool's speed over the skull.
    incidence : ndarray (N,), deg
        The tool's angle from the skull's normal.
    backtrack : ndarray (N,), m
        How far back along the contour the cut is from the farthest it reached.
    gap : float, m
        The longest stretch of the contour never swept inside the tube.
    gap_time : float, s
        When the cut first reaches that stretch's start (the end, if never).
    landmark_errors : list of dict
        Each landmark visit in visiting order: ``landmark``, ``time_s``, ``error_mm``.
    depth_speed, depth_acceleration : ndarray (N,), m/s, m/s²
        The depth setpoint's rates (empty without an inner mesh).
    """

    directions: np.ndarray
    rates: np.ndarray
    margins: np.ndarray
    deviation: np.ndarray
    tool_speed: np.ndarray
    incidence: np.ndarray
    backtrack: np.ndarray
    gap: float
    gap_time: float
    landmark_errors: list[dict[str, Any]]
    depth_speed: np.ndarray
    depth_acceleration: np.ndarray


def cut_figures(
    problem: Problem,
    motion: Motion,
    tube: float | None,
    path: float,
    claimed: Claimed | None = None,
    between_samples: bool = False,
) -> CutFigures:
    """Measure the cut of ``motion``: swept in the ``tube`` (m; None: everywhere), its
    landmark visits within the ``path`` tolerance (m) where ``claimed``, or searched for
    (``between_samples``: between two samples too; :func:`spm_opt.judge.judge.judge`)."""
    contour, t = problem.contour, motion.t
    directions, rates, margins = kinematics.motion_directions(motion.q, motion.qd)
    near = contour.nearest(directions)
    radius, gradient = contour.surface.radius_gradient(directions)
    deviation = contour.distance(near, radius)
    in_tube = (
        np.ones(len(t), bool)
        if tube is None
        else deviation <= RULES["contour deviation"].allowed(tube)
    )
    progress = contour.progress(near)
    gap, gap_at = _largest_gap(progress, in_tube, contour.length)
    reached = np.flatnonzero(progress >= gap_at)
    depth_speed, depth_acceleration = _depth_rates(problem, t, directions, rates)
    return CutFigures(
        directions=directions,
        rates=rates,
        margins=margins,
        deviation=deviation,
        tool_speed=surface_speed(radius, gradient, rates),
        incidence=np.degrees(np.arctan(row_lengths(gradient) / radius)),
        backtrack=np.maximum.accumulate(progress) - progress,
        gap=gap,
        gap_time=t[reached[0]] if reached.size else t[-1],
        landmark_errors=_landmark_errors(problem, claimed, t, directions, path, between_samples),
        depth_speed=depth_speed,
        depth_acceleration=depth_acceleration,
    )


def _largest_gap(progress: np.ndarray, in_tube: np.ndarray, length: float) -> tuple[float, float]:
    """The longest stretch of the contour, m, that the cut never swept while in the tube,
    and the arc length, m, where it starts.

    Each step between consecutive samples that are both in the tube sweeps the contour
    between their nearest points' arc lengths (``progress``); the stretches of [0, length]
    that no such step sweeps (a plan that stands still, stops early, or leaves the tube
    to skip a stretch) are the gaps.
    """
    swept = in_tube[:-1] & in_tube[1:]
    low = np.clip(np.minimum(progress[:-1], progress[1:])[swept], 0.0, length)
    high = np.clip(np.maximum(progress[:-1], progress[1:])[swept], 0.0, length)
    if low.size == 0:
        return length, 0.0
    # stable: quick on a cut's nearly sorted arc lengths; the result is any sort's, as of
    # steps with equal starts the first in the order has the largest gap before it
    order = np.argsort(low, kind="stable")
    low, reached = low[order], np.maximum.accumulate(high[order])
    starts = np.concatenate([[0.0], reached])
    gaps = np.concatenate([low, [length]]) - starts
    worst = int(np.argmax(gaps))
    return float(max(gaps[worst], 0.0)), float(starts[worst])


def _landmark_errors(
    problem: Problem,
    claimed: Claimed | None,
    t: np.ndarray,
    directions: np.ndarray,
    tolerance: float,
    between_samples: bool,
) -> list[dict[str, Any]]:
    """Distance on the skull from each landmark visit, in visiting order: where the
    motion claims it, or, when it does not say, at the closest approach of the first pass
    within ``tolerance`` (m) after the previous visit (the closest approach after it, when
    the cut never comes that close); ``between_samples``: that approach measured on the
    straight segments from the nearest sample to its neighbours."""
    errors = []
    earliest = 0
    for k, index in enumerate(problem.visit_order):
        landmark = problem.landmarks[index]
        radius = np.linalg.norm(landmark)
        unit = landmark / radius
        if claimed is not None:
            time = float(claimed.times[k])
            error = radius * np.linalg.norm(claimed.directions[k] - unit)
        else:
            distances = radius * np.linalg.norm(directions[earliest:] - unit, axis=1)
            near = np.flatnonzero(distances <= RULES["landmark visit"].allowed(tolerance))
            if near.size:  # the closest approach of the first pass that comes near enough
                left = np.flatnonzero(np.diff(near) > 1)
                end = near[left[0]] + 1 if left.size else near[-1] + 1
                closest = near[0] + int(np.argmin(distances[near[0] : end]))
            else:
                closest = int(np.argmin(distances))
            time, error = float(t[earliest + closest]), distances[closest]
            if between_samples:
                time, error = _between(t, directions, earliest + closest, unit, radius)
            if near.size:
                earliest += closest
        errors.append(
            {
                "landmark": problem.landmark_names[index],
                "time_s": time,
                "error_mm": float(error / MM),
            }
        )
    return errors


def _depth_rates(
    problem: Problem, t: np.ndarray, directions: np.ndarray, rates: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The speed (N,), m/s, and acceleration (N,), m/s², of the tool's depth setpoint along
    unit directions (N, 3) moving at ``rates`` (N, 3), 1/s (empty without an inner mesh)."""
    inner = problem.inner_radius
    if inner is None:
        return np.zeros(0), np.zeros(0)
    return depth_rates(inner, t, directions, rates)


def _between(
    t: np.ndarray, directions: np.ndarray, k: int, unit: np.ndarray, radius: float
) -> tuple[float, float]:
    """The closest approach, (time, s; distance, m), of the cut to the landmark in
    direction ``unit`` on the skull's sphere of ``radius`` along the straight segments
    from sample ``k`` to its neighbours (time interpolated along them)."""
    best = (float(t[k]), float(radius * np.linalg.norm(directions[k] - unit)))
    for other in (k - 1, k + 1):
        if not 0 <= other < len(t):
            continue
        step = directions[other] - directions[k]
        squared = float(step @ step)
        if squared == 0.0:
            continue
        along = min(max(float((unit - directions[k]) @ step) / squared, 0.0), 1.0)
        distance = float(radius * np.linalg.norm(directions[k] + along * step - unit))
        if distance < best[1]:
            best = (float(t[k] + along * (t[other] - t[k])), distance)
    return best
