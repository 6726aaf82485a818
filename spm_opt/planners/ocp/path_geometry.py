"""The path-coordinate transcription's geometry: each segment's joint path, its lateral
offset, and the map from the grid's coordinate to the arc length.

Along segment k (length L, mm, between consecutive landmark visits) the contour's joint
path q₀(s) (s the arc length, mm) is a cubic spline through the inverse kinematics of
``samples`` points of the arc, exact at the landmarks
(:func:`spm_opt.planners.path.contour_joints`). The cut may leave the contour by a
lateral offset d (mm, on the skull, towards the arc's pole): q(s, d) = q₀(s) + d v(s),
v = ∂q/∂d from the direction Jacobian's pseudo-inverse applied to the arc's pole, over the
cut point's displacement per radian sqrt(ρ² + (∇ρ·n)²) (so that d is the 3-D distance from
the contour, to first order; the tube is ~0.1 mm against a 70 mm skull, and the second
order is 1e-4 mm).

The grid's coordinate u ∈ [0, L] (mm) maps to the arc length by s = L g(u / L). Where the
cut starts or stops (the first and the last landmark), g is cubic over an end zone
(g' = S(ξ / e), S = 6x² − 8x³ + 3x⁴: g' and g'' vanish at the end), so that the cut is at
rest with zero acceleration there while u̇ stays positive and time ∫ du / u̇ finite; at a
landmark the cut passes through, and in between, g is linear.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.planners.path import contour_joints, path_points
from spm_opt.problem.problem import Problem

CLUSTER = 1.5
"""Nodes of a corner zone at landmark distances ∝ (k / n)^1.5, finer near the landmark
(on the paper's flap, 1: 37.984 s, 1.5: 37.977 s, 2: 37.977 s)."""
MIN_ZONE = 1e-3
"""Least end zone, as a fraction of the segment."""
ZONE_INTEGRAL = 0.6
"""∫₀¹ S(x) dx: an end zone's share of its length in arc length."""


def _chebyshev(intervals: int) -> np.ndarray:
    """``intervals`` + 1 nodes on [0, 1], Chebyshev–Lobatto: finer towards both ends,
    where the cut speeds up, slows down and turns (on the paper's flap, ocp-min-jerk's
    ∫ q⃛ᵀq⃛ dt 0.737 rad²/s⁵ on even nodes, 0.396 on these; minimum time 37.977 and 37.976 s)."""
    return (1.0 - np.cos(np.pi * np.arange(intervals + 1) / intervals)) / 2


def _zone_shape(x: np.ndarray) -> tuple[np.ndarray, ...]:
    """S(x) (1 beyond x = 1), S', S'' and ∫₀ˣ S."""
    inside, y = x < 1.0, np.minimum(x, 1.0)
    shape = np.where(inside, 6 * y**2 - 8 * y**3 + 3 * y**4, 1.0)
    slope = np.where(inside, 12 * y * (1 - y) ** 2, 0.0)
    bend = np.where(inside, 12 - 48 * y + 36 * y**2, 0.0)
    integral = np.where(inside, 2 * y**3 - 2 * y**4 + 0.6 * y**5, x - (1 - ZONE_INTEGRAL))
    return shape, slope, bend, integral


def _end_factor(x: np.ndarray, zone: float) -> tuple[np.ndarray, ...]:
    """One end's factor of g' (x the distance from that end, as a fraction): S(x / zone) and
    its derivatives in x, and its integral; 1 without a zone."""
    if zone <= 0.0:
        one = np.ones_like(x)
        return one, 0 * x, 0 * x, x
    shape, slope, bend, integral = _zone_shape(x / zone)
    return shape, slope / zone, bend / zone**2, zone * integral


def path_map(xi: np.ndarray, zones: tuple[float, float]) -> tuple[np.ndarray, ...]:
    """g(ξ), g', g'', g''' (ξ = u / L ∈ [0, 1]) with end zones ``zones`` (fractions of ξ,
    0: none; they must not overlap)."""
    xi = np.asarray(xi, dtype=float)
    start, start_1, start_2, start_integral = _end_factor(xi, zones[0])
    end, end_1, end_2, end_integral = _end_factor(1.0 - xi, zones[1])
    # one factor is 1 wherever the other differs from it, so ∫ start·end = ∫ start + ∫ end − ξ
    total = 1.0 - (1.0 - ZONE_INTEGRAL) * (zones[0] + zones[1])
    end_total = 1.0 - (1.0 - ZONE_INTEGRAL) * zones[1]
    g = start_integral + (end_total - end_integral) - xi
    return (
        g / total,
        start * end / total,
        (start_1 * end - start * end_1) / total,
        (start_2 * end - 2 * start_1 * end_1 + start * end_2) / total,
    )


@dataclass(frozen=True)
class SegmentPath:
    """One segment's joint path q₀(s) and its lateral vector v(s) (rad/mm) as one spline
    of four columns, its length (mm), its map's end zones and its grid's nodes (u, mm)."""

    length: float
    curves: CubicSpline
    zones: tuple[float, float]
    nodes: np.ndarray

    @property
    def ends_speed_factor(self) -> np.ndarray:
        """ds/du at the segment's two ends (2,)."""
        return path_map(np.array([0.0, 1.0]), self.zones)[1]

    def geometry(self, u: np.ndarray) -> dict[str, np.ndarray]:
        """At grid coordinates u (N,), mm: q₀ and its u-derivatives A1–A3 (N, 2), and v and
        its u-derivatives v1–v3."""
        length = self.length
        g, g1, g2, g3 = path_map(np.asarray(u, dtype=float) / length, self.zones)
        s = np.clip(g * length, 0.0, length)
        g1, g2, g3 = g1[:, None], g2[:, None] / length, g3[:, None] / length**2

        def along(spline: CubicSpline) -> tuple[np.ndarray, ...]:
            d0, d1, d2, d3 = (spline(s, order) for order in range(4))
            return d0, d1 * g1, d2 * g1**2 + d1 * g2, d3 * g1**3 + 3 * d2 * g1 * g2 + d1 * g3

        names = ("q", "A1", "A2", "A3", "v", "v1", "v2", "v3")
        values = along(self.curves)
        return dict(
            zip(names, [v[:, :2] for v in values] + [v[:, 2:] for v in values], strict=True)
        )

    def joints(self, s: np.ndarray, order: int = 0) -> np.ndarray:
        """q₀ or its ``order``-th derivative at arc lengths s (N,), mm: (N, 2)."""
        return self.curves(s, order)[:, :2]

    def lateral(self, s: np.ndarray, order: int = 0) -> np.ndarray:
        """v or its ``order``-th derivative at arc lengths s (N,), mm: (N, 2), rad/mm."""
        return self.curves(s, order)[:, 2:]


def path_terms(
    problem: Problem, paths: list[SegmentPath], us: list[np.ndarray]
) -> list[dict[str, np.ndarray]]:
    """For each path, at its grid coordinates u (N,), mm: its :meth:`SegmentPath.geometry`,
    the cut point's speed metric G (N, 3: G11, G12, G22, mm²/rad², |ṡ_cut|² = q̇ᵀGq̇), and
    the model's terms at q₀ moving along the path (:func:`spm_opt.planners.path.path_points`:
    inertia with the rotors' (N, 4), Coriolis and centrifugal per unit u̇², gravity,
    friction (N, 2)); the model evaluated once for all paths."""
    parts = [path.geometry(u) for path, u in zip(paths, us, strict=True)]
    q, a1, a2 = (np.concatenate([part[name] for part in parts]) for name in ("q", "A1", "A2"))
    points = path_points(problem, q, a1, a2)
    model = {
        "G": _speed_metric(problem, q),
        "inertia": points.inertia.reshape(-1, 4),
        "bias": points.bias,
        "gravity": points.gravity,
        "friction": points.friction,
    }
    ends = np.cumsum([0] + [len(u) for u in us])
    return [
        {**part, **{name: values[start:end] for name, values in model.items()}}
        for part, start, end in zip(parts, ends[:-1], ends[1:], strict=True)
    ]


def _speed_metric(problem: Problem, q: np.ndarray) -> np.ndarray:
    """(G11, G12, G22) (N, 3), mm²/rad²: the cut point's squared speed per joint rates,
    ρ² JᵀJ + (Jᵀ∇ρ)(Jᵀ∇ρ)ᵀ with J the platform direction's Jacobian (|Ṗ|² = ρ²|ṗ|² + (∇ρ·ṗ)²,
    ṗ = J q̇)."""
    jacobian = kinematics.platform_jacobian(q, 1.0)  # (N, 3, 2)
    directions = kinematics.forward_kinematics(q, 1.0)
    radius, gradient = problem.contour.surface.radius_gradient(directions)
    slope = np.einsum("nk,nki->ni", gradient, jacobian)
    metric = radius[:, None, None] ** 2 * np.einsum("nki,nkj->nij", jacobian, jacobian)
    metric += slope[:, :, None] * slope[:, None, :]
    return np.column_stack([metric[:, 0, 0], metric[:, 0, 1], metric[:, 1, 1]]) / MM**2


def _ramp_length(curves: CubicSpline, length: float, bounds_speed: tuple[float, ...]) -> float:
    """Arc length, mm, of a start from rest to cruise: v (v / a + a / j) with the path's
    steepest joint (tool speed mm/s, joint speed rad/s, acceleration, jerk); ``curves``:
    the joint path in its first two columns."""
    tool, joint_speed, acceleration, jerk = bounds_speed
    pace = float(np.max(np.abs(curves(np.linspace(0.0, length, 50), 1)[:, :2])))  # rad/mm
    speed = min(tool, joint_speed / pace)
    return speed * (speed * pace / acceleration + acceleration / jerk)


def segment_paths(
    problem: Problem,
    limits: tuple[float, float, float, float],
    samples: int,
    intervals: tuple[int, int],
    zones: tuple[float, float],
) -> list[SegmentPath]:
    """Every segment's path and grid. ``limits``: tool speed (mm/s), joint speed (rad/s),
    acceleration (rad/s²) and jerk (rad/s³); ``intervals``: (each end's, the middle's);
    ``zones``: the end zones' lengths over a ramp's, at rest ends and at landmarks passed."""
    contour = problem.contour
    ends = contour.landmark_arc_lengths
    count = len(problem.segment_durations)
    lengths = [(ends[k + 1] - ends[k]) / MM for k in range(count)]
    arcs = [np.linspace(0.0, length, samples) for length in lengths]
    joints = contour_joints(problem, [s * MM for s in arcs])
    paths = []
    for k, (length, s, q) in enumerate(zip(lengths, arcs, joints, strict=True)):
        lateral = _lateral_vectors(problem, q, contour.normal[k])
        curves = CubicSpline(s, np.column_stack([q, lateral]))
        ramp = _ramp_length(curves, length, limits) / length
        rest = (k == 0, k == count - 1)
        grid_zone = [
            float(np.clip(zones[0 if at_rest else 1] * ramp, MIN_ZONE, 0.3)) for at_rest in rest
        ]
        map_zone = tuple(
            z / (ZONE_INTEGRAL + (1 - ZONE_INTEGRAL) * 2 * z) if at_rest else 0.0
            for z, at_rest in zip(grid_zone, rest, strict=True)
        )
        node_zone = [
            m if at_rest else z for m, z, at_rest in zip(map_zone, grid_zone, rest, strict=True)
        ]
        corner, middle = intervals
        spread = [
            np.linspace(0.0, 1.0, corner + 1) ** (1.0 if at_rest else CLUSTER) for at_rest in rest
        ]
        xi = np.concatenate(
            [
                node_zone[0] * spread[0],
                node_zone[0] + (1.0 - node_zone[1] - node_zone[0]) * _chebyshev(middle)[1:],
                1.0 - node_zone[1] * spread[1][::-1][1:],
            ]
        )
        paths.append(SegmentPath(length, curves, map_zone, xi * length))
    return paths


def _lateral_vectors(problem: Problem, q: np.ndarray, pole: np.ndarray) -> np.ndarray:
    """∂q/∂d (N, 2), rad/mm, at joint angles q (N, 2) on an arc with unit pole ``pole``."""
    jacobian = kinematics.platform_jacobian(q, 1.0)  # (N, 3, 2), per unit direction
    per_radian = np.linalg.solve(
        np.einsum("nki,nkj->nij", jacobian, jacobian),
        np.einsum("nki,k->ni", jacobian, pole)[..., None],
    )[..., 0]
    directions = kinematics.forward_kinematics(q, 1.0)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radius, gradient = problem.contour.surface.radius_gradient(directions)
    stretch = np.sqrt(radius**2 + (gradient @ pole) ** 2) / MM  # mm of offset per radian
    return per_radian / stretch[:, None]
