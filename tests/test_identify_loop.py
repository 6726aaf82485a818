"""The actuators' loops from goals and positions: an exact integration of the loop model, the
simulated robot (a PI velocity loop on the plant's inertia, not the model) and its tracking
with the identified loops as the lead, and a joint that never moves."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.integrate
import scipy.interpolate
from conftest import HARDWARE_PROBLEM

import spm_opt as so
from spm_opt.base.errors import InputError
from spm_opt.execution import ExecutionSettings, SimulatedRobot, execute
from spm_opt.execution.log import COLUMNS
from spm_opt.identify.loop import estimate_loops, goal_rms
from spm_opt.model.params import load_robot
from spm_opt.problem.trajectory import Trajectory

ROBOTS = Path(__file__).resolve().parents[1] / "problems" / "robots"
GAIN_PER_S = np.array([25.0, 40.0])
BANDWIDTH_PER_S = np.array([150.0, 80.0])
"""The loops of the exact integration: neither the robot file's default."""


def loop_log(path: Path, rate_hz: float, duration_s: float) -> Path:
    """A log whose positions the loop model q̈ = ωv (Kp (g − q) − q̇) gives, integrated
    period by period (``solve_ivp``) from goals held each period, read through the L54's
    encoder (rounded to its pulses); the goals a windowed sum of sines, up to 1.7 Hz."""
    step = 1.0 / rate_hz
    t = np.arange(int(duration_s * rate_hz)) * step
    window = np.sin(np.pi * t / duration_s) ** 2
    goal = np.stack(
        [
            window * (0.3 * np.sin(2 * np.pi * 0.4 * t) + 0.05 * np.sin(2 * np.pi * 1.7 * t)),
            window * (0.2 * np.sin(2 * np.pi * 0.7 * t + 1.0) - 0.04 * np.cos(2 * np.pi * 1.3 * t)),
        ],
        axis=1,
    )

    def loop(_: float, state: np.ndarray, held: np.ndarray) -> np.ndarray:
        q, rate = state[:2], state[2:]
        return np.concatenate([rate, BANDWIDTH_PER_S * (GAIN_PER_S * (held - q) - rate)])

    state, positions = np.zeros(4), []
    for held in goal:
        positions.append(state[:2])
        solution = scipy.integrate.solve_ivp(
            loop, (0.0, step), state, method="DOP853", args=(held,), rtol=1e-10, atol=1e-13
        )
        state = solution.y[:, -1]
    actuator = load_robot(ROBOTS / "prototype.toml").actuator
    measured = actuator.angle(actuator.pulses(np.array(positions)))
    table = pd.DataFrame({column: np.zeros(len(t)) for column in COLUMNS})
    table["time_s"], table["phase"], table["status"] = t, "plan", "ok"
    for joint in (1, 2):
        table[f"goal_theta{joint}_rad"] = goal[:, joint - 1]
        table[f"reference_theta{joint}_rad"] = goal[:, joint - 1]
        table[f"position_theta{joint}_rad"] = measured[:, joint - 1]
    table.to_csv(path, index=False)
    return path


@pytest.mark.parametrize(("rate_hz", "duration_s"), [(100.0, 10.0), (500.0, 4.0)])
def test_the_loops_of_an_exact_integration_come_out(rate_hz, duration_s, tmp_path):
    log = loop_log(tmp_path / "loop.csv", rate_hz, duration_s)
    prior = load_robot(ROBOTS / "prototype.toml")
    loops = estimate_loops([log], prior)
    assert loops.carried.all()
    # the encoder's rounding leaves errors of 1e-5 (Kp) and 3e-4 (ωv), honestly reported
    assert loops.gain_per_s == pytest.approx(GAIN_PER_S, rel=1e-4)
    assert loops.bandwidth_per_s == pytest.approx(BANDWIDTH_PER_S, rel=1e-3)
    assert np.all(np.abs(loops.gain_per_s - GAIN_PER_S) <= 4.0 * loops.gain_error_per_s)
    assert np.all(
        np.abs(loops.bandwidth_per_s - BANDWIDTH_PER_S) <= 4.0 * loops.bandwidth_error_per_s
    )
    # the identified robot carries them, and its loops predict the goals far better
    robot = loops.robot(prior)
    assert robot.actuator.position_loop_gain_per_s == pytest.approx(tuple(loops.gain_per_s))
    assert np.all(goal_rms([log], robot) < 0.1 * goal_rms([log], prior))


def fast_excitation(problem: so.Problem, duration_s: float) -> Trajectory:
    """Two sines per joint (0.45 and 1.05 Hz) under a sin⁴ window about the problem's first
    landmark (a quintic spline through them), scaled to 80 % of its joint speed,
    acceleration and jerk limits."""
    t = np.linspace(0.0, duration_s, int(duration_s * 200) + 1)
    window = np.sin(np.pi * t / duration_s) ** 4
    shape = window[:, None] * np.stack(
        [
            np.sin(2 * np.pi * 0.45 * t) + 0.3 * np.sin(2 * np.pi * 1.05 * t + 0.5),
            np.cos(2 * np.pi * 0.45 * t + 0.8) * np.sin(2 * np.pi * 1.05 * t),
        ],
        axis=1,
    )
    spline = scipy.interpolate.make_interp_spline(t, shape, k=5)
    derivatives = [spline(t, nu=order) for order in range(4)]
    limits = problem.limits
    bounds = (limits.max_joint_speed, limits.max_joint_acceleration, limits.max_joint_jerk)
    worst = max(
        np.max(np.abs(value)) / bound for value, bound in zip(derivatives[1:], bounds, strict=True)
    )
    q, qd, qdd = (0.8 / worst * value for value in derivatives[:3])
    return Trajectory.from_samples(
        t, q + problem.waypoint_angles[0], qd, qdd, {"problem": problem.record()}
    )


def tracking_rms(log: Path) -> np.ndarray:
    """RMS per joint (2,), rad, of the measured position less the reference."""
    table, _ = so.read_log(log)
    error = [table[f"position_theta{j}_rad"] - table[f"reference_theta{j}_rad"] for j in (1, 2)]
    return np.sqrt(np.mean(np.square(error), axis=1))


def test_the_plant_s_loops_come_out_and_lead_it_better(tmp_path):
    problem = so.load_problem(HARDWARE_PROBLEM)
    plant = load_robot(ROBOTS / "prototype_plant.toml")
    plan = fast_excitation(problem, 6.0)

    def run(name: str, robot: so.Robot) -> Path:
        """The plan on the plant at 100 Hz, its goals led by ``robot``'s loops."""
        backend = SimulatedRobot(robot, start_rad=plan.position(0.0), plant_robot=plant)
        led = dataclasses.replace(problem, robot=robot)
        log = tmp_path / f"{name}.csv"
        assert execute(plan, backend, led, log, ExecutionSettings(other_problem=True)).completed
        return log

    fit = run("prior", problem.robot)
    loops = estimate_loops([fit], problem.robot)
    assert loops.carried.all()
    # the plant's position P gain is 32 1/s (its 1 ms step makes a ramp lag as if 32.5)
    assert loops.gain_per_s == pytest.approx(32.0, rel=0.04)
    # measured: 0.0183° and 0.0361° RMS led by the prior's loops, 0.0117° and 0.0178° by these
    prior = tracking_rms(fit)
    identified = tracking_rms(run("identified", loops.robot(problem.robot)))
    assert np.all(identified < 0.75 * prior), (prior, identified)


def test_a_joint_that_never_moves_is_a_one_line_error(tmp_path):
    t = np.arange(1000) / 100.0
    table = pd.DataFrame({column: np.zeros(len(t)) for column in COLUMNS})
    table["time_s"], table["phase"], table["status"] = t, "plan", "ok"
    swing = 0.2 * np.sin(2 * np.pi * 0.2 * t)
    table["goal_theta1_rad"] = table["position_theta1_rad"] = swing
    table.to_csv(tmp_path / "one.csv", index=False)
    prior = load_robot(ROBOTS / "prototype.toml")
    with pytest.raises(InputError, match="theta2 does not move") as raised:
        estimate_loops([tmp_path / "one.csv"], prior)
    assert "position_loop_gain_per_s" in str(raised.value)
    assert "\n" not in str(raised.value)
