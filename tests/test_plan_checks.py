"""The independent plan checks (tests/plan_checks.py) can fail: the minimum-time plan of the
paper's flap passes them, and each change that breaks one limit is caught by its name."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from plan_checks import RATE_HZ, violations
from scipy.interpolate import PPoly

import spm_opt as so
from spm_opt.model import dynamics
from spm_opt.model.params import MM


@pytest.fixture(scope="module")
def plan(paper_problem: so.Problem) -> so.Trajectory:
    return so.plan(paper_problem, "ocp-min-time")


@pytest.fixture(scope="module")
def states(plan: so.Trajectory) -> tuple[np.ndarray, ...]:
    """The plan's own q, q̇, q̈ and jerk on the evaluator's grid (to set limits by)."""
    return plan.states(plan.time_grid(RATE_HZ))


def broken(problem: so.Problem, trajectory: so.Trajectory) -> list[str]:
    """The limits the checks find broken, by name."""
    return [found.limit for found in violations(problem, trajectory)]


def with_limits(problem: so.Problem, **limits: float) -> so.Problem:
    return dataclasses.replace(problem, limits=dataclasses.replace(problem.limits, **limits))


def window(t: np.ndarray, middle: float, width: float) -> tuple[np.ndarray, ...]:
    """w = sin⁴(π s) for s = (t − middle) / width + 1/2 in [0, 1], else 0, and its first
    two derivatives in t: a bump of height 1 whose every derivative up to the jerk starts
    and ends at 0."""
    s = np.clip((t - middle) / width + 0.5, 0.0, 1.0)
    sine, cosine, rate = np.sin(np.pi * s), np.cos(np.pi * s), np.pi / width
    return (
        sine**4,
        4.0 * sine**3 * cosine * rate,
        (12.0 * sine**2 * cosine**2 - 4.0 * sine**4) * rate**2,
    )


def uniform(trajectory: so.Trajectory) -> np.ndarray:
    """A uniform grid at 1 kHz over the plan (no sample a hair from a breakpoint, where
    quintic pieces through samples would take a large jerk from rounding)."""
    return np.linspace(trajectory.start_time, trajectory.end_time, round(trajectory.duration * 1e3))


def mid_segment(trajectory: so.Trajectory, segment: int) -> float:
    """The time, s, halfway between the visits that begin and end ``segment``."""
    times = trajectory.landmark_times
    return float(times[segment] + times[segment + 1]) / 2.0


def test_the_clean_plan_passes(paper_problem, plan):
    assert broken(paper_problem, plan) == []


def test_a_plan_run_5_percent_faster_breaks_the_tool_speed(paper_problem, plan):
    """Minimum time runs the tool at its limit; 5 % faster is 4 % over the allowance."""
    assert broken(paper_problem, plan.time_scaled(1.05)) == ["tool speed"]


@pytest.mark.parametrize(
    ("limit", "state", "name"),
    [
        ("max_joint_speed", 1, "speed"),
        ("max_joint_acceleration", 2, "acceleration"),
        ("max_joint_jerk", 3, "jerk"),
    ],
)
def test_a_joint_limit_5_percent_below_the_plans_peak_is_broken(
    paper_problem, plan, states, limit, state, name
):
    peaks = np.max(np.abs(states[state]), axis=0)
    found = broken(with_limits(paper_problem, **{limit: 0.95 * np.max(peaks)}), plan)
    assert f"theta{np.argmax(peaks) + 1} {name}" in found
    assert set(found) <= {f"theta1 {name}", f"theta2 {name}"}


def test_a_torque_limit_5_percent_below_the_plans_peak_is_broken(paper_problem, plan, states):
    """The peak by the exact model at the plan's own derivatives."""
    torque = dynamics.actuator_torque(paper_problem.robot, *states[:3])
    peaks = np.max(np.abs(torque), axis=0)
    found = broken(with_limits(paper_problem, max_joint_torque=0.95 * np.max(peaks)), plan)
    assert f"theta{np.argmax(peaks) + 1} torque" in found
    assert set(found) <= {"theta1 torque", "theta2 torque"}


def test_a_joint_range_the_cut_swings_past_is_broken(paper_problem, plan, states):
    """θ1's upper end between the highest landmark (which must stay in range) and the
    plan's highest θ1, 1.4e-4 rad above it (the cut rounding a corner inside the tube)."""
    highest = np.max(states[0][:, 0])
    landmark = np.max(paper_problem.landmark_angles[:, 0])
    assert highest - landmark > 1e-4
    robot = paper_problem.robot
    narrow = ((robot.joint_range[0][0], (highest + landmark) / 2.0), robot.joint_range[1])
    problem = dataclasses.replace(
        paper_problem, robot=dataclasses.replace(robot, joint_range=narrow)
    )
    assert broken(problem, plan) == ["theta1 range"]


def test_a_visit_recorded_late_misses_its_landmark(paper_problem, plan):
    """The third landmark's visit said to be 0.2 s later: about 0.6 mm past it."""
    times = plan.landmark_times.copy()
    times[2] += 0.2
    same = PPoly(plan.local_coefficients(), plan.breakpoints)
    late = so.Trajectory(same, {**plan.metadata, "landmark_times_s": times.tolist()})
    assert broken(paper_problem, late) == ["landmark A3 visit"]


def test_a_cut_pushed_off_the_contour_leaves_the_tube(paper_problem, plan):
    """The plan slowed to 80 % (room for the tool's speed) and pushed 0.2 mm across its path
    for 4 s in the middle of the second segment: 0.2 mm from the contour (the tube 0.07)."""
    slow = plan.time_scaled(0.8)
    t = uniform(slow)
    q, qd, qdd, _ = slow.states(t)
    w = window(t, mid_segment(slow, 1), 4.0)
    rate = slow.velocity([mid_segment(slow, 1)])[0]
    across = np.array([-rate[1], rate[0]]) / np.linalg.norm(rate)  # ⟂ the path in q
    offset = 0.2 * MM / np.linalg.norm(paper_problem.landmarks[1])  # rad, for 0.2 mm
    pushed = [x + offset * part[:, None] * across for x, part in zip((q, qd, qdd), w, strict=True)]
    assert broken(paper_problem, so.Trajectory.from_samples(t, *pushed, slow.metadata)) == [
        "contour tube"
    ]


def test_a_cut_that_runs_back_a_little_is_caught(paper_problem, plan):
    """The plan slowed to a quarter and its time warped, σ(t) = t − A w(t) for 1 s mid-way
    through the second segment, so that σ̇ dips to −0.5: the cut runs 0.05 mm back along the
    contour, inside the 0.07 mm the problem's path tolerance allows (the evaluator passes
    it), but a cut that runs back at all is caught."""
    slow = plan.time_scaled(0.25)
    t = uniform(slow)
    w, dw, ddw = window(t, mid_segment(slow, 1), 1.0)
    amplitude = 0.367  # s: σ̇ = 1 − A ẇ, ẇ peaks at 4.08 / width
    sigma, rate, curvature = t - amplitude * w, 1.0 - amplitude * dw, -amplitude * ddw
    q, qd, qdd, _ = slow.states(sigma)
    warped = so.Trajectory.from_samples(
        t,
        q,
        qd * rate[:, None],
        qdd * rate[:, None] ** 2 + qd * curvature[:, None],
        slow.metadata,
    )
    assert so.evaluate(paper_problem, warped).max_backtrack_mm < 0.07
    assert broken(paper_problem, warped) == ["backtracking"]


def test_a_plan_that_starts_moving_is_caught(paper_problem, plan):
    """q̇(0) = 1e-3 rad/s (five of the actuators' velocity units), the offset v₀ t e^(−t/τ)
    gone within a second: no rest at the start, and the sudden start is a large jerk."""
    t = uniform(plan)
    q, qd, qdd, _ = plan.states(t)
    v0, tau = 1e-3, 0.1
    decay = np.exp(-t / tau)[:, None]
    moving = so.Trajectory.from_samples(
        t,
        q + v0 * t[:, None] * decay,
        qd + v0 * (1.0 - t[:, None] / tau) * decay,
        qdd + v0 * (t[:, None] / tau - 2.0) / tau * decay,
        plan.metadata,
    )
    found = broken(paper_problem, moving)
    assert "rest at the start" in found and "rest at the end" not in found
    assert {"theta1 jerk", "theta2 jerk"} <= set(found)
