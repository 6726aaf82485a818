"""What the evaluator's fast paths compute, against independent computations: the contour's
arc length and points, its nearest points and tool speed, the Bernstein pieces of a
trajectory, and the lower bound the problem keeps."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.interpolate import BPoly, PPoly
from scipy.optimize import brentq

import spm_opt as so
from spm_opt.cut.contour import Contour, direction_rates
from spm_opt.judge.bounds import (
    SAMPLES_PER_SEGMENT,
    duration_lower_bound,
    sampled_segment_lower_bounds,
    segment_lower_bounds,
)
from spm_opt.model import kinematics
from spm_opt.model.params import MM

R = 0.07  # m


def uneven_loop() -> Contour:
    """Five landmarks at different skull radii around the vertex, a closed loop."""
    tilts = [(0.30, 0.02), (0.05, 0.28), (-0.27, 0.04), (-0.02, -0.31), (0.18, -0.2)]
    radii = np.array([0.068, 0.071, 0.0725, 0.0695, 0.070])
    points = np.array([[np.sin(a), np.sin(b), 1.0] for a, b in tilts])
    return Contour(radii[:, None] * points / np.linalg.norm(points, axis=1)[:, None], True)


def radius_along(contour: Contour, arc: int, angle: float) -> float:
    """The skull's radius, m, at ``angle`` along ``arc``: the surface's, in that direction."""
    start, end = contour.landmarks[arc], contour.landmarks[(arc + 1) % len(contour.landmarks)]
    a = start / np.linalg.norm(start)
    w = end / np.linalg.norm(end) - (end / np.linalg.norm(end) @ a) * a
    w /= np.linalg.norm(w)
    return float(contour.surface.radius((math.cos(angle) * a + math.sin(angle) * w)[None])[0])


def arc_length_by_quadrature(contour: Contour, arc: int, angle: float) -> float:
    """∫₀^angle sqrt(ρ² + ρ'²) dφ, m, by adaptive quadrature of the surface's radius along
    the arc, ρ' by central differences of it."""
    step = 1e-5

    def integrand(phi: float) -> float:
        slope = radius_along(contour, arc, phi + step) - radius_along(contour, arc, phi - step)
        return math.hypot(radius_along(contour, arc, phi), slope / (2 * step))

    value, _ = quad(integrand, 0.0, angle, epsabs=0, epsrel=1e-12)
    return value


def point_by_scalar_search(contour: Contour, s: float) -> np.ndarray:
    """The contour point at arc length s, m: the arc it falls on, then the angle along it
    whose quadrature arc length is s, then the point on the great circle at that radius."""
    cumulative = 0.0
    for arc in range(len(contour.sweep)):
        start = contour.landmarks[arc]
        end = contour.landmarks[(arc + 1) % len(contour.landmarks)]
        sweep = math.atan2(np.linalg.norm(np.cross(start, end)), float(start @ end))
        length = arc_length_by_quadrature(contour, arc, sweep)
        if s <= cumulative + length or arc == len(contour.sweep) - 1:
            break
        cumulative += length
    local = min(max(s - cumulative, 0.0), length)
    angle = brentq(lambda phi: arc_length_by_quadrature(contour, arc, phi) - local, 0, sweep)
    a = start / np.linalg.norm(start)
    w = end / np.linalg.norm(end) - (end / np.linalg.norm(end) @ a) * a
    w /= np.linalg.norm(w)
    return radius_along(contour, arc, angle) * (math.cos(angle) * a + math.sin(angle) * w)


def test_arc_lengths_match_quadrature():
    contour = uneven_loop()
    for arc, sweep in enumerate(contour.sweep):
        expected = arc_length_by_quadrature(contour, arc, sweep)
        assert contour.arc_lengths[arc] == pytest.approx(expected, rel=1e-9)


def test_arc_length_of_nearest_points_matches_quadrature():
    contour = uneven_loop()
    rng = np.random.default_rng(3)
    s = rng.uniform(0.0, contour.length, 200)
    near = contour.nearest(contour.point_at(s))
    lengths = contour.arc_length(near)
    for k in range(0, 200, 7):
        arc, angle = int(near.arc[k]), float(near.angle[k])
        expected = contour.landmark_arc_lengths[arc] + arc_length_by_quadrature(contour, arc, angle)
        assert lengths[k] == pytest.approx(expected, rel=1e-9, abs=1e-15)


def test_point_at_matches_a_scalar_search_along_the_arcs():
    contour = uneven_loop()
    s = np.concatenate([[0.0], np.random.default_rng(4).uniform(0, contour.length, 40)])
    s = np.concatenate([s, contour.landmark_arc_lengths, [contour.length]])
    points = contour.point_at(s)
    for k, value in enumerate(s):
        np.testing.assert_allclose(points[k], point_by_scalar_search(contour, value), atol=1e-11)


def nearest_by_scalar_search(contour: Contour, direction: np.ndarray) -> tuple[int, float, float]:
    """(arc, angle along it, angle off it), rad, of the contour point nearest a direction:
    per arc, the foot of the perpendicular when it falls inside the arc, else the closer end;
    the arc that comes closest wins (the first on a tie)."""
    p = direction / np.linalg.norm(direction)
    best = (math.inf, -1, 0.0)
    for arc in range(len(contour.sweep)):
        a, w, n = contour.start[arc], contour.inplane[arc], contour.normal[arc]
        sweep = contour.sweep[arc]
        along = math.atan2(float(p @ w), float(p @ a))
        candidates = [(math.acos(min(1.0, float(p @ a))), 0.0)]
        end = math.cos(sweep) * a + math.sin(sweep) * w
        candidates.append((math.acos(min(1.0, float(p @ end))), sweep))
        if 0.0 < along < sweep:
            in_plane = math.hypot(float(p @ a), float(p @ w))
            candidates.append((math.atan2(abs(float(p @ n)), in_plane), along))
        offset, angle = min(candidates)
        if offset < best[0]:
            best = (offset, arc, angle)
    return best[1], best[2], best[0]


def unit_at(contour: Contour, arc: int, angle: float) -> np.ndarray:
    """The unit direction at ``angle`` along ``arc`` (a landmark is the end of one arc and
    the start of the next: the same direction)."""
    return math.cos(angle) * contour.start[arc] + math.sin(angle) * contour.inplane[arc]


def test_nearest_matches_a_scalar_search_over_the_arcs():
    contour = uneven_loop()
    rng = np.random.default_rng(5)
    directions = np.vstack(
        [
            contour.point_at(rng.uniform(0, contour.length, 150)) + rng.normal(0, 2 * MM, (150, 3)),
            contour.landmarks,
            rng.normal(size=(50, 3)) + [0.0, 0.0, 1.5],
        ]
    )
    near = contour.nearest(directions)
    for k, direction in enumerate(directions):
        arc, angle, offset = nearest_by_scalar_search(contour, direction)
        # arccos near 1 turns a rounding of the dot product into ~1.5e-8 rad
        assert near.offset[k] == pytest.approx(offset, rel=1e-12, abs=5e-8)
        np.testing.assert_allclose(
            unit_at(contour, near.arc[k], near.angle[k]), unit_at(contour, arc, angle), atol=1e-12
        )


def test_tool_speed_matches_finite_differences_of_the_cut_points():
    """The cut point ρ(p) p moved along q + q̇ t: its speed by central differences in t."""
    contour = uneven_loop()
    rng = np.random.default_rng(6)
    q = rng.uniform(-0.3, 0.3, (300, 2))
    qd = rng.normal(0.0, 0.05, (300, 2))
    step = 1e-4  # s

    def cut(at: np.ndarray) -> np.ndarray:
        directions = kinematics.forward_kinematics(at, 1.0)
        return contour.surface.radius(directions)[:, None] * directions

    by_differences = np.linalg.norm(cut(q + step * qd) - cut(q - step * qd), axis=1) / (2 * step)
    np.testing.assert_allclose(contour.joint_tool_speed(q, qd), by_differences, rtol=1e-6)


def test_direction_rates_match_finite_differences():
    rng = np.random.default_rng(7)
    q = rng.uniform(-0.5, 0.5, (50, 2))
    qd = rng.normal(0.0, 1.0, (50, 2))
    h = 1e-6
    ahead, behind = (kinematics.forward_kinematics(q + sign * h * qd, 1.0) for sign in (1, -1))
    np.testing.assert_allclose(direction_rates(q, qd), (ahead - behind) / (2 * h), atol=1e-8)


def random_bernstein(degree: int, pieces: int, seed: int) -> BPoly:
    rng = np.random.default_rng(seed)
    breaks = np.concatenate([[0.0], np.cumsum(rng.uniform(0.001, 0.5, pieces))])
    return BPoly(rng.normal(size=(degree + 1, pieces, 2)), breaks)


@pytest.mark.parametrize("degree", [4, 5, 7])
def test_bernstein_pieces_evaluate_as_scipy_does_to_the_bit(degree):
    poly = random_bernstein(degree, 300, seed=degree)
    trajectory = so.Trajectory(poly)
    end = poly.x[-1]
    t = np.concatenate([np.linspace(0.0, end, 20_001), poly.x, [end]])
    np.testing.assert_array_equal(trajectory.position(t), poly(t))
    np.testing.assert_array_equal(trajectory.velocity(t), poly.derivative(1)(t))
    assert trajectory.position(0.5 * end).shape == (2,)
    assert trajectory.position(t.reshape(-1, 1)).shape == (len(t), 1, 2)


def test_bernstein_pieces_match_the_power_basis():
    poly = random_bernstein(5, 50, seed=1)
    power = PPoly.from_bernstein_basis(poly)
    t = np.linspace(0.0, poly.x[-1], 5001)
    np.testing.assert_allclose(so.Trajectory(poly).position(t), power(t), rtol=1e-12, atol=1e-12)


def test_the_lower_bound_is_computed_once_per_problem(paper_problem):
    problem = dataclasses.replace(paper_problem)
    first = segment_lower_bounds(problem)
    np.testing.assert_array_equal(first, sampled_segment_lower_bounds(problem, SAMPLES_PER_SEGMENT))
    assert problem.segment_lower_bounds is problem.segment_lower_bounds
    assert not problem.segment_lower_bounds.flags.writeable
    first[:] = 0.0  # the caller's copy
    assert duration_lower_bound(problem) == pytest.approx(37.53, abs=0.01)


def test_the_lower_bound_follows_the_limits(paper_problem):
    slower = dataclasses.replace(
        paper_problem, limits=dataclasses.replace(paper_problem.limits, max_tool_speed=1.5 * MM)
    )
    assert duration_lower_bound(slower) > 1.9 * duration_lower_bound(paper_problem)
    coarse = segment_lower_bounds(paper_problem, samples=201)
    np.testing.assert_allclose(coarse, segment_lower_bounds(paper_problem), rtol=1e-3)
