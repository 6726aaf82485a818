"""The depth setpoint of the platform's tool module along a cut.

The tool's tip is held at the distance from the isocenter where its axis meets the skull's
inner surface, plus the problem's ``depth_margin_mm`` (outwards: a positive margin leaves
that much bone under the tip; a negative one takes the tip past the inner surface). The
inner surface is the smooth interpolant of its ray casts over the flap
(:class:`spm_opt.skull.smooth_radius.SmoothRadius`), so the setpoint's speed and
acceleration are the bone's, not its triangulation's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.cut.contour import direction_rates
from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.skull.smooth_radius import SmoothRadius

if TYPE_CHECKING:
    from spm_opt.problem.trajectory import Trajectory

SETPOINT_RATE_HZ = 20.0
"""Rate of the depth setpoint a plan's metadata carries, Hz."""


@dataclass(frozen=True)
class DepthProfile:
    """The tool tip's distance from the isocenter along a motion.

    Attributes
    ----------
    depth : ndarray (N,), m
    speed : ndarray (N,), m/s
    acceleration : ndarray (N,), m/s²
        By central differences of the speed in time.
    """

    depth: np.ndarray
    speed: np.ndarray
    acceleration: np.ndarray


def depth_profile(
    inner: SmoothRadius, margin: float, t: np.ndarray, q: np.ndarray, qd: np.ndarray
) -> DepthProfile:
    """The depth along joint angles q (N, 2), rad, and rates q̇ (N, 2), rad/s, at times t
    (N,), s, over the inner surface's smooth radius ``inner`` and the margin, m."""
    directions = kinematics.forward_kinematics(q, 1.0)
    speed, acceleration = depth_rates(inner, t, directions, direction_rates(q, qd))
    return DepthProfile(inner.radius(directions) + margin, speed, acceleration)


def depth_rates(
    inner: SmoothRadius, t: np.ndarray, directions: np.ndarray, rates: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The depth's speed (N,), m/s, and acceleration (N,), m/s², of :func:`depth_profile`,
    along unit directions (N, 3) moving at ``rates`` (N, 3), 1/s, at times t (N,), s."""
    speed = inner.rate(directions, rates)
    acceleration = np.gradient(speed, t) if len(t) > 1 else np.zeros_like(speed)
    return speed, acceleration


def depth_setpoint(
    inner: SmoothRadius, margin: float, trajectory: Trajectory
) -> dict[str, list[float]]:
    """The depth setpoint a plan carries: times (s) and depths (mm) at
    :data:`SETPOINT_RATE_HZ`, for the tool module."""
    t = trajectory.time_grid(SETPOINT_RATE_HZ)
    profile = depth_profile(inner, margin, t, trajectory.position(t), trajectory.velocity(t))
    return {"t_s": t.tolist(), "depth_mm": (profile.depth / MM).tolist()}
