"""The simulated plant: the model's terms, the exact friction step, the position loop, and
its true state (for tests) beside what its sensors report."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from spm_opt.execution.plant import DynamixelPlant, StateTrace, _minimise
from spm_opt.model import dynamics

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
)
@settings(max_examples=60, deadline=None)
def test_friction_step_is_the_minimum_of_its_convex_function(linear, a, thresholds, stiffness):
    """Against a derivative-free minimiser of ½vᵀWv − bᵀv + Σ c_k |a_k·v|."""
    weights = np.array([[stiffness, 0.3], [0.3, 1.0]])
    slide_map = np.array(a).reshape(2, 2) + np.eye(2) * 1.5  # well away from singular
    b, c = np.array(linear), np.array(thresholds)

    def value(v: np.ndarray) -> float:
        return 0.5 * v @ weights @ v - b @ v + c @ np.abs(slide_map @ v)

    found = np.array(
        _minimise(
            tuple(map(tuple, weights)),
            tuple(b),
            tuple(map(tuple, slide_map)),
            tuple(c),
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
