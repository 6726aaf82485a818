"""The ruckig planner: jerk-limited segments the evaluator finds within every limit but the
contour tube, exact cubic pieces, clear errors, and never a remote waypoint calculation."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import ruckig

import spm_opt as so
from spm_opt.base.ruckig_local import calculate_locally
from spm_opt.model.params import MM
from spm_opt.planners import ruckig as ruckig_planner

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
NAMES = ("craniotomy_bone_flap", "craniotomy_large_flap", "craniotomy_five_landmarks")
MODES = ("stop", "pass-through")


def with_options(problem, **options):
    return dataclasses.replace(problem, planner_options={"ruckig": options})


def with_limits(problem, **limits):
    return dataclasses.replace(problem, limits=dataclasses.replace(problem.limits, **limits))


@pytest.fixture(scope="module", params=NAMES)
def problem(request):
    return so.load_problem(PROBLEMS / f"{request.param}.toml")


@pytest.fixture(scope="module")
def plans(problem):
    """Both via-point modes of one problem, by mode."""
    return {mode: so.plan(with_options(problem, via_points=mode), "ruckig") for mode in MODES}


@pytest.mark.parametrize("mode", MODES)
def test_within_every_limit_but_the_contour_tube(problem, plans, mode):
    """A straight line in joint space is not the great-circle arc on the skull: the contour
    deviation (0.1–0.4 mm here), and the stretches it leaves uncut for it (coverage), are
    the only violations expected."""
    report = so.evaluate(problem, plans[mode])
    assert {v.limit for v in report.violations} <= {"contour deviation", "coverage"}
    assert report.max_tool_speed_mm_s <= problem.limits.max_tool_speed / MM * (1 + 1e-3)
    assert report.max_contour_deviation_mm < 1.0
    if mode == "stop":
        assert report.max_landmark_error_mm <= 0.01


def test_pass_through_is_faster_than_stopping(plans):
    assert plans["pass-through"].duration < plans["stop"].duration
    statistics = plans["pass-through"].metadata["statistics"]
    assert np.any(np.abs(statistics["via_velocities_rad_s"]) > 0)


def test_metadata_names_every_visit_and_segment(problem, plans):
    plan = plans["stop"]
    times, statistics = plan.landmark_times, plan.metadata["statistics"]
    assert plan.metadata["landmarks"] == problem.visit_names
    assert len(times) == len(problem.visit_names) and times[-1] == plan.duration
    np.testing.assert_allclose(np.diff(times), statistics["segment_durations_s"])
    np.testing.assert_array_equal(statistics["via_velocities_rad_s"], 0.0)
    assert statistics["solve_time_s"] > 0.0 and statistics["via_points"] == "stop"
    np.testing.assert_allclose(plan.position(times), problem.waypoint_angles, atol=1e-15)


def test_stop_segments_run_along_the_joint_space_line(paper_problem):
    plan = so.plan(paper_problem, "ruckig")
    waypoints, times = paper_problem.waypoint_angles, plan.landmark_times
    for k in range(len(times) - 1):
        moved = plan.position(np.linspace(times[k], times[k + 1], 501)) - waypoints[k]
        step = waypoints[k + 1] - waypoints[k]
        off_line = moved[:, 0] * step[1] - moved[:, 1] * step[0]
        np.testing.assert_allclose(off_line / np.linalg.norm(step), 0.0, atol=1e-12)


def test_cubic_pieces_reproduce_ruckigs_profile_exactly():
    inp = ruckig.InputParameter(2)
    inp.current_position, inp.target_position = [0.1, -0.2], [0.4, 0.05]
    inp.current_velocity, inp.target_velocity = [0.02, 0.0], [0.0, 0.03]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [0.1, 0.08], [1.0, 1.0], [10.0, 10.0]
    profile = calculate_locally(inp, "test segment")
    pieces = ruckig_planner.cubic_pieces(profile)
    t = np.linspace(0.0, profile.duration, 997)
    expected = np.array([profile.at_time(x) for x in t])  # (N, 3, 2)
    for order in range(3):
        np.testing.assert_allclose(pieces.derivative(order)(t), expected[:, order], atol=1e-14)
    assert np.max(np.abs(pieces.derivative(3)(t))) <= 10.0 * (1 + 1e-9)


def test_open_limits_take_the_documented_stand_ins(paper_problem):
    problem = with_limits(
        paper_problem, max_joint_acceleration=None, max_joint_jerk=None, max_tool_speed=None
    )
    plan = so.plan(with_options(problem, default_acceleration_rad_s2=2.0), "ruckig")
    statistics = plan.metadata["statistics"]
    assert statistics["acceleration_limit_rad_s2"] == 2.0
    assert statistics["jerk_limit_rad_s3"] == ruckig_planner.RuckigSettings.default_jerk_rad_s3
    t = plan.time_grid(1000.0)
    assert np.max(np.abs(plan.acceleration(t))) <= 2.0 * (1 + 1e-9)
    assert np.max(np.abs(plan.velocity(t))) <= problem.limits.max_joint_speed * (1 + 1e-9)


def test_tool_speed_limit_sets_the_pace(paper_problem):
    """Halving the tool-speed limit roughly doubles the cut's duration."""
    fast = so.plan(paper_problem, "ruckig")
    slow_problem = with_limits(paper_problem, max_tool_speed=1.5 * MM)
    slow = so.plan(slow_problem, "ruckig")
    assert 1.9 < slow.duration / fast.duration < 2.1
    assert so.evaluate(slow_problem, slow).max_tool_speed_mm_s <= 1.5 * (1 + 1e-3)


@pytest.mark.parametrize("mode", MODES)
def test_tool_speed_check_lowers_caps_that_are_too_high(paper_problem, monkeypatch, mode):
    """The check on each solved segment is the safety net behind the line bound."""
    line_caps = ruckig_planner.line_speed_caps
    monkeypatch.setattr(ruckig_planner, "line_speed_caps", lambda problem: 1.5 * line_caps(problem))
    problem = with_options(paper_problem, via_points=mode)
    plan = so.plan(problem, "ruckig")
    assert plan.metadata["statistics"]["tool_speed_rounds"] >= 2
    report = so.evaluate(problem, plan)
    assert report.max_tool_speed_mm_s <= problem.limits.max_tool_speed / MM * (1 + 1e-3)


class SpyRuckig:
    """Stands in for ``ruckig.Ruckig``: records every construction and calculation."""

    real = ruckig.Ruckig
    made: list = []
    calls: list = []

    def __init__(self, *args, **kwargs):
        SpyRuckig.made.append((args, kwargs))
        self._generator = SpyRuckig.real(*args, **kwargs)

    def calculate(self, inp, trajectory, *rest):
        SpyRuckig.calls.append(
            (list(inp.intermediate_positions), self._generator.max_number_of_waypoints)
        )
        return self._generator.calculate(inp, trajectory, *rest)


@pytest.fixture
def spy(monkeypatch):
    SpyRuckig.made, SpyRuckig.calls = [], []
    monkeypatch.setattr(ruckig_planner.ruckig, "Ruckig", SpyRuckig)
    return SpyRuckig


@pytest.mark.parametrize("mode", MODES)
def test_never_asks_ruckig_for_intermediate_waypoints(paper_problem, spy, mode):
    """Intermediate waypoints would go to ruckig's remote service: every call must be one
    segment, on a generator built for 2 joints with no waypoint capacity."""
    so.plan(with_options(paper_problem, via_points=mode), "ruckig")
    assert len(spy.calls) >= 4
    assert spy.made and all(made == ((2,), {}) for made in spy.made)
    assert all(waypoints == [] and capacity == 0 for waypoints, capacity in spy.calls)


def test_guard_refuses_intermediate_positions(spy):
    inp = ruckig.InputParameter(2)
    inp.target_position, inp.intermediate_positions = [0.1, 0.1], [[0.05, 0.0]]
    with pytest.raises(so.PlanningError, match="segment 3: refusing 1 intermediate positions"):
        calculate_locally(inp, "segment 3")
    assert spy.made == [] and spy.calls == []


def test_ruckig_errors_name_the_segment():
    inp = ruckig.InputParameter(2)
    inp.target_position, inp.max_velocity = [0.1, 0.1], [-1.0, 1.0]
    with pytest.raises(so.PlanningError, match=r"^ruckig: segment 2 \(A2 -> A3\): \[ruckig\]"):
        calculate_locally(inp, "segment 2 (A2 -> A3)")


def test_a_failed_result_is_a_planning_error_in_words(paper_problem, monkeypatch):
    class Failing:
        def __init__(self, dofs):
            pass

        def calculate(self, inp, trajectory):
            return ruckig.Result.ErrorSynchronizationCalculation

    monkeypatch.setattr(ruckig_planner.ruckig, "Ruckig", Failing)
    message = r"segment 1 \(A1 -> A2\): ruckig could not synchronise the joints"
    with pytest.raises(so.PlanningError, match=message):
        so.plan(paper_problem, "ruckig")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"via_points": "fly"}, r"planner.ruckig.via_points = 'fly': expected one of stop"),
        ({"default_jerk_rad_s3": 0}, r"planner.ruckig.default_jerk_rad_s3 = 0: expected a num"),
        ({"default_acceleration_rad_s2": "big"}, r"default_acceleration_rad_s2 = 'big': exp"),
        ({"default_acceleration_rad_s2": True}, r"default_acceleration_rad_s2 = True: exp"),
        ({"colour": 1}, r"planner.ruckig.colour: unknown key"),
    ],
)
def test_bad_settings_are_one_line_errors(paper_problem, options, message):
    with pytest.raises(so.InputError, match=message):
        so.plan(with_options(paper_problem, **options), "ruckig")
