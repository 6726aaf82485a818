"""A plan slowed where the robot's joints break away from rest: the same path at a lower
pace there, and a true run that keeps the robot's limits the unslowed plan's run breaks."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from test_bad_inputs import assert_one_error, run_cli
from test_predicted_cut import FLAP, PLANT

import spm_opt as so
from spm_opt.execution import Executor, SimulatedRobot
from spm_opt.judge.limits import ROBOT_RULES
from spm_opt.problem.retiming import CREEP_RAD_S, breakaway_times, slowed_near
from spm_opt.problem.trajectory import Trajectory
from spm_opt.verify.breakaway import FEED_RESOLUTION, slowed_for_breakaways
from spm_opt.verify.compensation import compensate
from spm_opt.verify.executed_cut import evaluate_log

ROOT = Path(__file__).resolve().parents[1]
IDENTIFIED = ROOT / "docs" / "identification" / "identified.toml"


def swing(duration_s: float = 8.0) -> Trajectory:
    """θ1 = 0.3 (1 − cos(2πt/T)) / 2, θ2 = 0.2 sin(2πt/T): θ1 starts from rest and stops at
    T/2; θ2 reverses at T/4 and 3T/4 (rad, s)."""
    t = np.linspace(0.0, duration_s, 801)
    w = 2 * np.pi / duration_s
    q = np.column_stack([0.15 * (1 - np.cos(w * t)), 0.2 * np.sin(w * t)])
    qd = np.column_stack([0.15 * w * np.sin(w * t), 0.2 * w * np.cos(w * t)])
    qdd = np.column_stack([0.15 * w**2 * np.cos(w * t), -0.2 * w**2 * np.sin(w * t)])
    return Trajectory.from_samples(t, q, qd, qdd, {"landmark_times_s": [0.0, 4.0, 8.0]})


def test_the_breakaways_are_the_start_the_reversals_and_each_joint_leaving_creep():
    times = breakaway_times(swing())
    # θ1 starts at 0 and reverses at 4 s, θ2 reverses at 2 and 6 s; after each, the joint's
    # speed rises through the creep speed (|q̇| = a w |sin(w (t − t₀))|)
    w = 2 * np.pi / 8.0
    first, second = (np.arcsin(CREEP_RAD_S / (a * w)) / w for a in (0.15, 0.2))
    expected = [0.0, first, 2.0, 2.0 + second, 4.0, 4.0 + first, 6.0, 6.0 + second]
    assert len(times) == len(expected)
    np.testing.assert_allclose(times, expected, atol=8.0 / 20000 * 1.01)


@settings(max_examples=20, deadline=None)
@given(feed=st.floats(0.1, 1.0), half_width_s=st.floats(0.2, 1.5), at=st.floats(1.0, 7.0))
@example(feed=0.5, half_width_s=1.5, at=1.0)  # a dip that begins before the plan does
def test_the_slowed_plan_is_the_same_path_at_the_lower_pace_there(feed, half_width_s, at):
    plan = swing()
    slowed = slowed_near(plan, np.array([at]), feed, half_width_s)
    # the same ends and landmarks, later by what the dip adds within the plan (∫ (1/r − 1)
    # dτ, written here by the trapezoid rule on its own grid)
    tau = np.linspace(max(at - half_width_s, 0.0), min(at + half_width_s, 8.0), 40001)
    x = np.clip((tau - at) / half_width_s, -1, 1)
    r = 1 - (1 - feed) * ((1 + np.cos(np.pi * x)) / 2) ** 2
    added = np.trapezoid(1 / r - 1, tau)
    assert slowed.duration == pytest.approx(plan.duration + added, abs=1e-4)
    np.testing.assert_allclose(slowed.position(slowed.end_time), plan.position(8.0), atol=1e-9)
    np.testing.assert_allclose(slowed.landmark_times[[0, 2]], [0.0, slowed.end_time], atol=1e-4)
    # every point on the plan's path: θ1 and θ2 of the swing satisfy a circle's equation
    t = np.linspace(slowed.start_time, slowed.end_time, 997)
    q = slowed.position(t)
    np.testing.assert_allclose(
        ((q[:, 0] - 0.15) / 0.15) ** 2 + (q[:, 1] / 0.2) ** 2, 1.0, atol=2e-6
    )
    # at the dip's centre the speed is feed times the plan's, by finite differences
    centre = float(np.interp(at, np.linspace(0, 8, 8001), _plan_time_map(slowed, plan)))
    h = 1e-4
    speed = np.linalg.norm(slowed.position(centre + h) - slowed.position(centre - h)) / (2 * h)
    plan_speed = np.linalg.norm(plan.position(at + h) - plan.position(at - h)) / (2 * h)
    assert speed == pytest.approx(feed * plan_speed, rel=2e-3, abs=1e-6)
    # the stored rates are the position's derivatives
    mid = 0.5 * (t[1:-1])
    fd = (slowed.position(mid + h) - slowed.position(mid - h)) / (2 * h)
    np.testing.assert_allclose(slowed.velocity(mid), fd, atol=1e-6)


def _plan_time_map(slowed: Trajectory, plan: Trajectory) -> np.ndarray:
    """The slowed plan's time at plan times 0, 0.001, …, 8 s: where it reaches the same
    angle of the swing's circle (which grows monotonically along it)."""
    t = np.linspace(slowed.start_time, slowed.end_time, 200001)
    q = slowed.position(t)
    angle = np.unwrap(np.arctan2(q[:, 1] / 0.2, -(q[:, 0] - 0.15) / 0.15))
    plan_angle = 2 * np.pi * np.linspace(0, 8, 8001) / 8.0 + angle[0]
    return np.interp(plan_angle, angle, t)


def test_a_plan_no_dip_can_slow_enough_is_slowed_throughout():
    """toppra's hardware plan runs θ1 at its speed limit for most of its 2.8 s, and its
    predicted run breaks that limit. Its breakaways' dips overlap: the deeper ones break the
    plan's own acceleration limit, the shallowest (0.95) leaves θ1's speed past its 95 %
    margin. The whole plan is then slowed to the highest uniform pace that keeps every
    limit with its margin: q(pace·t), whose rates all fall with the pace, so the plan
    stays clean; the next pace up (within the resolution) does not keep the margin. The
    slowed plan is built on the plan's own samples, so a stream compensated on it is as
    clean (one stretched in time by its polynomials, then sampled on its breakpoints and
    a 100 Hz grid together, broke θ1's jerk tenfold)."""
    problem = so.load_problem(ROOT / "problems" / "craniotomy_hardware.toml")
    plan = so.plan(problem, "toppra")
    tried = []
    slowed = slowed_for_breakaways(problem, plan, progress=tried.append)
    assert slowed.where == "throughout" and slowed.keeps_limits and slowed.feed < 1.0
    assert slowed.trajectory.duration == pytest.approx(plan.duration / slowed.feed, rel=1e-9)
    t = np.linspace(0.0, plan.duration, 57)
    assert np.allclose(slowed.trajectory.position(t / slowed.feed), plan.position(t), atol=1e-12)
    assert not so.evaluate(problem, slowed.trajectory).violations
    dipped = [s for s in tried if s.where == "at the breakaways" and s.feed < 1.0]
    assert dipped and not any(s.keeps_limits for s in dipped)
    above = [s for s in tried if s.where == "throughout" and s.feed > slowed.feed]
    assert above and not any(s.keeps_limits for s in above)
    assert min(s.feed for s in above) <= slowed.feed + FEED_RESOLUTION + 1e-9
    compensated = compensate(problem, slowed.trajectory, iterations=1)  # built on its samples
    assert not so.evaluate(problem, compensated.plan).violations


@pytest.mark.slow
def test_slowed_on_an_identified_model_the_true_run_keeps_the_robots_limits(tmp_path):
    """Predicted on the robot file identified from the plant's logs, the toppra plan of the
    paper's flap is slowed at its breakaways; on the plant itself (another robot: its
    masses, friction and loops are not the file's), the plan's run breaks acceleration and
    jerk limits and the slowed plan's does not."""
    problem = so.load_problem(FLAP)
    plant = dataclasses.replace(so.load_robot(PLANT), encoder_offset=np.zeros(2))
    plan = so.plan(problem, "toppra")
    slowed = slowed_for_breakaways(problem, plan, so.load_robot(IDENTIFIED))
    assert slowed.keeps_limits and FEED_RESOLUTION <= slowed.feed < 1.0
    assert not so.evaluate(problem, slowed.trajectory).violations
    assert slowed.trajectory.duration < plan.duration / 0.6  # a uniform feed of 0.6 would take this
    broken = {}
    for name, trajectory in (("plan", plan), ("slowed", slowed.trajectory)):
        backend = SimulatedRobot(
            problem.robot, start_rad=trajectory.position(0.0), plant_robot=plant
        )
        assert Executor(problem, backend).run(trajectory, tmp_path / f"{name}.csv").completed
        backend.trace.save(tmp_path / f"{name}.npz")
        true = evaluate_log(problem, tmp_path / f"{name}.csv", tmp_path / f"{name}.npz").true
        broken[name] = [str(v) for v in true.violations if v.rule in ROBOT_RULES]
    assert any("jerk" in line for line in broken["plan"]), broken
    assert broken["slowed"] == []


def test_the_command_refuses_careless_input(tmp_path, capsys):
    plan_path = tmp_path / "plan.csv"
    swing().to_csv(plan_path)
    out = tmp_path / "slowed.csv"
    base = ["slow-breakaways", str(plan_path), "--problem", str(FLAP), "--other-problem"]
    for extra, expected in (
        (["--out", str(tmp_path / "s.txt")], ("--out", "ending in .csv")),
        (["--out", str(out), "--half-width-s", "0"], ("--half-width-s 0", "0.1 to 10")),
        (["--out", str(out), "--half-width-s", "nan"], ("--half-width-s nan",)),
        (["--out", str(out), "--robot", str(tmp_path / "no.toml")], ("no.toml",)),
    ):
        status, shown = run_cli([*base, *extra])
        assert_one_error(status, capsys.readouterr().err, expected, tmp_path, shown)
        assert not out.exists()
    slowed = slowed_near(swing(), np.array([2.0]), 0.5, 1.0)
    slowed.to_csv(plan_path)
    assert json.loads(plan_path.with_suffix(".json").read_text())["slowed"]["feed"] == 0.5
    status, shown = run_cli([*base, "--out", str(out)])
    assert_one_error(status, capsys.readouterr().err, ("already slowed",), tmp_path, shown)
