"""toppra's path speeds made a jerk-limited motion s(t): a uniform time grid and a moving
average.

toppra's s̈ is constant between gridpoints; its steps would be steps of the joint
acceleration. Its ṡ(t), piecewise linear, is resampled on a uniform grid of ``time_step_s``
(each step's s̈ the mean of toppra's over it), then s(t) is replaced by its moving average
over a window T_w of whole steps. Then ṡ and s̈ are window averages of feasible ones,
s⃛ = (s̈(t) − s̈(t − T_w)) / T_w is bounded by the largest change of s̈ within a window over
T_w, the motion stays monotone, starts and ends at rest with zero acceleration, and lasts
T_w longer. T_w starts at a / j and is rescaled by the peak joint jerk of the averaged
motion, q⃛ = q' s⃛ + 3 q'' ṡ s̈ + q''' ṡ³, until it is the fewest steps within the limit.

The averaged s(t) is one cubic per grid step, so samples at every grid time carry every
knot of the motion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PPoly

from spm_opt.base.errors import PlanningError
from spm_opt.planners.path import JointPath
from spm_opt.problem.trajectory import MAX_DURATION_S

_JERK_ITERATIONS = 8
"""Rescalings of the moving-average window before giving up."""
_MERGED = 1e-3
"""Knots of the averaged motion closer than this fraction of the window to the one before
are not sampled: a sliver between two samples would give the quintic pieces a jerk of
rounding errors over its length cubed."""


def toppra_steps(s: np.ndarray, speed: np.ndarray) -> np.ndarray:
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


def path_profile(steps: np.ndarray, speed: np.ndarray, start: np.ndarray, end: float) -> PPoly:
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


def uniform_profile(s: np.ndarray, speed: np.ndarray, step: float) -> PPoly:
    """s(t), mm, on a uniform time grid of about ``step`` s, from toppra's path speeds (N,),
    mm/s, at gridpoints s (N,), mm.

    toppra's motion has a constant s̈ between gridpoints, so ṡ is piecewise linear in time;
    it is sampled at the grid's times and joined linearly again (each step's s̈ is the mean
    of toppra's over that step). Where that cuts a corner of ṡ(t) the path would end short
    (by parts per million here), so the grid is stretched in time until it ends exactly at
    the path's end: the speeds stay toppra's, the accelerations shrink. At rest, and
    extrapolated so, before 0 and after the end.
    """
    knots = np.concatenate([[0.0], np.cumsum(toppra_steps(s, speed))])
    times = np.linspace(0.0, knots[-1], max(1, math.ceil(knots[-1] / step)) + 1)
    rate = np.interp(times, knots, speed)
    rate[[0, -1]] = 0.0
    steps = np.diff(times) * s[-1] / np.trapezoid(rate, times)
    distance = np.concatenate([[0.0], np.cumsum(steps * (rate[:-1] + rate[1:]) / 2.0)])
    return path_profile(steps, rate, distance[:-1], float(s[-1]))


def moving_average(profile: PPoly, width: float, t: np.ndarray) -> list[np.ndarray]:
    """The moving average of s(t) (``profile``, mm) over ``width`` s, s_w(t) = (1/T_w) ∫ s
    over [t − T_w, t], and its derivatives at times t (N,): s_w, ṡ_w, s̈_w and s⃛_w in mm,
    mm/s, mm/s², mm/s³."""
    integral = profile.antiderivative()
    values = [(integral(t) - integral(t - width)) / width]
    for order in range(3):
        derivative = profile.derivative(order) if order else profile
        values.append((derivative(t) - derivative(t - width)) / width)
    return values


def average_knots(knots: np.ndarray, width: float) -> np.ndarray:
    """The times, s, where the average over ``width`` s of a motion with ``knots`` (M,), s,
    from 0, changes its cubic: the knots and the knots + width, from 0 to the end, without
    those within ``_MERGED`` of the width of the one before or of the end."""
    t = np.sort(np.concatenate([knots, knots + width]))
    inner = t[1:-1]
    apart = (inner - t[:-2] > _MERGED * width) & (t[-1] - inner > _MERGED * width)
    return np.concatenate([t[:1], inner[apart], t[-1:]])


@dataclass(frozen=True)
class Averaged:
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
        return moving_average(self.profile, self.window * self.step, t)


def _peak_jerk(segment: JointPath, motion: Averaged) -> float:
    """Largest joint jerk, rad/s³, of the averaged motion: q⃛ = q' s⃛ + 3 q'' ṡ s̈ + q''' ṡ³,
    in the middle of every grid step (s⃛ is constant on each)."""
    t = motion.times
    s, sd, sdd, sddd = motion((t[:-1] + t[1:]) / 2.0)
    _, dq, ddq, dddq = segment.derivatives(s, orders=4)
    jerk = dq * sddd[:, None] + 3.0 * ddq * (sd * sdd)[:, None] + dddq * sd[:, None] ** 3
    return float(np.max(np.abs(jerk)))


def smoothed(
    segment: JointPath, profile: PPoly, first: float, jerk: float | None, shortest: float
) -> Averaged:
    """The moving average whose peak joint jerk is within ``jerk``, rad/s³ (None: the
    ``shortest`` window, s): from ``first`` s, the window is rescaled by the measured peak
    jerk (which falls as 1 / window) until it is the fewest grid steps that fit."""
    step = float(profile.x[2] - profile.x[1])
    fewest = max(1, math.ceil(shortest / step * (1.0 - 1e-3)))
    window = max(fewest, math.ceil(first / step * (1.0 - 1e-3)))
    fits, too_short = None, 0
    for _ in range(_JERK_ITERATIONS):
        motion = Averaged(profile, window)
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
