"""The cubic baseline against independent derivations and its own conditions."""

import dataclasses

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

import spm_opt as so
from spm_opt.planners.cubic import absolute_time_coefficients
from spm_opt.studies import paper


def test_matches_the_papers_absolute_time_32x32_system(paper_problem, baseline):
    """Build Eq. 4's D matrix in absolute time, as the paper does, and solve it."""
    theta = np.degrees(paper_problem.waypoint_angles)
    times = paper_problem.waypoint_times
    rows, rhs = [], []

    def block(segment, joint, values):
        row = np.zeros(32)
        row[8 * segment + 4 * joint : 8 * segment + 4 * joint + 4] = values
        return row

    def pos(t):
        return [t**3, t**2, t, 1]

    def vel(t):
        return [3 * t**2, 2 * t, 1, 0]

    def acc(t):
        return [6 * t, 2, 0, 0]

    for joint in range(2):
        for s in range(4):
            rows += [block(s, joint, pos(times[s])), block(s, joint, pos(times[s + 1]))]
            rhs += [theta[s, joint], theta[s + 1, joint]]
        rows += [block(0, joint, vel(0.0)), block(3, joint, vel(40.0))]
        rhs += [0.0, 0.0]
        for s in range(1, 4):
            for basis in (vel, acc):
                rows.append(block(s - 1, joint, basis(times[s])) - block(s, joint, basis(times[s])))
                rhs.append(0.0)
    solution = np.linalg.solve(np.array(rows), np.array(rhs)).reshape(4, 2, 4)
    ours = np.degrees(absolute_time_coefficients(baseline))
    np.testing.assert_allclose(ours, solution, rtol=1e-9, atol=1e-9)


def test_same_as_a_clamped_cubic_spline(paper_problem, baseline):
    spline = CubicSpline(
        paper_problem.waypoint_times, paper_problem.waypoint_angles, bc_type="clamped"
    )
    t = np.linspace(0.0, 40.0, 2001)
    np.testing.assert_allclose(baseline.position(t), spline(t), atol=1e-12)


def test_c2_continuous_with_rest_at_both_ends(baseline):
    inner = baseline.breakpoints[1:-1]
    for derivative in (baseline.position, baseline.velocity, baseline.acceleration):
        np.testing.assert_allclose(derivative(inner - 1e-9), derivative(inner + 1e-9), atol=1e-9)
    np.testing.assert_allclose(baseline.velocity([0.0, 40.0]), 0.0, atol=1e-14)
    jumps = baseline.jerk(inner + 1e-6) - baseline.jerk(inner - 1e-6)
    assert np.all(np.max(np.abs(jumps), axis=1) > 1e-6)  # cubic pieces: jerk is not continuous


def test_passes_every_landmark_at_its_time(paper_problem, baseline):
    np.testing.assert_allclose(
        baseline.position(paper_problem.waypoint_times), paper_problem.waypoint_angles, atol=1e-14
    )
    assert baseline.metadata["landmark_times_s"] == [0.0, 10.0, 20.0, 30.0, 40.0]
    assert baseline.metadata["planner"] == "cubic"
    assert baseline.metadata["statistics"]["unknowns"] == 32


def test_any_number_of_landmarks_and_durations(paper_problem):
    """An open cut through three landmarks with unequal segments: 16 unknowns."""
    problem = dataclasses.replace(
        paper_problem,
        landmark_names=("A1", "A2", "A3"),
        landmarks=paper_problem.landmarks[:3],
        closed=False,
        segment_durations=np.array([3.0, 7.5]),
    )
    trajectory = so.plan(problem, "cubic")
    assert trajectory.duration == pytest.approx(10.5)
    assert trajectory.metadata["statistics"]["unknowns"] == 16
    np.testing.assert_allclose(
        trajectory.position([0.0, 3.0, 10.5]), problem.landmark_angles, atol=1e-13
    )
    np.testing.assert_allclose(trajectory.velocity([0.0, 10.5]), 0.0, atol=1e-14)


def test_planner_table_refuses_unknown_options(paper_problem):
    problem = dataclasses.replace(paper_problem, planner_options={"cubic": {"nodes": 3}})
    with pytest.raises(so.InputError, match="planner.cubic.nodes"):
        so.plan(problem, "cubic")


def test_unknown_planner_lists_the_known_ones(paper_problem):
    with pytest.raises(so.UnknownPlannerError, match="cubic"):
        so.plan(paper_problem, "cubic-spline")
    assert "cubic" in so.PLANNERS


def test_table_iii_time_unit_is_the_papers(paper_problem):
    assert list(paper_problem.segment_durations) == [paper.TABLE_III_SEGMENT_S] * 4
