"""The planned contour: arc length, distances and tool speed against known answers."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spm_opt.cut.contour import Contour

R = 0.07  # m
APEX_ANGLE = 0.5
APEX = np.array([0.0, np.sin(APEX_ANGLE), np.cos(APEX_ANGLE)])
"""On the y-z great circle, APEX_ANGLE before the top: the meridian runs away from it."""


class ConeSurface:
    """A skull whose radius grows linearly with the angle φ along the meridian from the
    top: ρ = R + k (angle from APEX − APEX_ANGLE)."""

    def __init__(self, slope: float) -> None:
        self.slope = slope

    def radius(self, directions: np.ndarray) -> np.ndarray:
        angle = np.arccos(np.clip(directions @ APEX, -1.0, 1.0))
        return R + self.slope * (angle - APEX_ANGLE)

    def radius_gradient(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cosine = np.clip(directions @ APEX, -1.0, 1.0)
        away = cosine[:, None] * directions - APEX  # ∇ of the angle from APEX, times its sine
        sine = np.sqrt(1.0 - cosine**2)
        return self.radius(directions), self.slope * away / sine[:, None]


def meridian_contour(angle: float, end_radius: float = R) -> Contour:
    """Two landmarks on the y-z great circle, ``angle`` apart, from the top, on the skull
    whose radius grows linearly from R at the top to ``end_radius`` at the second."""
    end = end_radius * np.array([0.0, -np.sin(angle), np.cos(angle)])
    surface = ConeSurface((end_radius - R) / angle)
    return Contour(np.array([[0.0, 0.0, R], end]), closed=False, surface=surface)


def test_constant_radius_arc_length_is_radius_times_angle():
    contour = meridian_contour(0.5)
    assert contour.length == pytest.approx(R * 0.5, rel=1e-14)


def test_varying_radius_arc_length_matches_the_closed_form():
    """ρ(φ) = ρ0 + kφ: L = [ρ√(ρ²+k²) + k² asinh(ρ/k)] / 2k between the ends."""
    angle, end_radius = 0.6, 0.08
    k = (end_radius - R) / angle

    def primitive(rho):
        return (rho * np.hypot(rho, k) + k**2 * np.arcsinh(rho / k)) / (2 * k)

    contour = meridian_contour(angle, end_radius)
    assert contour.length == pytest.approx(primitive(end_radius) - primitive(R), rel=1e-11)


@settings(max_examples=50, deadline=None)
@given(st.floats(0.01, 1.0))
def test_point_at_walks_the_arc_by_length(fraction):
    contour = meridian_contour(0.6, 0.08)
    s = fraction * contour.length
    point = contour.point_at(np.array([s]))[0]
    angle = np.arctan2(-point[1], point[2])
    assert point[0] == pytest.approx(0.0, abs=1e-15)
    assert np.linalg.norm(point) == pytest.approx(R + (0.08 - R) * angle / 0.6, rel=1e-11)
    partial = meridian_contour(angle, np.linalg.norm(point))
    assert partial.length == pytest.approx(s, rel=1e-9, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(st.floats(0.01, 0.49), st.floats(-0.3, 0.3))
def test_deviation_of_a_direction_tilted_off_the_arc(along, tilt):
    """A direction at angle ``tilt`` off the great circle, inside the arc: chord 2ρ sin(δ/2)."""
    contour = meridian_contour(0.5)
    direction = np.array(
        [np.sin(tilt), -np.cos(tilt) * np.sin(along), np.cos(tilt) * np.cos(along)]
    )
    deviation = contour.deviation(direction[None, :])[0]
    assert deviation == pytest.approx(2 * R * np.sin(abs(tilt) / 2), rel=1e-9, abs=1e-15)
    cut = contour.cut_points(direction[None, :])
    np.testing.assert_allclose(np.linalg.norm(cut), R)
    assert contour.deviation(cut)[0] == pytest.approx(deviation, rel=1e-12, abs=1e-18)


def test_deviation_beyond_the_arc_end_is_the_distance_to_the_landmark():
    contour = meridian_contour(0.5)
    beyond = np.array([[0.0, -np.sin(0.7), np.cos(0.7)]])
    assert contour.deviation(beyond)[0] == pytest.approx(2 * R * np.sin(0.1), rel=1e-12)


def test_closed_contour_returns_to_the_first_landmark():
    landmarks = R * np.array([[0, 0, 1], [0.3, 0, 0.954], [0.3, 0.3, 0.905]])
    landmarks = R * landmarks / np.linalg.norm(landmarks, axis=1, keepdims=True)
    closed, open_ = Contour(landmarks, True), Contour(landmarks, False)
    assert len(closed.arc_lengths) == 3 and len(open_.arc_lengths) == 2
    np.testing.assert_allclose(
        closed.point_at(np.array([closed.length]))[0], landmarks[0], atol=1e-15
    )
    np.testing.assert_allclose(
        closed.point_at(closed.landmark_arc_lengths[:3]), landmarks, atol=1e-15
    )


def test_tool_speed_along_the_contour_at_constant_arc_length_rate():
    """Moving along the contour at ds/dt = v gives tool speed v, radius change included."""
    contour = meridian_contour(0.6, 0.08)
    speed = 0.003  # m/s
    s = np.linspace(0.05, 0.95, 50) * contour.length
    h = 1e-7
    ahead, behind = contour.point_at(s + h), contour.point_at(s - h)
    unit = contour.point_at(s)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)

    def normalise(p):
        return p / np.linalg.norm(p, axis=1, keepdims=True)

    direction_rate = (normalise(ahead) - normalise(behind)) / (2 * h) * speed
    np.testing.assert_allclose(contour.tool_speed(unit, direction_rate), speed, rtol=1e-6)


def square_loop() -> Contour:
    """Four landmarks around the vertex, a closed loop."""
    tilt = 0.3
    corners = [(tilt, 0.0), (0.0, tilt), (-tilt, 0.0), (0.0, -tilt)]
    points = np.array([[np.sin(a), np.sin(b), 1.0] for a, b in corners])
    return Contour(R * points / np.linalg.norm(points, axis=1, keepdims=True), closed=True)


@settings(max_examples=50, deadline=None)
@given(st.floats(0.0, 0.99), st.floats(0.05, 1.0), st.integers(0, 1))
def test_progress_recovers_the_arc_length_across_the_closing_landmark(start, span, backwards):
    """Cut points walked along a closed loop from any start, forwards or backwards, for any
    part of a turn: the progress is the arc length walked, continued past the first
    landmark (not wrapped back to 0), up to where it started."""
    contour = square_loop()
    walked = np.linspace(0.0, span * contour.length, 400) * (-1.0 if backwards else 1.0)
    s = start * contour.length + walked
    progress = contour.progress(contour.nearest(contour.point_at(np.mod(s, contour.length))))
    shift = progress[0] - s[0]
    assert shift / contour.length == pytest.approx(np.round(shift / contour.length), abs=1e-9)
    np.testing.assert_allclose(progress - shift, s, atol=1e-9)
