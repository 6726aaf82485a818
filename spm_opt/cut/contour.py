"""The planned cut on the skull: great-circle arcs through the landmarks' directions.

A surgeon draws the cut through the landmarks A_i. Between consecutive landmarks it follows
the great circle through their directions; its points lie on the skull's outer surface
(:mod:`spm_opt.skull`), at the radius ρ the surface has in each direction. The tool points
at the isocenter, so the robot cuts where the platform's direction p = B / r_u meets the
surface: the cut point ρ(p) p.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.skull.landmark_surface import LandmarkSurface
from spm_opt.skull.surface import SkullSurface

KNOTS_PER_RADIAN = 1024
"""Knots of each arc's tables of the radius and the arc length, per radian of the arc (at
least 32 an arc): about one every 0.07 mm on a skull of 70 mm."""
_GAUSS_NODES, _GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(4)
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
        The skull's radius at the nearest contour point.
    interior : ndarray (N,), bool
        True where the nearest point lies strictly inside its arc (not at a landmark).
    """

    arc: np.ndarray
    angle: np.ndarray
    offset: np.ndarray
    radius: np.ndarray
    interior: np.ndarray


class Contour:
    """Great-circle arcs between consecutive landmarks' directions, closed back to the first
    if asked, on the skull's outer surface.

    Parameters
    ----------
    landmarks : ndarray, shape (n, 3), m
        Points on the skull, in visiting order; each with z > 0, no two consecutive in the
        same direction.
    closed : bool
        Whether the cut returns from the last landmark to the first.
    surface : SkullSurface, optional
        The skull's outer surface; by default the smooth surface through the landmarks.
    """

    def __init__(
        self, landmarks: np.ndarray, closed: bool, surface: SkullSurface | None = None
    ) -> None:
        landmarks = np.asarray(landmarks, dtype=float)
        self.surface = LandmarkSurface(landmarks) if surface is None else surface
        order = list(range(len(landmarks))) + ([0] if closed else [])
        starts, ends = landmarks[order[:-1]], landmarks[order[1:]]
        self.landmarks = landmarks
        self.closed = closed
        self.start = starts / np.linalg.norm(starts, axis=1)[:, None]
        end = ends / np.linalg.norm(ends, axis=1)[:, None]
        normal = np.cross(self.start, end)
        sine = np.linalg.norm(normal, axis=1)
        self.sweep = np.arctan2(sine, np.einsum("ij,ij->i", self.start, end))
        """Angle of each arc, rad."""
        self.normal = normal / sine[:, None]
        self.inplane = np.cross(self.normal, self.start)
        self.end = self._unit(np.arange(len(self.sweep)), self.sweep)
        """Unit direction at the end of each arc (its next landmark's, to rounding)."""

    @cached_property
    def _splines(self) -> tuple[tuple[CubicHermiteSpline, ...], ...]:
        """Per arc, its radius, arc length and angle splines (:meth:`_tables`), built when
        first needed (the surface is ray-cast then)."""
        return tuple(zip(*(self._tables(arc) for arc in range(len(self.sweep))), strict=True))

    @property
    def _radius_along(self) -> tuple[CubicHermiteSpline, ...]:
        return self._splines[0]

    @property
    def _length_along(self) -> tuple[CubicHermiteSpline, ...]:
        return self._splines[1]

    @property
    def _angle_at(self) -> tuple[CubicHermiteSpline, ...]:
        return self._splines[2]

    @cached_property
    def arc_lengths(self) -> np.ndarray:
        """Length of each arc, m."""
        return np.array([float(table(table.x[-1])) for table in self._length_along])

    @cached_property
    def landmark_arc_lengths(self) -> np.ndarray:
        """Arc length at each landmark visit (the first again at the end if closed), m."""
        return np.concatenate([[0.0], np.cumsum(self.arc_lengths)])

    def _tables(
        self, arc: int
    ) -> tuple[CubicHermiteSpline, CubicHermiteSpline, CubicHermiteSpline]:
        """The radius ρ(φ), the arc length s(φ) and its inverse φ(s) along ``arc``: cubic
        Hermite splines through the surface's radius and its slope at the knots, and the
        length ∫ sqrt(ρ² + ρ'²) dφ (4-point Gauss on each knot interval)."""
        sweep = self.sweep[arc]
        knots = np.linspace(0.0, sweep, max(32, int(np.ceil(KNOTS_PER_RADIAN * sweep))) + 1)
        units = self._unit(np.full(len(knots), arc), knots)
        radius, gradient = self.surface.radius_gradient(units)
        tangents = (
            -np.sin(knots)[:, None] * self.start[arc] + np.cos(knots)[:, None] * (self.inplane[arc])
        )
        radius_along = CubicHermiteSpline(knots, radius, np.einsum("ni,ni->n", gradient, tangents))
        slope_along = radius_along.derivative()
        width = np.diff(knots)
        nodes = knots[:-1, None] + width[:, None] * (_GAUSS_NODES + 1) / 2
        integrand = np.hypot(radius_along(nodes), slope_along(nodes))
        lengths = np.concatenate([[0.0], np.cumsum(width / 2 * (integrand @ _GAUSS_WEIGHTS))])
        rate = np.hypot(radius, slope_along(knots))
        return (
            radius_along,
            CubicHermiteSpline(knots, lengths, rate),
            CubicHermiteSpline(lengths, knots, 1.0 / rate),
        )

    @property
    def length(self) -> float:
        """Total length of the cut, m."""
        return float(self.landmark_arc_lengths[-1])

    def _per_arc(
        self, tables: tuple[CubicHermiteSpline, ...], arc: np.ndarray, x: np.ndarray
    ) -> np.ndarray:
        """Each arc's spline of ``tables`` at its own points: ``tables[arc[k]](x[k])``."""
        arc, x = np.broadcast_arrays(np.asarray(arc), np.asarray(x, dtype=float))
        out = np.empty(x.shape)
        for index in np.flatnonzero(np.bincount(arc.ravel(), minlength=len(tables))):
            rows = arc == index
            out[rows] = tables[index](x[rows])
        return out

    def _radius(self, arc: np.ndarray, angle: np.ndarray) -> np.ndarray:
        return self._per_arc(self._radius_along, arc, angle)

    def _length_to(self, arc: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """Arc length, m, from the start of ``arc`` to ``angle`` along it."""
        return self._per_arc(self._length_along, arc, angle)

    def point_at(self, s: np.ndarray) -> np.ndarray:
        """Contour points (N, 3), m, at arc lengths ``s`` (N,), m, from the first landmark."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        arc = np.clip(
            np.searchsorted(self.landmark_arc_lengths, s, side="right") - 1, 0, len(self.sweep) - 1
        )
        local = np.clip(s - self.landmark_arc_lengths[arc], 0.0, self.arc_lengths[arc])
        angle = np.clip(self._per_arc(self._angle_at, arc, local), 0.0, self.sweep[arc])
        return self._unit(arc, angle) * self._radius(arc, angle)[..., None]

    def _unit(self, arc: np.ndarray, angle: np.ndarray) -> np.ndarray:
        return (
            np.cos(angle)[..., None] * self.start[arc]
            + np.sin(angle)[..., None] * self.inplane[arc]
        )

    def nearest(self, directions: np.ndarray) -> Nearest:
        """The contour point nearest by angle to each direction (N, 3): unit vectors, or any
        points (a cut point, B) taken as their direction from the isocenter."""
        p = _unit_rows(directions)
        # (N, arcs) arrays, each buffer reused once its values are no longer needed
        along = _components(p, self.start)
        across = _components(p, self.inplane)
        angle = np.arctan2(across, along)
        interior = (angle > 0.0) & (angle < self.sweep)
        in_plane = np.hypot(along, across, out=along)
        off_plane = np.abs(_components(p, self.normal, out=across), out=across)
        offset = np.arctan2(off_plane, in_plane, out=in_plane)
        np.putmask(offset, ~interior, np.inf)
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
        directions = np.asarray(directions, dtype=float)
        return self.surface.radius(directions)[:, None] * directions

    def deviation(self, directions: np.ndarray) -> np.ndarray:
        """Distance (N,), m, of the cut point in each direction (or of each cut point) from
        the contour, on the skull (see :meth:`distance`)."""
        p = _unit_rows(directions)
        return self.distance(self.nearest(p), self.surface.radius(p))

    @staticmethod
    def distance(near: Nearest, radius: np.ndarray) -> np.ndarray:
        """Distance (N,), m, between each cut point, at ``radius`` (N,), m, along its
        direction, and its nearest contour point (by angle δ, at the radius ρ_c there):
        |ρ p − ρ_c c| = sqrt((ρ − ρ_c)² + 4 ρ ρ_c sin²(δ/2))."""
        lateral = 2.0 * np.sqrt(radius * near.radius) * np.sin(near.offset / 2.0)
        return np.hypot(radius - near.radius, lateral)

    def joint_tool_speed(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Speed (N,), m/s, of the cut point for joint angles q (N, 2), rad, moving at
        q̇ (N, 2) or (2,), rad/s (see :meth:`tool_speed`)."""
        q = np.asarray(q, dtype=float)
        return self.tool_speed(kinematics.forward_kinematics(q, 1.0), direction_rates(q, qd))

    def tool_speed(self, directions: np.ndarray, direction_rates: np.ndarray) -> np.ndarray:
        """Speed (N,), m/s, of the cut point for unit directions p (N, 3) moving at ṗ (N, 3),
        1/s.

        The cut point is P = ρ(p) p on the skull's surface, so |Ṗ|² = ρ² |ṗ|² + ρ̇², with
        ρ̇ = ∇ρ · ṗ (ṗ ⟂ p).
        """
        radius, gradient = self.surface.radius_gradient(np.asarray(directions, dtype=float))
        return surface_speed(radius, gradient, direction_rates)


def segment_durations_s(points_m: np.ndarray, closed: bool, speed_mm_s: float) -> list[float]:
    """Duration of each segment of a cut through landmarks (n, 3), m, s: the segment's
    length along the contour (great-circle arc, skull radius interpolated) at
    ``speed_mm_s`` (mm/s, > 0), rounded up to 0.1 s, at least 1 s."""
    lengths_mm = Contour(np.asarray(points_m, dtype=float), closed=closed).arc_lengths / MM
    return [max(1.0, math.ceil(round(length / speed_mm_s * 10, 6)) / 10) for length in lengths_mm]


def surface_speed(radius: np.ndarray, gradient: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """Speed (N,), m/s, of the point ρ(p) p on a surface of radius ρ (N,), m, and gradient
    ∇ρ (N, 3), m/rad, at directions p moving at ṗ = ``rates`` (N, 3), 1/s:
    sqrt(ρ² |ṗ|² + (∇ρ · ṗ)²)."""
    rates = np.asarray(rates, dtype=float)
    radius_rate = np.einsum("nk,nk->n", gradient, rates)
    return np.hypot(radius * row_lengths(rates), radius_rate)


def direction_rates(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Rates ṗ (N, 3), 1/s, of the platform's unit direction for joint angles q (N, 2), rad,
    moving at q̇ (N, 2) or (2,), rad/s."""
    q = np.asarray(q, dtype=float)
    jacobian = kinematics.platform_jacobian(q, 1.0)
    return np.einsum("nij,nj->ni", jacobian, np.broadcast_to(qd, q.shape))


def row_lengths(vectors: np.ndarray) -> np.ndarray:
    """Lengths (N,) of vectors (N, 3): ``np.linalg.norm(vectors, axis=1)`` to the bit (the
    same squares summed in the same order), without its slow reduction over three."""
    x, y, z = vectors[:, 0], vectors[:, 1], vectors[:, 2]
    return np.sqrt(x * x + y * y + z * z)


def _unit_rows(points: np.ndarray) -> np.ndarray:
    """Points (N, 3) over their lengths, as floats."""
    p = np.asarray(points, dtype=float)
    return p / row_lengths(p)[:, None]


def _components(p: np.ndarray, axes: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """p @ axes.T: components (N, arcs) of vectors p (N, 3) along unit vectors (arcs, 3),
    ``PRODUCT_ROWS`` rows at a time, into ``out`` when given."""
    out = np.empty((len(p), len(axes))) if out is None else out
    for start in range(0, len(p), PRODUCT_ROWS):
        rows = slice(start, start + PRODUCT_ROWS)
        np.matmul(p[rows], axes.T, out=out[rows])
    return out


def _angles_between(p: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Angles (N, arcs), rad, between unit directions p (N, 3) and unit vectors (arcs, 3).

    The cosines are summed one contiguous column at a time as (x eₓ + z e_z) + y e_y, the
    order in which ``np.einsum("nk,ak->na", p, ends)`` sums them (numpy 2.4): its values,
    several times quicker.
    """
    x, y, z = np.ascontiguousarray(p.T)
    cosine = np.empty((len(p), len(ends)))
    for column, (ex, ey, ez) in enumerate(ends):
        cosine[:, column] = (x * ex + z * ez) + y * ey
    return np.arccos(np.clip(cosine, -1.0, 1.0, out=cosine), out=cosine)
