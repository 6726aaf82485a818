"""The path-coordinate transcription: its map, its lateral offset, and its plans judged by
checks written here."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from plan_checks import assert_within_limits

import spm_opt as so
from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.planners.ocp.path_geometry import path_map, segment_paths

ZONE = st.one_of(st.just(0.0), st.floats(0.01, 0.45))


@given(ZONE, ZONE)
@settings(max_examples=40, deadline=None)
def test_the_map_runs_from_start_to_end_and_its_derivatives_are_its_slopes(start, end):
    """g(0) = 0, g(1) = 1, g' ≥ 0, and g', g'', g''' agree with central differences of g,
    g', g'' (away from the zones' edges, where g''' jumps)."""
    xi = np.linspace(1e-3, 1 - 1e-3, 2001)
    g, g1, g2, g3 = path_map(xi, (start, end))
    ends = path_map(np.array([0.0, 1.0]), (start, end))[0]
    assert ends == pytest.approx([0.0, 1.0], abs=1e-12)
    assert np.all(g1 >= 0.0)
    step = 1e-6
    for value, slope in ((0, g1), (1, g2), (2, g3)):
        ahead = path_map(xi + step, (start, end))[value]
        behind = path_map(xi - step, (start, end))[value]
        edges = np.minimum.reduce([np.abs(xi - start), np.abs(xi - (1 - end))])
        away = edges > 1e-3
        np.testing.assert_allclose(
            ((ahead - behind) / (2 * step))[away],
            slope[away],
            atol=1e-4 * (1 + np.abs(slope[away]).max()),
        )


@pytest.mark.parametrize("zones", [(0.1, 0.0), (0.0, 0.2), (0.1, 0.05)])
def test_the_map_rests_at_its_zoned_ends(zones):
    """Where a zone is, the path's rate and its rate of change vanish (rest, no step)."""
    _, g1, g2, _ = path_map(np.array([0.0, 1.0]), zones)
    for end, zone in enumerate(zones):
        if zone > 0:
            assert g1[end] == pytest.approx(0.0, abs=1e-12)
            assert g2[end] == pytest.approx(0.0, abs=1e-12)
        else:
            assert g1[end] > 0.5


@pytest.fixture(scope="module")
def paper_problem():
    return so.load_problem("problems/craniotomy_bone_flap.toml")


def _cut_point(problem, q):
    """ρ(p) p, mm, for joint angles q (N, 2), from forward kinematics and the surface."""
    directions = kinematics.forward_kinematics(q, 1.0)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radius, _ = problem.contour.surface.radius_gradient(directions)
    return directions * radius[:, None] / MM


def test_the_lateral_offset_moves_the_cut_across_its_arc_by_d(paper_problem):
    """q₀ + d v puts the cut point d mm from the contour's point, towards the arc's pole,
    to second order (0.05 mm: 1e-6 mm), checked with forward kinematics."""
    paths = segment_paths(paper_problem, (3.0, 1.4, 0.9, 6.0), 200, (8, 4), (2.0, 0.5))
    for k, path in enumerate(paths):
        s = np.linspace(0.0, path.length, 7)
        q0, v = path.joints(s), path.lateral(s)
        base = _cut_point(paper_problem, q0)
        moved = _cut_point(paper_problem, q0 + 0.05 * v)
        shift = moved - base
        np.testing.assert_allclose(np.linalg.norm(shift, axis=1), 0.05, rtol=2e-3)
        towards = shift @ paper_problem.contour.normal[k] / 0.05
        assert np.all(towards > 0.99)


@pytest.mark.parametrize(
    "name", ["craniotomy_bone_flap", "craniotomy_five_landmarks", "skull_flap"]
)
def test_min_time_in_path_coordinates_passes_the_landmarks_within_the_limits(name):
    """Every limit kept by the tests' own measure (:mod:`plan_checks`); the plan points at
    every landmark at its visit time (forward kinematics), crosses the intermediate ones at
    speed (finite differences of the cut point), and beats toppra, which stops there."""
    problem = so.load_problem(f"problems/{name}.toml")
    plan = so.plan(problem, "ocp-min-time")
    assert plan.metadata["statistics"]["transcription"] == "path"
    assert_within_limits(problem, plan)
    times = np.asarray(plan.metadata["landmark_times_s"])
    visited = kinematics.forward_kinematics(plan.position(times), 1.0)
    order = list(range(len(problem.landmarks))) + ([0] if problem.closed else [])
    expected = np.asarray(problem.landmarks)[order]
    cosines = np.einsum(
        "ij,ij->i",
        visited / np.linalg.norm(visited, axis=1, keepdims=True),
        expected / np.linalg.norm(expected, axis=1, keepdims=True),
    )
    assert np.all(np.arccos(np.minimum(cosines, 1.0)) < 1e-7)  # rad: 7 nm on the skull
    step = 1e-3
    around = np.stack([times[1:-1] - step, times[1:-1] + step], axis=1).ravel()
    points = _cut_point(problem, plan.position(around)).reshape(-1, 2, 3)
    speeds = np.linalg.norm(points[:, 1] - points[:, 0], axis=1) / (2 * step)
    assert np.all(speeds > 0.3 * problem.limits.max_tool_speed / MM)
    assert plan.duration < so.plan(problem, "toppra").duration


def test_path_coordinates_are_for_minimum_time_only(paper_problem):
    """Another objective in path coordinates is a one-line error naming the key."""

    problem = dataclasses.replace(
        paper_problem, planner_options={"ocp-min-energy": {"transcription": "path"}}
    )
    with pytest.raises(so.InputError, match=r"planner\.ocp-min-energy\.transcription = 'path'"):
        so.plan(problem, "ocp-min-energy")
