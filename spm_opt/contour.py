"""The planned cut on the skull: great-circle arcs through the landmarks.

A surgeon draws the cut through the landmarks A_i. Between consecutive landmarks it follows
the great circle through their directions, and its radius (the skull's) changes linearly
with the angle travelled, from |A_i| to |A_{i+1}|. The tool points at the isocenter, so the
robot cuts where the platform's direction b = B / r_u meets the skull; the skull's radius
in a direction is taken as that of the nearest contour point (by angle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spm_opt.model import kinematics

_GAUSS_NODES, _GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(16)
_GAUSS_FRACTIONS = _GAUSS_NODES + 1
"""The Gauss nodes as fractions of half the interval, from its start (0 to 2)."""
NEWTON_STEPS = 8
"""Newton steps of :meth:`Contour.point_at` (from the constant-radius guess)."""
PRODUCT_ROWS = 16_384
"""Rows per matrix product in :func:`_components`: few enough that OpenBLAS keeps a product
of three columns on one thread (starting threads costs more than it saves on so little
work, and far more on a busy machine), and a power of two, so that every row meets the
same kernel as in one product (the same values, to the bit)."""


@dataclass(frozen=True)
class Nearest:
    """The contour point nearest (by angle) to each of N directions.

    Attributes
    ----------
    arc : ndarray (N,), int
        Index of the arc (arc i runs from landmark i to the next).
    angle : ndarray (N,), rad
        Angle φ along that arc from its start landmark.
    offset : ndarray (N,), rad
        Angle between the direction and the nearest contour point.
    radius : ndarray (N,), m
        Skull radius at the nearest contour point.
    interior : ndarray (N,), bool
        True where the nearest point lies strictly inside its arc (not at a landmark).
    """

    arc: np.ndarray
    angle: np.ndarray
    offset: np.ndarray
    radius: np.ndarray
    interior: np.ndarray


class Contour:
    """Great-circle arcs between consecutive landmarks, closed back to the first if asked.

    Parameters
    ----------
    landmarks : ndarray, shape (n, 3), m
        Points on the skull, in visiting order; each with z > 0, no two consecutive equal.
    closed : bool
        Whether the cut returns from the last landmark to the first.
    """

    def __init__(self, landmarks: np.ndarray, closed: bool) -> None:
        landmarks = np.asarray(landmarks, dtype=float)
        order = list(range(len(landmarks))) + ([0] if closed else [])
        starts, ends = landmarks[order[:-1]], landmarks[order[1:]]
        self.landmarks = landmarks
        self.closed = closed
        self.start_radius = np.linalg.norm(starts, axis=1)
        self.end_radius = np.linalg.norm(ends, axis=1)
        self.start = starts / self.start_radius[:, None]
        end = ends / self.end_radius[:, None]
        normal = np.cross(self.start, end)
        sine = np.linalg.norm(normal, axis=1)
        self.sweep = np.arctan2(sine, np.einsum("ij,ij->i", self.start, end))
        """Angle of each arc, rad."""
        self.normal = normal / sine[:, None]
        self.inplane = np.cross(self.normal, self.start)
        self.end = self._unit(np.arange(len(self.sweep)), self.sweep)
        """Unit direction at the end of each arc (its next landmark's, to rounding)."""
        self.radius_slope = (self.end_radius - self.start_radius) / self.sweep
        """dρ/dφ of each arc, m/rad."""
        self.arc_lengths = self._length_to(np.arange(len(self.sweep)), self.sweep)
        self.landmark_arc_lengths = np.concatenate([[0.0], np.cumsum(self.arc_lengths)])
        """Arc length at each landmark visit (the first again at the end if closed), m."""

    @property
    def length(self) -> float:
        """Total length of the cut, m."""
        return float(self.landmark_arc_lengths[-1])

    def _radius(self, arc: np.ndarray, angle: np.ndarray) -> np.ndarray:
        return self.start_radius[arc] + self.radius_slope[arc] * angle

    def _length_to(self, arc: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """Arc length from the start of ``arc`` to ``angle``: ∫ sqrt(ρ² + ρ'²) dφ (Gauss)."""
        arc, angle = np.broadcast_arrays(np.asarray(arc), np.asarray(angle, dtype=float))
        return _gauss_length(self.start_radius[arc], self.radius_slope[arc], angle)

    def point_at(self, s: np.ndarray) -> np.ndarray:
        """Contour points (N, 3), m, at arc lengths ``s`` (N,), m, from the first landmark."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        arc = np.clip(
            np.searchsorted(self.landmark_arc_lengths, s, side="right") - 1, 0, len(self.sweep) - 1
        )
        local = s - self.landmark_arc_lengths[arc]
        start_radius, slope, sweep = self.start_radius[arc], self.radius_slope[arc], self.sweep[arc]
        angle = local / np.hypot(start_radius, slope)
        for _ in range(NEWTON_STEPS):  # on s(φ) = local; ds/dφ = sqrt(ρ² + ρ'²) > 0
            rate = np.hypot(start_radius + slope * angle, slope)
            step = (_gauss_length(start_radius, slope, angle) - local) / rate
            angle = np.clip(angle - step, 0, sweep)
        return self._unit(arc, angle) * (start_radius + slope * angle)[..., None]

    def _unit(self, arc: np.ndarray, angle: np.ndarray) -> np.ndarray:
        return (
            np.cos(angle)[..., None] * self.start[arc]
            + np.sin(angle)[..., None] * self.inplane[arc]
        )

    def nearest(self, directions: np.ndarray) -> Nearest:
        """The contour point nearest by angle to each direction (N, 3): unit vectors, or any
        points (a cut point, B) taken as their direction from the isocenter."""
        p = np.asarray(directions, dtype=float)
        p = p / np.linalg.norm(p, axis=-1, keepdims=True)
        # (N, arcs) arrays, each buffer reused once its values are no longer needed
        along = _components(p, self.start)
        across = _components(p, self.inplane)
        angle = np.arctan2(across, along)
        interior = (angle > 0.0) & (angle < self.sweep)
        in_plane = np.hypot(along, across, out=along)
        off_plane = np.abs(_components(p, self.normal, out=across), out=across)
        offset = np.arctan2(off_plane, in_plane, out=in_plane)
        offset[~interior] = np.inf
        to_start, to_end = _angles_between(p, self.start), _angles_between(p, self.end)
        end_angle = np.where(to_end < to_start, self.sweep, 0.0)
        end_offset = np.minimum(to_start, to_end, out=to_start)
        use_end = end_offset < offset
        np.copyto(offset, end_offset, where=use_end)
        np.copyto(angle, end_angle, where=use_end)
        arc = np.argmin(offset, axis=1)
        rows = np.arange(len(p))
        chosen_angle = angle[rows, arc]
        return Nearest(
            arc=arc,
            angle=chosen_angle,
            offset=offset[rows, arc],
            radius=self._radius(arc, chosen_angle),
            interior=~use_end[rows, arc],
        )

    def arc_length(self, near: Nearest) -> np.ndarray:
        """Arc length (N,), m, from the first landmark to each nearest contour point."""
        return self.landmark_arc_lengths[near.arc] + self._length_to(near.arc, near.angle)

    def progress(self, near: Nearest) -> np.ndarray:
        """How far along the contour (N,), m, a sequence of cut points has come: the arc
        length of each one's nearest contour point, continued across the closing landmark
        of a closed contour (so a loop that starts at the first landmark runs from about 0
        to about the length, and one that runs backwards goes negative)."""
        s = self.arc_length(near)
        if not self.closed or len(s) == 0:
            return s
        length = self.length
        steps = np.diff(s)
        steps -= length * np.round(steps / length)
        s = s[0] + np.concatenate([[0.0], np.cumsum(steps)])
        return s - length if s[0] > length / 2 else s

    def cut_points(self, directions: np.ndarray) -> np.ndarray:
        """Where the tool meets the skull along unit directions (N, 3): points (N, 3), m."""
        return self.nearest(directions).radius[:, None] * np.asarray(directions, dtype=float)

    def deviation(self, directions: np.ndarray) -> np.ndarray:
        """Distance (N,), m, of the cut point in each direction (or of each cut point) from
        the contour.

        The chord 2 ρ sin(δ/2) between the cut point and the nearest contour point, with δ
        the angle between them and ρ the skull radius there.
        """
        return self.chord(self.nearest(directions))

    @staticmethod
    def chord(near: Nearest) -> np.ndarray:
        """Distance (N,), m, from each nearest contour point to the cut point it is nearest
        to: 2 ρ sin(δ/2) (see :meth:`deviation`)."""
        return 2.0 * near.radius * np.sin(near.offset / 2.0)

    def joint_tool_speed(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Speed (N,), m/s, of the cut point for joint angles q (N, 2), rad, moving at
        q̇ (N, 2) or (2,), rad/s (see :meth:`tool_speed`)."""
        q = np.asarray(q, dtype=float)
        return self.tool_speed(kinematics.forward_kinematics(q, 1.0), direction_rates(q, qd))

    def tool_speed(
        self, directions: np.ndarray, direction_rates: np.ndarray, near: Nearest | None = None
    ) -> np.ndarray:
        """Speed (N,), m/s, of the cut point for unit directions p (N, 3) moving at ṗ (N, 3),
        1/s; ``near``: the contour points nearest to p, when already found.

        The cut point is P = ρ p, so |Ṗ|² = ρ² |ṗ|² + ρ̇², with ρ̇ = ρ' φ̇ where the nearest
        contour point moves along an arc (and 0 where it sits at a landmark).
        """
        p = np.asarray(directions, dtype=float)
        p_dot = np.asarray(direction_rates, dtype=float)
        near = self.nearest(p) if near is None else near
        a, w = self.start[near.arc], self.inplane[near.arc]
        pa, pw = np.einsum("nk,nk->n", p, a), np.einsum("nk,nk->n", p, w)
        angle_rate = (
            np.einsum("nk,nk->n", p_dot, w) * pa - pw * np.einsum("nk,nk->n", p_dot, a)
        ) / (pa**2 + pw**2)
        radius_rate = np.where(near.interior, self.radius_slope[near.arc] * angle_rate, 0.0)
        return np.hypot(near.radius * np.linalg.norm(p_dot, axis=1), radius_rate)


def direction_rates(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Rates ṗ (N, 3), 1/s, of the platform's unit direction for joint angles q (N, 2), rad,
    moving at q̇ (N, 2) or (2,), rad/s."""
    q = np.asarray(q, dtype=float)
    jacobian = kinematics.platform_jacobian(q, 1.0)
    return np.einsum("nij,nj->ni", jacobian, np.broadcast_to(qd, q.shape))


def _gauss_length(start_radius: np.ndarray, slope: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """∫₀^angle sqrt(ρ² + ρ'²) dφ, m, with ρ = start_radius + slope φ, element by element
    (16-point Gauss–Legendre; radii in m, slopes in m/rad, angles in rad)."""
    half = angle / 2
    radius = half[..., None] * _GAUSS_FRACTIONS
    radius *= slope[..., None]
    radius += start_radius[..., None]
    integrand = np.hypot(radius, slope[..., None], out=radius)
    return half * (integrand @ _GAUSS_WEIGHTS)


def _components(p: np.ndarray, axes: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """p @ axes.T: components (N, arcs) of vectors p (N, 3) along unit vectors (arcs, 3),
    ``PRODUCT_ROWS`` rows at a time, into ``out`` when given."""
    out = np.empty((len(p), len(axes))) if out is None else out
    for start in range(0, len(p), PRODUCT_ROWS):
        rows = slice(start, start + PRODUCT_ROWS)
        np.matmul(p[rows], axes.T, out=out[rows])
    return out


def _angles_between(p: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Angles (N, arcs), rad, between unit directions p (N, 3) and unit vectors (arcs, 3)."""
    cosine = np.einsum("nk,ak->na", p, ends)
    return np.arccos(np.clip(cosine, -1.0, 1.0, out=cosine), out=cosine)
