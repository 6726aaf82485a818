"""The simulated plant: the model's terms, the exact friction step, the position loop, and
its true state (for tests) beside what its sensors report."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from spm_opt.execution import SimulatedRobot, execute, read_log
from spm_opt.execution.plant import DynamixelPlant, PlantSettings, StateTrace, _minimise
from spm_opt.model import dynamics
from spm_opt.model.params import load_robot

ROBOTS = Path(__file__).resolve().parents[1] / "problems" / "robots"

angles = st.floats(-0.8, 0.8)
# no subnormal rates: at 5e-324 rad/s one of two algebraically equal slide velocities
# underflows to 0 and the other does not, so sign() differs (found on a fresh run)
rates = st.floats(-0.5, 0.5, allow_subnormal=False)


@given(angles, angles, rates, rates, rates, rates)
@settings(max_examples=40, deadline=None)
def test_plant_terms_rebuild_the_inverse_dynamics(paper_problem, a, b, va, vb, aa, ab):
    """τ = M q̈ + bias + C sign(A q̇) is the model's torque with exact friction."""
    robot = paper_problem.robot
    q, qd, qdd = np.array([a, b]), np.array([va, vb]), np.array([aa, ab])
    mass, bias, slide_map, friction_map = dynamics.PlantTerms(robot)(q, qd)
    torque = mass @ qdd + bias + friction_map @ np.sign(slide_map @ qd)
    expected = dynamics.inverse_dynamics(robot, q[None], qd[None], qdd[None])[0]
    np.testing.assert_allclose(torque, expected, atol=1e-12)
    # virtual work: C = Aᵀ diag(F), F ≥ 0 the friction torques of the two slides
    per_slide = np.linalg.solve(slide_map.T, friction_map)
    np.testing.assert_allclose(per_slide, np.diag(np.diag(per_slide)), atol=1e-12)
    assert np.all(np.diag(per_slide) >= 0.0)


@given(
    st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=2),
    st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4),
    st.lists(st.floats(0.0, 0.5), min_size=2, max_size=2),
    st.floats(0.2, 3.0),
    st.one_of(st.none(), st.lists(st.floats(0.0, 0.3), min_size=2, max_size=2)),
)
@settings(max_examples=80, deadline=None)
def test_friction_step_is_the_minimum_of_its_convex_function(
    linear, a, thresholds, stiffness, joint_friction
):
    """Against a derivative-free minimiser of ½vᵀWv − bᵀv + Σ c_k |a_k·v|: the two slides,
    and with ``joint_friction`` the joints themselves as two more lines."""
    weights = np.array([[stiffness, 0.3], [0.3, 1.0]])
    lines = np.array(a).reshape(2, 2) + np.eye(2) * 1.5  # well away from singular
    c = np.array(thresholds)
    if joint_friction is not None:
        lines, c = np.vstack([lines, np.eye(2)]), np.concatenate([c, joint_friction])
    b = np.array(linear)

    def value(v: np.ndarray) -> float:
        return 0.5 * v @ weights @ v - b @ v + c @ np.abs(lines @ v)

    found = np.array(
        _minimise(
            tuple(map(tuple, weights)),
            tuple(b),
            list(map(tuple, lines)),
            list(c),
            [True, True],
        )
    )
    reference = min(
        (
            minimize(value, x0, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-14})
            for x0 in (np.zeros(2), np.linalg.solve(weights, b))
        ),
        key=lambda r: r.fun,
    )
    assert value(found) <= reference.fun + 1e-9


def test_a_joint_without_torque_is_held_by_its_gear(paper_problem):
    plant = DynamixelPlant(paper_problem.robot, start_rad=np.array([0.3, -0.4]))
    plant.enable_torque(0, True)
    plant.goal_position_rad[0] = 0.35
    plant.advance_to(1.0)
    assert plant.position_rad[0] == pytest.approx(0.35, abs=1e-4)
    assert plant.position_rad[1] == -0.4 and plant.current_a[1] == 0.0


def test_the_position_loop_holds_against_gravity_through_its_integrator(paper_problem):
    robot = paper_problem.robot
    start = np.array([0.3, -0.4])
    plant = DynamixelPlant(robot, start_rad=start)
    for joint in range(2):
        plant.enable_torque(joint, True)
    plant.advance_to(3.0)
    assert np.max(np.abs(plant.position_rad - start)) < 2 * 2 * np.pi / 361_384
    gravity = dynamics.gravity_torque(robot, start[None])[0]
    friction = np.abs(dynamics.friction_torque(robot, start[None], np.array([[1e-3, 1e-3]]))[0])
    torque = robot.actuator.current_map.torque(plant.current_a)
    # at rest the drive balances gravity, up to what static friction takes
    assert np.all(np.abs(torque - gravity) <= np.sum(friction) + 1e-6)


def test_an_overload_switches_torque_off_until_a_reboot(paper_problem):
    plant = DynamixelPlant(paper_problem.robot)
    plant.enable_torque(0, True)
    plant.trigger_hardware_error(0, 5)
    assert plant.hardware_error[0] == 32 and not plant.torque_enabled[0]
    plant.enable_torque(0, True)
    assert not plant.torque_enabled[0]
    plant.reboot(0)
    plant.enable_torque(0, True)
    assert plant.torque_enabled[0] and plant.hardware_error[0] == 0


def test_a_stuck_encoder_freezes_the_reported_position_only(paper_problem):
    plant = DynamixelPlant(paper_problem.robot)
    plant.enable_torque(1, True)
    frozen = plant.present_position_pulses()
    plant.encoder_stuck[1] = True
    plant.goal_position_rad[1] = 0.05
    plant.advance_to(0.5)
    assert plant.present_position_pulses()[1] == frozen[1]
    assert plant.position_rad[1] == pytest.approx(0.05, abs=1e-3)


def test_the_true_state_is_exact_where_the_sensors_quantise(paper_problem, tmp_path):
    plant = DynamixelPlant(paper_problem.robot, start_rad=np.array([0.1, -0.2]))
    plant.enable_torque(0, True)
    plant.goal_position_rad[0] = 0.15
    trace = StateTrace()
    for k in range(1, 11):
        plant.advance_to(0.005 * k)
        trace.record(0.005 * k, plant)
    state = plant.true_state(0.05)
    pulses = plant.present_position_pulses()
    angle = paper_problem.robot.actuator.angle(pulses)
    assert 0 < abs(state.position_rad[0] - angle[0]) < np.pi / 361_384  # under half a pulse
    assert state.velocity_rad_s[0] > 0 and state.velocity_rad_s[1] == 0.0
    state.position_rad[0] = 99.0  # a copy: the plant is untouched
    assert plant.position_rad[0] < 1.0
    trace.save(tmp_path / "trace.npz")
    loaded = StateTrace.load(tmp_path / "trace.npz")
    assert len(trace) == 10 and loaded["position_rad"].shape == (10, 2)
    np.testing.assert_array_equal(loaded["time_s"], 0.005 * np.arange(1, 11))
    assert loaded["position_rad"][-1, 0] == plant.position_rad[0]
    np.testing.assert_array_equal(loaded["goal_rad"][-1], plant.goal_position_rad)


def test_the_joints_coulomb_friction_costs_its_torque_against_the_motion(paper_problem):
    """Two plants driven alike at constant rates, one with Coulomb friction in the gear
    trains: the drive torques differ by f_c sign(q̇), what Actuator.drive_torque adds."""
    coulomb = (0.05, 0.03)
    rates = np.array([0.1, -0.1])
    torques = []
    for friction in ((0.0, 0.0), coulomb):
        actuator = dataclasses.replace(paper_problem.robot.actuator, coulomb_friction_nm=friction)
        plant = DynamixelPlant(
            dataclasses.replace(paper_problem.robot, actuator=actuator),
            PlantSettings(current_noise_a=0.0),
            start_rad=np.array([0.1, 0.2]),
        )
        for joint in range(2):
            plant.enable_torque(joint, True)
        start, sampled = plant.goal_position_rad.copy(), []
        for k in range(1, 2001):
            plant.goal_position_rad[:] = start + rates * k * 1e-3
            plant.advance_to(k * 1e-3)
            if k > 1000:
                sampled.append(actuator.current_map.torque(plant.current_a.copy()))
        torques.append(np.mean(sampled, axis=0))
    np.testing.assert_allclose(
        torques[1] - torques[0], np.array(coulomb) * np.sign(rates), atol=1e-3
    )


def test_the_encoders_read_theta_plus_their_offset(paper_problem):
    offset = np.array([0.01, -0.02])
    robot = dataclasses.replace(paper_problem.robot, encoder_offset=offset)
    start = np.array([0.3, -0.4])
    plant = DynamixelPlant(robot, start_rad=start)
    reading = robot.actuator.angle(plant.present_position_pulses())
    np.testing.assert_allclose(reading, start + offset, atol=1e-5)
    for joint in range(2):
        plant.enable_torque(joint, True)  # holds what its encoder reads: no jump
    plant.goal_position_rad[:] = [0.32, -0.38]
    plant.advance_to(3.0)
    np.testing.assert_allclose(plant.position_rad, np.array([0.32, -0.38]) - offset, atol=2e-5)


def _run(problem, plan, tmp_path, plant_robot=None):
    """The plan on the simulated robot: the log's time and torques, and the plant's true
    state at the log's rows."""
    backend = SimulatedRobot(problem.robot, start_rad=plan.position(0.0), plant_robot=plant_robot)
    log = tmp_path / "run.csv"
    assert execute(plan, backend, problem, log).completed
    table, _ = read_log(log)
    t = table["time_s"].to_numpy()
    trace = backend.trace.arrays()
    at_log = np.searchsorted(trace["time_s"], t + 1e-6, side="right") - 1  # the last read
    assert np.allclose(trace["time_s"][at_log], t, atol=1e-6)
    measured = table[["torque_theta1_nm", "torque_theta2_nm"]].to_numpy()
    return t, measured, trace["position_rad"][at_log], trace["velocity_rad_s"][at_log]


def _prediction_error(robot, run):
    """RMS over the moving samples of measured − predicted torque (actuator_torque of
    ``robot`` at the plant's true state), each smoothed over 1 s (the current's noise
    averaged out), N·m."""
    t, measured, q, qd = run
    predicted = dynamics.actuator_torque(robot, q, qd, np.gradient(qd, t, axis=0))
    window = np.ones(100) / 100
    error = np.stack(
        [np.convolve(column, window, mode="same") for column in (measured - predicted).T], axis=1
    )
    moving = np.all(np.abs(qd) > 0.01, axis=1)
    moving[:100] = moving[-100:] = False
    return float(np.sqrt(np.mean(error[moving] ** 2)))


def test_the_plant_robot_drives_what_its_own_model_asks(hardware_problem, hardware_plan, tmp_path):
    """The plant integrates forward (implicit steps, gear losses by each step's power
    sign); the plant robot's inverse dynamics through Actuator.drive_torque (rotor inertia,
    viscous friction, gear efficiency) predict what it measures as well as the planning
    model predicts a plant that is the model, and the planning model predicts it at least
    twice as badly."""
    model = hardware_problem.robot
    plant = load_robot(ROBOTS / "prototype_plant.toml")
    (tmp_path / "model").mkdir()
    (tmp_path / "plant").mkdir()
    floor = _prediction_error(model, _run(hardware_problem, hardware_plan, tmp_path / "model"))
    run = _run(hardware_problem, hardware_plan, tmp_path / "plant", plant)
    assert _prediction_error(plant, run) < 1.25 * floor
    assert _prediction_error(model, run) > 2.0 * floor


def test_each_step_takes_the_gear_side_its_own_power_takes(paper_problem):
    """A lossy gear train (η 0.7), goals stepped every 10 ms so that the velocity loop swings
    the torque through zero within each period: in every step the load's torque,
    rebuilt here from the step's motion (M(q) (v⁺ − v) / Δt + the frictionless inverse
    dynamics at (q, v)), is η times the motor's where the motor drives (τ v⁺ ≥ 0) and the
    motor's over η where it is driven back (measured: in all 801 steps, the torque through
    zero 238 times; when each step took the last step's side, in 89.5 % of them)."""
    efficiency = 0.7
    actuator = dataclasses.replace(paper_problem.robot.actuator, gear_efficiency=efficiency)
    robot = dataclasses.replace(
        paper_problem.robot,
        actuator=actuator,
        friction=dataclasses.replace(paper_problem.robot.friction, mu=0.0),
    )
    plant = DynamixelPlant(robot, PlantSettings(current_noise_a=0.0), start_rad=np.zeros(2))
    for joint in range(2):
        plant.enable_torque(joint, True)
    rates, dt = np.array([0.6, -0.4]), plant.settings.step_s
    sides, crossings = [], 0
    for k in range(1, 1001):
        if k % 10 == 1:  # a goal a period, as the executor sends them
            plant.goal_position_rad[:] = rates * (k + 9) * dt
        q, v = plant.position_rad.copy(), plant.velocity_rad_s.copy()
        before = plant.current_a.copy()
        plant.advance_to(k * dt)
        motor = actuator.current_map.torque(plant.current_a)
        crossings += int(np.sum(np.sign(motor) != np.sign(before)))
        if k < 200:  # the start's transient
            continue
        acceleration = (plant.velocity_rad_s - v) / dt
        load = (
            dynamics.mass_matrix(robot, q)[0] @ acceleration
            + dynamics.inverse_dynamics(robot, q[None], v[None], np.zeros((1, 2)), friction=False)[
                0
            ]
        )
        driving = motor * plant.velocity_rad_s >= 0.0
        expected = np.where(driving, efficiency * motor, motor / efficiency)
        sides.append(np.abs(load - expected) <= 1e-6 + 1e-6 * np.abs(load))
    assert crossings > 50  # the torque swings through zero
    assert np.mean(sides) >= 0.99, np.mean(sides)
