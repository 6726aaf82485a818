"""The executed cut, judged: logs written by hand with known errors, checked against
distances computed here from the paper's kinematics and dense polylines, and a run of the
simulated robot with a joint displaced by hand."""

from __future__ import annotations

import dataclasses
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree
from test_evaluate import meridian_problem

import spm_opt as so
from spm_opt.base.errors import InputError
from spm_opt.execution.log import LogWriter
from spm_opt.execution.plant import StateTrace
from spm_opt.model import dynamics
from spm_opt.model.params import DEG, MM
from spm_opt.verify.executed_cut import (
    ExecutionReport,
    _peaks_between,
    evaluate_log,
    is_execution_log,
)
from spm_opt.verify.log_estimates import smoothed_derivatives

ROOT = Path(__file__).resolve().parents[1]
PERIOD = 0.01  # s: the logs' 100 Hz
RADIUS = 0.07  # m: the meridian problem's skull
VELOCITY_QUANTUM = 0.00199234 * 2 * np.pi / 60  # rad/s: one Present Velocity unit


# --- independent references ---------------------------------------------------------------


def direction(q: np.ndarray) -> np.ndarray:
    """Eq. 5 written out: the tool's unit direction b ∝ (C1 S2, −S1 C2, C1 C2)."""
    c1, s1, c2, s2 = np.cos(q[:, 0]), np.sin(q[:, 0]), np.cos(q[:, 1]), np.sin(q[:, 1])
    b = np.column_stack([c1 * s2, -s1 * c2, c1 * c2])
    return b / np.linalg.norm(b, axis=1, keepdims=True)


def dense_contour(problem: so.Problem, per_arc: int = 40_000) -> np.ndarray:
    """The planned contour as points (M, 3), m: each arc the great circle between its
    landmarks (slerp), at the skull's radius in each direction (the problem's surface)."""
    landmarks = problem.landmarks[problem.visit_order]
    points = []
    for a, b in zip(landmarks[:-1], landmarks[1:], strict=True):
        ua, ub = a / np.linalg.norm(a), b / np.linalg.norm(b)
        sweep = np.arccos(np.clip(ua @ ub, -1.0, 1.0))
        phi = np.linspace(0.0, sweep, per_arc)[:, None]
        unit = (np.sin(sweep - phi) * ua + np.sin(phi) * ub) / np.sin(sweep)
        points.append(problem.surface.radius(unit)[:, None] * unit)
    return np.vstack(points)


def deviation_from_polyline(problem: so.Problem, q: np.ndarray, contour: np.ndarray) -> np.ndarray:
    """Distance (N,), m, of the cut at joint angles q from the dense contour: the cut point
    on the skull in the tool's direction, to the contour point nearest it by angle."""
    unit_contour = contour / np.linalg.norm(contour, axis=1, keepdims=True)
    _, nearest = cKDTree(unit_contour).query(direction(q))
    cut = problem.surface.radius(direction(q))[:, None] * direction(q)
    return np.linalg.norm(cut - contour[nearest], axis=1)


def distance_to_polyline(point: np.ndarray, vertices: np.ndarray) -> float:
    """Distance, m, from a point to the polyline through ``vertices`` (K, 3)."""
    start, step = vertices[:-1], np.diff(vertices, axis=0)
    along = np.clip(np.einsum("ij,ij->i", point - start, step) / np.sum(step**2, axis=1), 0, 1)
    return float(np.min(np.linalg.norm(start + along[:, None] * step - point, axis=1)))


# --- logs written by hand -------------------------------------------------------------------


def write_log(
    path: Path,
    problem: so.Problem,
    t: np.ndarray,
    measured: np.ndarray,
    reference: np.ndarray,
    *,
    velocity: np.ndarray | None = None,
    torque: np.ndarray | None = None,
    feed: np.ndarray | None = None,
    phases: list[str] | None = None,
    failed: frozenset[int] = frozenset(),
    outcome: dict | None = None,
    planner: str = "by hand",
) -> Path:
    """A log with the executor's writer: ``measured`` angles (N, 2) at times t, the
    plan's ``reference``; velocity by default the measured angles' gradient, torque 0."""
    n = len(t)
    velocity = np.gradient(measured, t, axis=0) if velocity is None else velocity
    torque = np.zeros((n, 2)) if torque is None else torque
    current = problem.robot.actuator.current_map.current(torque)
    feed = np.ones(n) if feed is None else feed
    phases = ["plan"] * n if phases is None else phases
    header = {
        "plan": {"planner": planner},
        "problem": problem.record(),
        "settings": {"rate_hz": 1.0 / PERIOD},
        "clock_origin_s": 0.0,
    }
    writer = LogWriter(path, header)
    for k in range(n):
        along = (t[k], feed[k], feed[k]) if phases[k] == "plan" else None
        read = None if k in failed else (measured[k], velocity[k], current[k], torque[k])
        status = "read failed: no reply" if k in failed else "ok"
        errors = None if k in failed else (0, 0)
        writer.append(t[k], phases[k], along, reference[k], reference[k], read, errors, status)
    writer.close({"completed": True, "reason": "completed"} if outcome is None else outcome)
    return path


def meridian_sweep(duration: float = 20.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """θ1 from 0 to 0.4 rad by a quintic from rest to rest, θ2 = 0: times, angles, rates."""
    t = np.arange(0.0, duration + PERIOD / 2, PERIOD)
    tau = t / duration
    q = np.column_stack([0.4 * (10 * tau**3 - 15 * tau**4 + 6 * tau**5), np.zeros_like(t)])
    qd = np.column_stack([0.4 * 30 * tau**2 * (1 - tau) ** 2 / duration, np.zeros_like(t)])
    return t, q, qd


@pytest.fixture(scope="module")
def meridian(paper_problem: so.Problem) -> so.Problem:
    """Two landmarks 0.4 rad apart on the y-z great circle, 70 mm from the isocenter."""
    return meridian_problem(paper_problem, 0.4)


@settings(max_examples=15, deadline=None)
@given(offset=st.floats(-3e-3, 3e-3))
def test_a_joint_offset_gives_the_deviation_of_the_papers_kinematics(meridian, offset):
    """θ2 held off by δ while θ1 sweeps the meridian: the cut is off the y-z plane by
    asin(b_x), a chord of 2ρ sin(asin(b_x)/2) from the contour."""
    t, q, qd = meridian_sweep()
    measured = q + [0.0, offset]
    with tempfile.TemporaryDirectory() as folder:
        log = write_log(Path(folder) / "run.csv", meridian, t, measured, q, velocity=qd)
        report = evaluate_log(meridian, log).measured
    off = np.arcsin(np.abs(direction(measured)[:, 0]))
    expected = np.max(2 * RADIUS * np.sin(off / 2)) / MM
    assert report.max_contour_deviation_mm == pytest.approx(expected, rel=1e-6, abs=1e-6)
    assert report.max_tracking_error_deg == pytest.approx([0.0, abs(offset) / DEG], abs=1e-7)
    assert report.rms_tracking_error_deg == pytest.approx([0.0, abs(offset) / DEG], abs=1e-7)
    broken = "contour deviation" in [v.rule for v in report.violations]
    if abs(expected - 0.1005) > 1e-6:  # the tube, 0.1 mm, and the evaluator's 0.5 %
        assert broken == (expected > 0.1005)


@pytest.fixture(scope="module")
def hardware_toppra(hardware_problem: so.Problem) -> tuple[so.Problem, so.Trajectory]:
    """The hardware problem with a 0.2 mm tube, and its toppra plan."""
    limits = dataclasses.replace(hardware_problem.limits, contour_tolerance=0.2 * MM)
    problem = dataclasses.replace(hardware_problem, limits=limits)
    return problem, so.plan(problem, "toppra")


@pytest.mark.parametrize("offset_deg", [(0.05, -0.03), (0.0, 0.1), (-0.08, 0.0)])
def test_the_flap_displaced_matches_a_dense_polyline(hardware_toppra, offset_deg, tmp_path):
    problem, plan = hardware_toppra
    t = np.arange(0.0, plan.duration, PERIOD)
    q, qd, _, _ = plan.states(t)
    measured = q + np.radians(offset_deg)
    report = evaluate_log(
        problem, write_log(tmp_path / "run.csv", problem, t, measured, q)
    ).measured
    expected = deviation_from_polyline(problem, measured, dense_contour(problem))
    assert report.max_contour_deviation_mm == pytest.approx(np.max(expected) / MM, abs=1e-4)
    assert report.rms_contour_deviation_mm == pytest.approx(
        np.sqrt(np.trapezoid(expected**2, t) / (t[-1] - t[0])) / MM, abs=1e-4
    )
    # each landmark's error: its distance from the measured cut's polyline, near its visit
    cut = direction(measured)
    for visit, claimed in zip(report.landmark_errors_mm, plan.landmark_times, strict=True):
        landmark = problem.landmarks[problem.landmark_names.index(visit["landmark"])]
        radius = np.linalg.norm(landmark)
        near = np.abs(t - claimed) < 0.3
        expected_error = radius * distance_to_polyline(landmark / radius, cut[near])
        assert visit["error_mm"] == pytest.approx(expected_error / MM, abs=1e-6)
        assert abs(visit["time_s"] - claimed) < 0.3


def test_a_log_of_the_plan_itself_gives_the_plans_figures(hardware_toppra, tmp_path):
    problem, plan = hardware_toppra
    t = np.append(np.arange(0.0, plan.duration, PERIOD), plan.duration)
    q, qd, qdd, _ = plan.states(t)
    torque = dynamics.actuator_torque(problem.robot, q, qd, qdd)
    log = write_log(tmp_path / "run.csv", problem, t, q, q, velocity=qd, torque=torque)
    logged, planned = evaluate_log(problem, log).measured, so.evaluate(problem, plan)
    assert logged.violations == planned.violations == []
    assert logged.max_contour_deviation_mm < 1e-6 and planned.max_contour_deviation_mm < 1e-6
    assert logged.max_landmark_error_mm < 1e-3
    assert logged.coverage_gap_mm < 1e-3 and logged.max_backtrack_mm < 1e-6
    assert logged.max_tracking_error_deg == [0.0, 0.0]
    assert logged.duration_s == pytest.approx(planned.duration_s)
    for name in ("peak_joint_speed_rad_s", "peak_torque_nm"):
        assert getattr(logged, name) == pytest.approx(getattr(planned, name), rel=2e-3), name
    for name in ("max_tool_speed_mm_s", "mean_tool_speed_mm_s", "energy_j"):
        assert getattr(logged, name) == pytest.approx(getattr(planned, name), rel=5e-3), name
    # the smoother never raises a peak, and rounds this plan's off by less than 0.5 %
    for got, peak in zip(
        logged.peak_joint_acceleration_rad_s2, planned.peak_joint_acceleration_rad_s2, strict=True
    ):
        assert 0.995 * peak <= got <= peak


# --- the smoother ---------------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(
    amplitudes=st.lists(st.floats(0.01, 1.0), min_size=3, max_size=3),
    frequencies=st.lists(st.floats(0.1, 3.0), min_size=3, max_size=3),
    phases=st.lists(st.floats(0.0, 6.3), min_size=3, max_size=3),
)
def test_smoothing_never_raises_a_peak(amplitudes, frequencies, phases):
    """A sum of sinusoids as the rate: the smoothed derivatives stay within the largest
    magnitude of the true ones (computed here, on a dense grid)."""
    terms = list(zip(amplitudes, 2 * np.pi * np.array(frequencies), phases, strict=True))

    def derivative(t: np.ndarray, order: int) -> np.ndarray:
        return sum(a * w**order * np.sin(w * t + p + order * np.pi / 2) for a, w, p in terms)

    t = np.arange(0.0, 4.0, PERIOD)
    acceleration, jerk = smoothed_derivatives(t, derivative(t, 0)[:, None], PERIOD)
    dense = np.linspace(0.0, 4.0, 20_001)
    assert np.max(np.abs(acceleration)) <= np.max(np.abs(derivative(dense, 1))) * (1 + 1e-9)
    assert np.max(np.abs(jerk)) <= np.max(np.abs(derivative(dense, 2))) * (1 + 1e-9)


def test_smoothing_is_exact_on_a_quadratic_and_its_noise_floor_is_the_documented_one():
    t = np.arange(0.0, 3.0, PERIOD)
    rate = np.column_stack([0.3 - 0.2 * t + 0.05 * t**2, 1.1 * t - 0.4 * t**2])
    acceleration, jerk = smoothed_derivatives(t, rate, PERIOD)
    inside = slice(2, -2)  # the acceleration's ends hold the rate beyond the log
    exact = np.column_stack([-0.2 + 0.1 * t, 1.1 - 0.8 * t])
    np.testing.assert_allclose(acceleration[inside], exact[inside], atol=1e-9)
    np.testing.assert_allclose(jerk, np.tile([0.1, -0.8], (len(t), 1)), atol=1e-9)
    # the velocity rounded to its unit: at most 0.0063 rad/s² and 0.20 rad/s³ off
    rounded = VELOCITY_QUANTUM * np.round(rate / VELOCITY_QUANTUM)
    noisy_acceleration, noisy_jerk = smoothed_derivatives(t, rounded, PERIOD)
    assert np.max(np.abs(noisy_acceleration - acceleration)) <= 0.0063
    assert np.max(np.abs(noisy_jerk - jerk)) <= 0.205


# --- the feed, the rows judged, the header ---------------------------------------------------


@pytest.mark.parametrize(
    ("pace", "feed", "broken"),
    [
        pytest.param(1.5, 1.0, True, id="faster-than-planned-at-feed-1"),
        pytest.param(1.5, 1.5, False, id="faster-at-the-feed-asked-for"),
        pytest.param(1.0, 0.5, False, id="a-feed-below-1-keeps-the-plain-limit"),
    ],
)
def test_the_tool_speed_limit_is_scaled_by_the_feed_in_force(
    meridian, pace, feed, broken, tmp_path
):
    """The sweep peaks at 2.6 mm/s on the skull; run 1.5 times as fast, 3.9 mm/s, beyond
    the problem's 3 mm/s unless the log's feed says 1.5."""
    t, q, qd = meridian_sweep(20.0 / pace)
    log = write_log(
        tmp_path / "run.csv", meridian, t, q, q, velocity=qd, feed=np.full(len(t), feed)
    )
    report = evaluate_log(meridian, log).measured
    peak = RADIUS * np.max(qd[:, 0]) / MM
    assert report.max_tool_speed_mm_s == pytest.approx(peak, rel=1e-6)
    speed = [v for v in report.violations if v.rule == "tool speed"]
    assert bool(speed) == broken
    if broken:
        assert speed[0].allowed == pytest.approx(3.0 * max(1.0, feed))


def test_failed_reads_are_left_out_and_a_log_cut_short_is_judged(meridian, tmp_path):
    t, q, qd = meridian_sweep()
    failed = frozenset(range(500, 505))
    log = write_log(tmp_path / "run.csv", meridian, t, q, q, velocity=qd, failed=failed, outcome={})
    report = evaluate_log(meridian, log).measured
    assert report.failed_reads_skipped == 5
    assert report.rows_judged == len(t) - 5
    assert not report.completed and "cut short" in report.outcome
    markdown = report.to_markdown()
    assert "The run did not complete" in markdown and "5 row(s) whose read failed" in markdown
    stopped = write_log(
        tmp_path / "stopped.csv",
        meridian,
        t,
        q,
        q,
        velocity=qd,
        outcome={"completed": False, "reason": "following error of theta1"},
    )
    report = evaluate_log(meridian, stopped).measured
    assert not report.completed and report.outcome == "following error of theta1"


def test_the_approach_is_not_judged_and_the_stop_after_it_is(meridian, tmp_path):
    """Rows before the plan (3.5 mm off the contour) are left out; rows after it are in."""
    t, q, qd = meridian_sweep()
    off = q + [0.0, 0.05]
    both = np.vstack([off[:100], q, q[-1:].repeat(50, axis=0) + [0.0, 0.001]])
    times = np.arange(len(both)) * PERIOD
    phases = ["approach"] * 100 + ["plan"] * len(t) + ["stop"] * 50
    log = write_log(tmp_path / "run.csv", meridian, times, both, both, phases=phases)
    report = evaluate_log(meridian, log).measured
    assert report.rows_judged == len(t) + 50
    off = np.arcsin(np.abs(direction(both[-1:])[0, 0]))  # the stop's, at θ1 = 0.4 rad
    assert report.max_contour_deviation_mm == pytest.approx(2 * RADIUS * np.sin(off / 2) / MM)


def test_a_log_is_judged_under_the_problem_it_ran_under(meridian, paper_problem, tmp_path):
    t, q, qd = meridian_sweep()
    log = write_log(tmp_path / "run.csv", meridian, t, q, q, velocity=qd)
    with pytest.raises(InputError, match="ran under craniotomy_bone_flap.*--other-problem"):
        evaluate_log(paper_problem, log)
    assert evaluate_log(paper_problem, log, other_problem=True).measured.rows_judged == len(t)


def test_a_logs_late_goals_are_counted_and_a_damaged_record_of_them_is_named(meridian, tmp_path):
    t, q, qd = meridian_sweep()
    late = {"threshold_s": 0.002, "count": 3, "latest_s": 0.006, "first": [[1.0, 0.006]]}
    timing = {"read_s": 0.0, "goal_written_s": 0.0, "late_goals": late}
    outcome = {"completed": True, "reason": "completed", "cycle_timing": timing}
    log = write_log(tmp_path / "run.csv", meridian, t, q, q, velocity=qd, outcome=outcome)
    report = evaluate_log(meridian, log).measured
    assert (report.late_goals, report.latest_goal_ms) == (3, pytest.approx(6.0))
    late["first"] = [[1.0, 0.006, "lots"]]
    damaged = write_log(tmp_path / "damaged.csv", meridian, t, q, q, velocity=qd, outcome=outcome)
    with pytest.raises(InputError, match=r"^log header: cycle_timing.late_goals: expected"):
        evaluate_log(meridian, damaged)


def test_evaluate_takes_a_log_or_a_trajectory_by_its_path(meridian, hardware_problem, tmp_path):
    t, q, qd = meridian_sweep()
    log = write_log(tmp_path / "run.csv", meridian, t, q, q, velocity=qd)
    report = so.evaluate(meridian, str(log))
    assert isinstance(report, ExecutionReport) and is_execution_log(log)
    same = evaluate_log(meridian, log).measured.to_dict()
    assert json.dumps(report.to_dict()) == json.dumps(same)
    plan = so.plan(hardware_problem, "cubic")
    plan.to_csv(tmp_path / "plan.csv")
    assert not is_execution_log(tmp_path / "plan.csv")
    from_path = so.evaluate(hardware_problem, tmp_path / "plan.csv")
    read = so.Trajectory.from_csv(tmp_path / "plan.csv")
    assert from_path.to_dict() == so.evaluate(hardware_problem, read).to_dict()


# --- a run of the simulated robot -------------------------------------------------------


@pytest.fixture(scope="module")
def simulated_run(hardware_toppra, tmp_path_factory):
    """The toppra plan run on the simulated robot driving the plant robot: the log, its
    true state, the reports and each joint's largest speed over every step of the plant
    (1 ms; the log reads it every 10 ms), recorded here."""
    problem, plan = hardware_toppra
    folder = tmp_path_factory.mktemp("simulated")
    plant = so.load_robot(ROOT / "problems" / "robots" / "prototype_plant.toml")
    backend = so.SimulatedRobot(problem.robot, start_rad=plan.position(0.0), plant_robot=plant)
    fastest = np.zeros(2)
    step = backend.plant._step

    def recorded_step() -> None:
        step()
        np.maximum(fastest, np.abs(backend.plant.velocity_rad_s), out=fastest)

    backend.plant._step = recorded_step
    result = so.execute(plan, backend, problem, folder / "run.csv", so.ExecutionSettings())
    assert result.completed
    backend.trace.save(folder / "true.npz")
    reports = evaluate_log(problem, folder / "run.csv", folder / "true.npz")
    return folder, reports, fastest


def test_a_simulated_run_is_judged_measured_and_true(simulated_run):
    folder, reports, _ = simulated_run
    measured, true = reports.measured, reports.true
    assert measured.completed and measured.angles == "measured" and true.angles == "true"
    assert "contour deviation" not in [v.rule for v in measured.violations + true.violations]
    table, header = so.read_log(folder / "run.csv")
    plan_rows = table[table["phase"] == "plan"]
    reference = plan_rows[["reference_theta1_rad", "reference_theta2_rad"]].to_numpy()
    angles = plan_rows[["position_theta1_rad", "position_theta2_rad"]].to_numpy()
    expected = np.max(np.abs(angles - reference), axis=0) / DEG
    assert measured.max_tracking_error_deg == pytest.approx(expected.tolist(), rel=1e-9)
    trace = StateTrace.load(folder / "true.npz", header["clock_origin_s"])
    t = plan_rows["time_s"].to_numpy()
    truth = np.column_stack(
        [np.interp(t, trace["time_s"], trace["position_rad"][:, j]) for j in range(2)]
    )
    expected = np.max(np.abs(truth - reference), axis=0) / DEG
    assert true.max_tracking_error_deg == pytest.approx(expected.tolist(), rel=1e-6)
    assert max(measured.max_tracking_error_deg) < 0.5
    assert "without the encoder offsets" in true.to_markdown()


def test_the_true_speed_is_judged_between_the_reads(simulated_run):
    """Each goal is a step the loops answer within the 10 ms period: the plant's speed
    peaks between two reads. The true cut's joint speed is the largest over every step of
    the plant (recorded by the fixture, not by the trace), above any read's; at the full
    pace of a plan at its speed limit, θ1's peak breaks the limit, which the reads alone
    would not show."""
    folder, reports, fastest = simulated_run
    true = reports.true
    assert true.peak_joint_speed_rad_s == pytest.approx(fastest.tolist(), rel=1e-12)
    table, header = so.read_log(folder / "run.csv")
    trace = StateTrace.load(folder / "true.npz", header["clock_origin_s"])
    at_reads = np.max(np.abs(trace["velocity_rad_s"]), axis=0)
    assert np.all(fastest > at_reads)
    limit = true.joint_speed_limit_rad_s
    assert at_reads[0] < limit < fastest[0]
    assert [v.limit for v in true.violations] == ["theta1 speed"]
    shares = [true.limit_shares[f"theta{j} speed"] for j in (1, 2)]
    assert shares == pytest.approx((fastest / limit).tolist(), rel=1e-12)


@settings(max_examples=200, deadline=None)
@example(samples=[199], rows=[209], seed=0)  # a sample one period before the first row
@given(
    st.lists(st.integers(0, 400), min_size=1, max_size=60, unique=True),
    st.lists(st.integers(0, 400), min_size=1, max_size=20, unique=True),
    st.integers(0, 2**32 - 1),
)
def test_the_peak_over_each_row_s_span_is_every_sample_s_in_it(samples, rows, seed):
    """Each row's peak is the largest of the trace samples after the row before (the
    first: after one period before it), up to and at the row, by a loop over the rows;
    0 where none falls in the span. Times on a 1 ms grid, as the plant steps."""
    times, at = np.sort(samples) * 1e-3, np.sort(rows) * 1e-3
    peaks = np.random.default_rng(seed).uniform(0.0, 2.0, (len(times), 2))
    period = 0.01
    expected = np.zeros((len(at), 2))
    for k, row in enumerate(at):
        after = at[k - 1] if k else row - period
        inside = (times > after) & (times <= row)
        if inside.any():
            expected[k] = peaks[inside].max(axis=0)
    np.testing.assert_array_equal(_peaks_between(times, peaks, at, period), expected)


def test_a_joint_displaced_mid_run_shows_a_contour_violation_then(
    simulated_run, hardware_toppra, tmp_path
):
    """θ1 moved by 1° over 0.9–1.2 s in a copy of the log: the contour deviation is broken
    at the time the distance computed here from a dense polyline is largest."""
    problem, _ = hardware_toppra
    folder, _, _ = simulated_run
    table = pd.read_csv(folder / "run.csv")
    window = (table["time_s"] >= 0.9) & (table["time_s"] <= 1.2)
    table.loc[window, "position_theta1_rad"] += 1.0 * DEG
    table.to_csv(tmp_path / "run.csv", index=False)
    shutil.copy(folder / "run.json", tmp_path / "run.json")
    report = evaluate_log(problem, tmp_path / "run.csv").measured
    (violation,) = [v for v in report.violations if v.rule == "contour deviation"]
    assert 0.9 <= violation.time_s <= 1.2
    rows = table[table.index >= table.index[table["phase"] == "plan"][0]]
    q = rows[["position_theta1_rad", "position_theta2_rad"]].to_numpy()
    distance = deviation_from_polyline(problem, q, dense_contour(problem))
    assert violation.time_s == rows["time_s"].iloc[int(np.argmax(distance))]
    assert violation.worst == pytest.approx(np.max(distance) / MM, abs=1e-4)
    plan_rows = table[table["phase"] == "plan"]
    error = plan_rows["position_theta1_rad"] - plan_rows["reference_theta1_rad"]
    assert report.max_tracking_error_deg[0] == pytest.approx(np.max(np.abs(error)) / DEG)
    assert report.max_tracking_error_deg[0] > 0.9


def test_the_command_line_prints_the_measured_and_the_true_cut(
    simulated_run, hardware_toppra, tmp_path, capsys
):
    from spm_opt.cli import main

    problem, _ = hardware_toppra
    folder, reports, _ = simulated_run
    # the log ran under the widened tube, which no file holds: judge it under the file's
    args = [str(ROOT / "problems" / "craniotomy_hardware.toml"), str(folder / "run.csv")]
    assert main(["evaluate", *args, "--trace", str(folder / "true.npz"), "--other-problem"]) == 1
    captured = capsys.readouterr()
    assert "## The measured cut" in captured.out and "## The true cut" in captured.out
    assert captured.err == "spm-opt: the true cut: 1 violations (joint speed)\n"
    assert main(["evaluate", *args, "--other-problem", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["angles"] == "measured"
    assert data["max_tracking_error_deg"] == reports.measured.max_tracking_error_deg
