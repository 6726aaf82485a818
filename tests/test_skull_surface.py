"""The skull's radius without a mesh (the smooth surface through the landmarks) and the
optimal-control planners' fit of it near each arc, against independent computations."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import spm_opt as so
from spm_opt.cut.contour import Contour
from spm_opt.skull.arc_fit import fit_arc_radius
from spm_opt.skull.landmark_surface import LandmarkSurface


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


landmark_sets = st.integers(2, 9).flatmap(
    lambda n: st.tuples(
        st.lists(st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)), min_size=n, max_size=n),
        st.lists(st.floats(0.06, 0.09), min_size=n, max_size=n),
    )
)


def landmarks_of(tilts, radii) -> np.ndarray:
    """Landmarks at least 0.05 rad apart (nearer ones at different radii make no skull)."""
    directions = unit(np.array([[np.sin(a), np.sin(b), 1.0] for a, b in tilts]))
    apart = [np.arccos(min(1.0, a @ b)) for i, a in enumerate(directions) for b in directions[:i]]
    assume(min(apart) > 0.05)
    return np.array(radii)[:, None] * directions


@settings(max_examples=60, deadline=None)
@given(landmark_sets)
def test_the_surface_passes_through_every_landmark(case):
    landmarks = landmarks_of(*case)
    directions = unit(landmarks)
    surface = LandmarkSurface(landmarks)
    np.testing.assert_allclose(
        surface.radius(directions), np.linalg.norm(landmarks, axis=1), atol=1e-9
    )


@settings(max_examples=40, deadline=None)
@given(landmark_sets, st.integers(0, 2**31))
def test_the_gradient_is_the_derivative_on_the_sphere(case, seed):
    landmarks = landmarks_of(*case)
    surface = LandmarkSurface(landmarks)
    rng = np.random.default_rng(seed)
    p = unit(rng.normal(size=(20, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, 1.0])
    tangent = unit(np.cross(p, rng.normal(size=(20, 3))))
    step = 1e-6
    ahead = unit(p + step * tangent)
    behind = unit(p - step * tangent)
    by_differences = (surface.radius(ahead) - surface.radius(behind)) / (2 * step)
    radius, gradient = surface.radius_gradient(p)
    np.testing.assert_allclose(
        np.einsum("ni,ni->n", gradient, tangent), by_differences, rtol=1e-6, atol=1e-8
    )
    scale = 1.0 + np.linalg.norm(gradient, axis=1)
    assert np.all(np.abs(np.einsum("ni,ni->n", gradient, p)) <= 1e-12 * scale)
    np.testing.assert_allclose(radius, surface.radius(p))


def test_a_flap_on_a_sphere_keeps_the_sphere():
    landmarks = 0.07 * unit(np.array([[0.3, 0.0, 1.0], [0.0, 0.3, 1.0], [-0.3, 0.0, 1.0]]))
    directions = unit(np.random.default_rng(1).normal(size=(50, 3)) * 0.3 + [0, 0, 1])
    np.testing.assert_allclose(LandmarkSurface(landmarks).radius(directions), 0.07, rtol=1e-12)


def test_no_jump_in_the_cut_where_the_nearest_arc_changes(paper_problem):
    """Directions swept across the corner at A4, inside the tube: the nearest arc changes
    halfway, and the cut point's radius must not jump (the radius of the nearest contour
    point did: 0.019 mm within 1 ms at A4 on ocp-min-energy's plan)."""
    contour = paper_problem.contour
    corner = unit(paper_problem.landmarks[3])
    inward = unit(unit(paper_problem.landmarks[2]) + unit(paper_problem.landmarks[0]) - 2 * corner)
    across = unit(np.cross(corner, inward))
    offsets = np.linspace(-0.001, 0.001, 2001)
    directions = unit(corner + 0.0008 * inward + offsets[:, None] * across)
    near = contour.nearest(directions)
    assert len(np.unique(near.arc)) == 2
    radii = np.linalg.norm(contour.cut_points(directions), axis=1)
    assert np.max(np.abs(np.diff(radii))) < 1e-7  # m, between directions 1e-6 rad apart


def ellipsoid_radius(directions: np.ndarray) -> np.ndarray:
    """A head-like ellipsoid about the isocenter, semi-axes 75, 95 and 85 mm."""
    axes = np.array([0.075, 0.095, 0.085])
    return 1.0 / np.sqrt(np.sum((directions / axes) ** 2, axis=1))


class Ellipsoid:
    def radius(self, directions):
        return ellipsoid_radius(np.atleast_2d(directions))

    def radius_gradient(self, directions):  # not used by the fit
        raise NotImplementedError


@pytest.mark.parametrize("across", [0.004, 0.02])
def test_the_arc_fit_follows_the_surface_and_reports_its_error(across):
    start, end = unit(np.array([0.2, -0.1, 1.0])), unit(np.array([-0.3, 0.35, 1.0]))
    normal = unit(np.cross(start, end))
    inplane = np.cross(normal, start)
    sweep = float(np.arccos(start @ end))
    fit = fit_arc_radius(Ellipsoid(), start, inplane, normal, sweep, across)
    rng = np.random.default_rng(2)
    along = rng.uniform(0.0, sweep, 500)
    off = rng.uniform(-across, across, 500)
    p = (
        np.sqrt(1 - off**2)[:, None]
        * (np.cos(along)[:, None] * start + np.sin(along)[:, None] * inplane)
        + off[:, None] * normal
    )
    error = np.abs(fit.radius(along, off) - ellipsoid_radius(p))
    assert np.max(error) < 1e-6  # m
    assert np.max(error) <= fit.max_error * 1.5


def test_the_paper_flap_keeps_its_landmarks_and_its_length_on_the_surface(paper_problem):
    contour = paper_problem.contour
    np.testing.assert_allclose(
        contour.point_at(contour.landmark_arc_lengths[:-1]), paper_problem.landmarks, atol=1e-12
    )
    sphere_like = Contour(paper_problem.landmarks, True)
    assert sphere_like.length == pytest.approx(contour.length, rel=1e-12)
    assert so.evaluate(paper_problem, so.plan(paper_problem, "cubic")).max_tool_incidence_deg > 0
