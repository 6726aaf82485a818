"""A plan slowed around chosen instants: the same path, its pace lowered there by a smooth
dip and kept elsewhere.

The pace is r(τ) = dτ/dt at plan time τ: r = 1 − (1 − feed) · maxₖ b((τ − τₖ)/w), with
b(x) = ((1 + cos πx)/2)² for |x| < 1 and 0 beyond, which has two continuous derivatives, so
the slowed plan keeps a bounded jerk: q‴ r³ + 3 q″ r ṙ + q′ r̈ (q′, q″, q‴ the plan's
derivatives in τ). The path, its landmarks and its ends are the plan's; only the time each
point is reached changes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.problem.trajectory import DEFAULT_RATE_HZ, Trajectory

CREEP_RAD_S = 2e-3
"""A joint slower than this, rad/s, is taken as at rest: on its friction it sticks."""
_SCAN_SAMPLES = 20001
"""Samples over the plan where its rests and reversals are looked for."""
_PACE_SAMPLES = 200001
"""Samples of the pace r(τ) over the plan, integrated for the time t(τ)."""


def breakaway_times(trajectory: Trajectory) -> np.ndarray:
    """Plan times (s) where a joint starts from rest: the plan's start, each reversal of a
    joint's velocity, and each time a joint's speed rises through :data:`CREEP_RAD_S`."""
    t = np.linspace(trajectory.start_time, trajectory.end_time, _SCAN_SAMPLES)
    velocity = trajectory.velocity(t)
    times = [trajectory.start_time]
    for joint in range(2):
        sign = np.sign(velocity[:, joint])
        signed = np.nonzero(sign)[0]  # a sample at exactly 0 is neither side
        changed = sign[signed[1:]] != sign[signed[:-1]]
        times += list(t[signed[1:][changed]])
        moving = np.abs(velocity[:, joint]) >= CREEP_RAD_S
        times += list(t[1:][moving[1:] & ~moving[:-1]])
    return np.unique(np.array(times))


def _dip(x: np.ndarray) -> np.ndarray:
    """b(x): 1 at 0, 0 from |x| = 1 on, twice continuously differentiable."""
    x = np.clip(x, -1.0, 1.0)
    return ((1.0 + np.cos(np.pi * x)) / 2.0) ** 2


def slowed_near(
    trajectory: Trajectory,
    times_s: np.ndarray,
    feed: float,
    half_width_s: float,
    rate_hz: float = DEFAULT_RATE_HZ,
) -> Trajectory:
    """``trajectory`` with its pace lowered to ``feed`` (0 < feed ≤ 1) at each of the plan
    times ``times_s`` (s) and back to 1 within ``half_width_s`` (plan time, s) of it, as
    samples at ``rate_hz`` (Hz); it starts when the plan does. The metadata records the dip
    under ``slowed``."""
    if not (np.isfinite(feed) and 0.0 < feed <= 1.0):
        raise InputError(f"feed = {feed!r}: expected a number in (0, 1]")
    if not (np.isfinite(half_width_s) and half_width_s > 0.0):
        raise InputError(f"half_width_s = {half_width_s!r}: expected a positive number of s")
    tau = np.linspace(trajectory.start_time, trajectory.end_time, _PACE_SAMPLES)
    dip = np.zeros_like(tau)
    for at in np.asarray(times_s, dtype=float):
        dip = np.maximum(dip, _dip((tau - at) / half_width_s))
    pace = 1.0 - (1.0 - feed) * dip
    inverse = 1.0 / pace
    t = trajectory.start_time + np.concatenate(
        [[0.0], np.cumsum(np.diff(tau) * 0.5 * (inverse[1:] + inverse[:-1]))]
    )
    pace_per_tau = np.gradient(pace, tau)
    grid = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * rate_hz)) + 1) / rate_hz
    if t[-1] - grid[-1] > 1e-9:
        grid = np.append(grid, t[-1])
    at_tau = np.interp(grid, t, tau)
    r = np.interp(grid, t, pace)[:, None]
    r_dot = (np.interp(grid, t, pace_per_tau) * r[:, 0])[:, None]  # dr/dt = dr/dτ · r
    q_tau, qd_tau = trajectory.position(at_tau), trajectory.velocity(at_tau)
    qdd_tau = trajectory.acceleration(at_tau)
    metadata: dict[str, Any] = dict(trajectory.metadata)
    if trajectory.landmark_times is not None:
        metadata["landmark_times_s"] = np.interp(trajectory.landmark_times, tau, t).tolist()
    metadata["slowed"] = {
        "feed": float(feed),
        "half_width_s": float(half_width_s),
        "plan_times_s": [float(x) for x in np.asarray(times_s, dtype=float)],
        "duration_before_s": trajectory.duration,
    }
    return Trajectory.from_samples(
        grid, q_tau, qd_tau * r, qdd_tau * r**2 + qd_tau * r_dot, metadata
    )
