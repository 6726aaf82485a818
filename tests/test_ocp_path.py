"""The path-coordinate transcription: its map, its lateral offset, and its plans judged by
checks written here."""

import dataclasses

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from plan_checks import assert_within_limits, cut_points, on_contour, sample

import spm_opt as so
from spm_opt.judge.bounds import segment_lower_bounds
from spm_opt.judge.limits import planner_bounds
from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.planners.ocp import path_planner
from spm_opt.planners.ocp.path_geometry import path_map, segment_paths
from spm_opt.planners.ocp.path_solver import assembled_nlp
from spm_opt.planners.registry import get_planner

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


@pytest.mark.parametrize("planner", ["ocp-min-energy", "ocp-min-jerk", "ocp-mix"])
def test_objectives_over_time_plan_in_path_coordinates(paper_problem, planner):
    """∫τᵀτ dt, ∫jerk² dt and the mix, each integrated over u with dt = du / √β: every limit
    kept by the tests' own measure, minimum jerk lasting the problem's 40 s (a row of the
    time) and minimum energy no longer."""
    plan = so.plan(paper_problem, planner)
    assert plan.metadata["statistics"]["transcription"] == "path"
    assert_within_limits(paper_problem, plan, landmark_tolerance=0.01 * MM)
    total = float(np.sum(paper_problem.segment_durations))
    if planner == "ocp-min-jerk":
        assert plan.duration == pytest.approx(total, rel=1e-5)
    elif planner == "ocp-min-energy":
        assert plan.duration <= total * (1 + 1e-5)


def test_each_segment_keeps_its_duration_when_the_timing_holds_them(paper_problem):
    """timing = "segments": one row of time a segment; the cut is at each landmark (forward
    kinematics, in the checks) at the times the durations give."""
    uneven = 1.1 * segment_lower_bounds(paper_problem) * np.array([1.0, 1.2, 1.05, 1.1])
    problem = dataclasses.replace(
        paper_problem,
        segment_durations=uneven,
        planner_options={"ocp-min-jerk": {"timing": "segments"}},
    )
    plan = so.plan(problem, "ocp-min-jerk")
    assert plan.metadata["statistics"]["transcription"] == "path"
    assert_within_limits(problem, plan, landmark_tolerance=0.01 * MM)
    visits = np.asarray(plan.metadata["landmark_times_s"])
    np.testing.assert_allclose(np.diff(visits), problem.segment_durations, rtol=1e-5)


def test_without_a_tube_the_planners_work_in_the_time_domain(hardware_problem):
    """The hardware run has no contour tube: "auto" plans in the time domain, where the cut
    is free in joint space."""
    plan = so.plan(hardware_problem, "ocp-min-time")
    assert plan.metadata["statistics"]["transcription"] == "time"


def test_path_coordinates_without_a_tube_stay_within_a_millimetre(hardware_problem):
    """Asked for, path coordinates on the hardware run keep the cut within 1 mm of the
    contour (the checks' own distance to the arcs), where the offset's model holds; it
    uses more than a 0.1 mm tube would give."""
    problem = dataclasses.replace(
        hardware_problem, planner_options={"ocp-min-time": {"transcription": "path"}}
    )
    plan = so.plan(problem, "ocp-min-time")
    assert plan.metadata["statistics"]["transcription"] == "path"
    assert_within_limits(problem, plan)
    q = sample(plan).q
    cut = on_contour(problem, cut_points(q, problem.surface.radius), problem.surface.radius)
    # the offset is the distance to first order: 1 mm of it moved the cut 1.001 mm
    assert 0.1 * MM < np.max(cut.distance) <= 1.0 * MM * (1 + 1e-2)


def _random_point(problem, planner, seed):
    """The stage-wise NLP of ``planner`` on ``problem``, its parameters and a random x
    and multipliers near the start."""
    settings = get_planner(planner).settings(problem)
    limits = path_planner._limits(problem, planner_bounds(problem, settings.margin))
    paths = segment_paths(
        problem, tuple(limits[:4]), path_planner.PATH_SAMPLES, settings.path_grid, (2.0, 0.5)
    )
    layout, nlp = assembled_nlp(
        len(paths), len(paths[0].nodes) - 1, path_planner.objectives(settings), settings.timing
    )
    rng = np.random.default_rng(seed)
    p = np.concatenate([path_planner._path_parameters(problem, paths), limits, rng.random(3)])
    x = path_planner._start(paths, limits, layout) * (1 + 0.1 * rng.random(layout.size))
    x += 0.01 * rng.standard_normal(layout.size)
    return nlp, x, p, rng.standard_normal(layout.rows)


@pytest.mark.parametrize("planner", ["ocp-min-time", "ocp-min-jerk"])
def test_the_assembled_derivatives_are_casadis_own(paper_problem, planner):
    """The stage-wise NLP's Jacobian, gradient and Hessian (the intervals' and the
    landmarks' scattered; with minimum jerk's time row) equal CasADi's automatic
    derivatives of its f and g, at a random point."""
    nlp, x0, p0, lam = _random_point(paper_problem, planner, 3)
    x, p, f, g = (nlp.problem[k] for k in "xpfg")
    automatic = ca.Function(
        "automatic",
        [x, p],
        [
            ca.jacobian(g, x),
            ca.gradient(f, x),
            ca.triu(ca.hessian(0.7 * f + ca.dot(ca.DM(lam), g), x)[0]),
        ],
    )
    jac, grad, hess = (value.full() for value in automatic(x0, p0))
    derivatives = nlp.derivatives
    np.testing.assert_allclose(derivatives["jac_g"](x0, p0)[1].full(), jac, atol=1e-9)
    np.testing.assert_allclose(derivatives["grad_f"](x0, p0)[1].full(), grad, atol=1e-12)
    np.testing.assert_allclose(
        derivatives["hess_lag"](x0, p0, 0.7, lam).full(), hess, atol=1e-9 * np.max(abs(hess))
    )


def test_fatrop_and_ipopt_find_the_same_minimum_time(paper_problem):
    """Minimum time solves with FATROP by default; IPOPT, asked for, reaches the same
    duration (1 ms of 38 s) on the same stage-wise NLP."""
    fatrop = so.plan(paper_problem, "ocp-min-time")
    problem = dataclasses.replace(
        paper_problem, planner_options={"ocp-min-time": {"solver": "ipopt"}}
    )
    by_ipopt = so.plan(problem, "ocp-min-time")
    assert fatrop.metadata["statistics"]["solver"] == "fatrop"
    assert by_ipopt.metadata["statistics"]["solver"] == "ipopt"
    assert fatrop.duration == pytest.approx(by_ipopt.duration, abs=1e-3)
    assert_within_limits(paper_problem, fatrop)


def test_a_solver_that_stops_early_is_named_with_the_one_after_it(paper_problem):
    """Five iterations are too few: FATROP stops, IPOPT tries from the same start and
    stops too, and the error names both."""
    problem = dataclasses.replace(
        paper_problem, planner_options={"ocp-min-time": {"max_iterations": 5}}
    )
    with pytest.raises(so.PlanningError, match="fatrop stopped .* ipopt stopped"):
        so.plan(problem, "ocp-min-time")


def test_fatrop_with_a_fixed_timing_is_refused(paper_problem):
    """FATROP reads rows of one stage; a fixed timing's time row spans them all."""
    problem = dataclasses.replace(
        paper_problem, planner_options={"ocp-min-jerk": {"solver": "fatrop"}}
    )
    with pytest.raises(so.InputError, match="solver = 'fatrop': needs timing = 'free'"):
        so.plan(problem, "ocp-min-jerk")


def test_a_cut_of_one_segment_has_no_landmark_to_pass(paper_problem):
    """An open cut through two landmarks: one segment, no continuity rows; FATROP (minimum
    time) and IPOPT (minimum energy) plan it within every limit."""
    problem = dataclasses.replace(
        paper_problem,
        landmark_names=paper_problem.landmark_names[:2],
        landmarks=paper_problem.landmarks[:2],
        closed=False,
        segment_durations=np.array([10.0]),
    )
    for planner, solver in (("ocp-min-time", "fatrop"), ("ocp-min-energy", "ipopt")):
        plan = so.plan(problem, planner)
        assert plan.metadata["statistics"]["solver"] == solver
        assert_within_limits(problem, plan)
