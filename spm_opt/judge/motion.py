"""A motion as the judge takes it: sampled on a time grid (:class:`Motion`), with the jumps
of q̈ between its samples (:class:`Steps`) and the landmark visits it claims
(:class:`Claimed`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Motion:
    """A motion sampled at times ``t`` (N,), s, and what drove it; per-joint arrays (N, 2).

    Attributes
    ----------
    t : ndarray, s
    q, qd, qdd, jerk : ndarray, rad, rad/s, rad/s², rad/s³
    torque : ndarray, N·m
        The torque the actuators delivered.
    current : ndarray, A
        The motor current it took.
    peak_speed : ndarray or None, rad/s
        Where the motion is known between its samples (a plant's true state): each joint's
        largest speed since the sample before, this one's included. None: the samples'
        own ``|qd|``.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    jerk: np.ndarray
    torque: np.ndarray
    current: np.ndarray
    peak_speed: np.ndarray | None = None

    def joint_speed(self) -> np.ndarray:
        """Each joint's speed the judge holds to its limit (N, 2), rad/s: ``peak_speed``
        where known, else ``|qd|``."""
        return np.abs(self.qd) if self.peak_speed is None else self.peak_speed


@dataclass(frozen=True)
class Steps:
    """Jumps of q̈ the samples cannot show: at ``times`` (K,), s, ``values`` (K, 2),
    rad/s², judged against ``limit`` (rad/s², the jerk a grid interval allows; None: not
    limited)."""

    times: np.ndarray
    values: np.ndarray
    limit: float | None


@dataclass(frozen=True)
class Claimed:
    """Where a motion says it visits each landmark: ``times`` (visits,), s, and the unit
    ``directions`` (visits, 3) of the cut then."""

    times: np.ndarray
    directions: np.ndarray
