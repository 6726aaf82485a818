"""The skull's radius near one arc of the contour as a smooth polynomial, for the
optimal-control planners.

Near arc i a direction is p = √(1 − o²) (cos φ a + sin φ w) + o n: φ the angle along the
arc's great circle from its start a, o the component off its plane (n its normal). The
radius there is fitted, by least squares over the surface's own radius (a mesh's ray casts,
or the smooth surface through the landmarks), as

    ρ(φ, o) = Σ_k Σ_j C_kj T_k(x) y^j,   x = (φ − φ_c) / φ_h,   y = o / o_h,

with T_k the Chebyshev polynomials (k ≤ :data:`ALONG_DEGREE`, j ≤ :data:`ACROSS_DEGREE`).
It is smooth and differentiable everywhere (an NLP's iterates may stray off the skull's
mesh), and its largest error against the surface is measured on a finer grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import chebyshev

from spm_opt.skull.surface import SkullSurface

ALONG_DEGREE = 11
"""Degree of the Chebyshev polynomial along the arc."""
ACROSS_DEGREE = 2
"""Degree of the polynomial across it."""
COEFFICIENTS = (ALONG_DEGREE + 1) * (ACROSS_DEGREE + 1)
END_MARGIN_RAD = 0.02
"""How far past each end of the arc the fit reaches, rad."""
MIN_ACROSS_RAD, MAX_ACROSS_RAD = 0.004, 0.05
"""Bounds on how far off the arc's plane the fit reaches (o_h), rad."""


@dataclass(frozen=True)
class ArcRadiusFit:
    """The fitted radius near one arc (see the module's docstring).

    Attributes
    ----------
    centre, half_span : float, rad
        φ_c and φ_h: the fit covers φ in [φ_c − φ_h, φ_c + φ_h].
    across : float
        o_h: the fit covers o in [−o_h, o_h].
    coefficients : ndarray (ALONG_DEGREE + 1, ACROSS_DEGREE + 1), m
        C_kj.
    max_error : float, m
        Largest |fit − surface| on a grid finer than the fit's.
    """

    centre: float
    half_span: float
    across: float
    coefficients: np.ndarray
    max_error: float

    def radius(self, along: np.ndarray, off: np.ndarray) -> np.ndarray:
        """ρ(φ, o), m, at angles along the arc φ (N,), rad, and off-plane components o."""
        x = (np.asarray(along, dtype=float) - self.centre) / self.half_span
        y = np.asarray(off, dtype=float) / self.across
        return _design(x, y) @ self.coefficients.ravel()


def fit_arc_radius(
    surface: SkullSurface,
    start: np.ndarray,
    inplane: np.ndarray,
    normal: np.ndarray,
    sweep: float,
    across: float,
) -> ArcRadiusFit:
    """Fit the radius near the arc from unit ``start`` through ``sweep`` rad in the plane of
    ``start`` and ``inplane`` (``normal`` ⟂ both), out to ``across`` off its plane (clipped
    to [MIN_ACROSS_RAD, MAX_ACROSS_RAD])."""
    across = float(np.clip(across, MIN_ACROSS_RAD, MAX_ACROSS_RAD))
    half_span = sweep / 2 + END_MARGIN_RAD
    centre = sweep / 2

    def grid(along_points: int, across_points: int, shift: float) -> tuple[np.ndarray, ...]:
        x = np.cos(np.pi * (np.arange(along_points) + shift) / along_points)
        y = np.linspace(-1.0, 1.0, across_points)
        return tuple(a.ravel() for a in np.meshgrid(x, y, indexing="ij"))

    def surface_radius(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        along, off = centre + half_span * x, across * y
        in_plane = np.cos(along)[:, None] * start + np.sin(along)[:, None] * inplane
        return surface.radius(np.sqrt(1 - off**2)[:, None] * in_plane + off[:, None] * normal)

    x, y = grid(6 * (ALONG_DEGREE + 1), 2 * (ACROSS_DEGREE + 1) + 1, 0.5)
    coefficients = np.linalg.lstsq(_design(x, y), surface_radius(x, y), rcond=None)[0]
    # the check points: between the fit's along the arc, and on twice as many lines across
    check_x, check_y = grid(6 * (ALONG_DEGREE + 1), 4 * (ACROSS_DEGREE + 1) + 1, 0.0)
    error = np.max(
        np.abs(_design(check_x, check_y) @ coefficients - surface_radius(check_x, check_y))
    )
    return ArcRadiusFit(
        centre=centre,
        half_span=half_span,
        across=across,
        coefficients=coefficients.reshape(ALONG_DEGREE + 1, ACROSS_DEGREE + 1),
        max_error=float(error),
    )


def _design(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The basis T_k(x) y^j at each point (N, COEFFICIENTS), k-major."""
    along = chebyshev.chebvander(x, ALONG_DEGREE)
    across = np.vander(y, ACROSS_DEGREE + 1, increasing=True)
    return (along[:, :, None] * across[:, None, :]).reshape(len(x), COEFFICIENTS)
