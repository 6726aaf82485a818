"""A surface's radius over the directions near a flap as a smooth interpolant: a bicubic
spline on the gnomonic chart about the flap's mean direction m,

    u = p · e₁ / p · m,   v = p · e₂ / p · m   (e₁, e₂ ⟂ m),

through the surface's radius at the grid's directions (a mesh's ray casts). Where a mesh's
flat facets make the ray-cast radius kink along a path, the spline is twice continuously
differentiable, so rates and accelerations taken along a motion are the surface's, not its
triangulation's.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import RectBivariateSpline

GRID_SPACING = 0.005
"""Spacing of the chart's grid (≈ rad): about 0.35 mm on a skull of 70 mm."""


class SmoothRadius:
    """The radius of ``surface_radius`` (unit directions (N, 3) → radius (N,), m) over the
    directions within ``half_angle`` rad of the unit direction ``centre``."""

    def __init__(
        self,
        surface_radius: Callable[[np.ndarray], np.ndarray],
        centre: np.ndarray,
        half_angle: float,
    ) -> None:
        centre = np.asarray(centre, dtype=float) / np.linalg.norm(centre)
        helper = np.eye(3)[np.argmin(np.abs(centre))]
        first = np.cross(centre, helper)
        first /= np.linalg.norm(first)
        self._axes = np.stack([centre, first, np.cross(centre, first)])
        reach = float(np.tan(half_angle))
        knots = np.linspace(-reach, reach, int(np.ceil(2 * reach / GRID_SPACING)) + 1)
        u, v = np.meshgrid(knots, knots, indexing="ij")
        directions = self._directions(u.ravel(), v.ravel())
        radius = surface_radius(directions).reshape(u.shape)
        if not np.all(np.isfinite(radius)):
            raise ValueError("the surface does not cover every direction of the chart")
        self._spline = RectBivariateSpline(knots, knots, radius, kx=3, ky=3, s=0)

    def _directions(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        points = np.column_stack([np.ones_like(u), u, v]) @ self._axes
        return points / np.linalg.norm(points, axis=1, keepdims=True)

    def _chart(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        local = np.asarray(directions, dtype=float) @ self._axes.T
        return local[:, 1] / local[:, 0], local[:, 2] / local[:, 0], local

    def radius(self, directions: np.ndarray) -> np.ndarray:
        """Radius (N,), m, along unit directions (N, 3)."""
        u, v, _ = self._chart(directions)
        return self._spline.ev(u, v)

    def rate(self, directions: np.ndarray, rates: np.ndarray) -> np.ndarray:
        """dρ/dt (N,), m/s, for unit directions (N, 3) moving at ``rates`` (N, 3), 1/s."""
        u, v, local = self._chart(directions)
        local_rates = np.asarray(rates, dtype=float) @ self._axes.T
        u_rate = (local_rates[:, 1] - u * local_rates[:, 0]) / local[:, 0]
        v_rate = (local_rates[:, 2] - v * local_rates[:, 0]) / local[:, 0]
        return self._spline.ev(u, v, dx=1) * u_rate + self._spline.ev(u, v, dy=1) * v_rate
