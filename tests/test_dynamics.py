"""The Lagrange dynamics (Eqs. 6–22): the paper's numbers, energy and friction by hand."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spm_opt.model import dynamics, kinematics

LIMIT = np.radians(60.0)
states = st.tuples(
    *(st.floats(-LIMIT, LIMIT) for _ in range(2)), *(st.floats(-1.0, 1.0) for _ in range(4))
).map(np.array)


@pytest.fixture(scope="module")
def robot(paper_problem):
    return paper_problem.robot


def frictionless(robot):
    return dataclasses.replace(robot, friction=dataclasses.replace(robot.friction, mu=0.0))


def test_table_iv_rms_torques_without_friction(robot, baseline):
    t = baseline.time_grid(100.0)
    torque = dynamics.inverse_dynamics(
        robot, baseline.position(t), baseline.velocity(t), baseline.acceleration(t), friction=False
    )
    rms = np.sqrt(np.trapezoid(torque**2, t, axis=0) / 40.0)
    assert rms == pytest.approx([0.11, 0.10], abs=0.005)


def energy_rate(robot, q, qd, qdd):
    return float(dynamics.energy_rate(robot, q, qd, qdd)[0])


@settings(max_examples=40, deadline=None)
@given(states)
def test_power_balance_without_friction(robot, state):
    q, qd, qdd = state[0:2], state[2:4], state[4:6] * 0.5
    torque = dynamics.inverse_dynamics(robot, q, qd, qdd, friction=False)[0]
    power, rate = torque @ qd, energy_rate(robot, q, qd, qdd)
    scale = max(1.0, abs(rate))
    assert power == pytest.approx(rate, abs=1e-9 * scale)


@settings(max_examples=40, deadline=None)
@given(states)
def test_power_balance_with_friction_dissipates(robot, state):
    q, qd, qdd = state[0:2], state[2:4], state[4:6] * 0.5
    torque = dynamics.inverse_dynamics(robot, q, qd, qdd, friction=True)[0]
    upper, lower = dynamics.friction_forces(robot, q, qd)
    b_rate = kinematics.platform_jacobian(q[None], robot.upper_platform_radius)[0] @ qd
    ratio = robot.lower_platform_radius / robot.upper_platform_radius
    dissipated = -(upper[0] @ b_rate + lower[0] @ (ratio * b_rate))
    assert dissipated >= -1e-12
    rate = energy_rate(robot, q, qd, qdd)
    assert torque @ qd - rate == pytest.approx(dissipated, abs=1e-9 * max(1.0, abs(rate)))


def test_friction_at_home_moving_theta1(robot):
    """θ = 0, θ̇ = (ω, 0): B = (0, 0, r_u), Ḃ = (0, −r_u ω, 0). The upper platform turns with
    its arc (Ḃ · x_u = 0, no sliding); the lower one slides along y_L = (0, 1, 0) and feels
    F = μ m_L g (0, 1, 0) at D. By virtual work the actuators add τ = −Jᵀ (r_L / r_u) F =
    (r_L μ m_L g, 0)."""
    q, qd = np.zeros((1, 2)), np.array([[0.1, 0.0]])
    upper, lower = dynamics.friction_forces(robot, q, qd)
    mu, g, m_l = robot.friction.mu, robot.gravity, robot.lower_platform.mass
    np.testing.assert_allclose(upper[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(lower[0], [0.0, mu * m_l * g, 0.0], rtol=1e-12)
    torque = dynamics.friction_torque(robot, q, qd)[0]
    np.testing.assert_allclose(
        torque, [robot.lower_platform_radius * mu * m_l * g, 0.0], rtol=1e-12, atol=1e-15
    )
    smooth = dynamics.friction_torque(robot, q, qd, exact=False)[0]
    assert smooth[0] == pytest.approx(torque[0], rel=1e-4)  # 0.1 rad/s >> 1e-3 rad/s


def test_friction_off_when_mu_is_zero(robot):
    q, qd = np.array([[0.2, -0.3]]), np.array([[0.1, 0.2]])
    np.testing.assert_array_equal(dynamics.friction_torque(frictionless(robot), q, qd), 0.0)


@settings(max_examples=30, deadline=None)
@given(states)
def test_forward_dynamics_inverts_inverse_dynamics(robot, state):
    q, qd, qdd = state[None, 0:2], state[None, 2:4], state[None, 4:6]
    for exact in (True, False):
        torque = dynamics.inverse_dynamics(robot, q, qd, qdd, exact=exact)
        back = dynamics.forward_dynamics(robot, q, qd, torque, exact=exact)
        np.testing.assert_allclose(back, qdd, atol=1e-9)


@settings(max_examples=30, deadline=None)
@given(states)
def test_mass_matrix_gives_the_kinetic_energy(robot, state):
    q, qd = state[None, 0:2], state[None, 2:4]
    mass = dynamics.mass_matrix(robot, q)[0]
    np.testing.assert_allclose(mass, mass.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(mass) > 0)
    kinetic, _ = dynamics.mechanical_energy(robot, q, qd)
    assert kinetic[0] == pytest.approx(0.5 * qd[0] @ mass @ qd[0], rel=1e-10, abs=1e-15)


def test_statics_is_the_gradient_of_the_potential(robot):
    q = np.array([[0.3, -0.2]])
    h = 1e-6
    gradient = []
    for joint in range(2):
        step = np.zeros((1, 2))
        step[0, joint] = h
        up = dynamics.mechanical_energy(robot, q + step, np.zeros((1, 2)))[1]
        down = dynamics.mechanical_energy(robot, q - step, np.zeros((1, 2)))[1]
        gradient.append(float((up - down)[0] / (2 * h)))
    np.testing.assert_allclose(dynamics.gravity_torque(robot, q)[0], gradient, rtol=1e-7)


def test_payload_at_the_centre_adds_to_the_upper_platform(robot):
    q, qd, qdd = np.array([[0.2, 0.1]]), np.array([[0.3, -0.2]]), np.array([[0.1, 0.4]])
    base = frictionless(robot)
    carried = dataclasses.replace(base, payload=dataclasses.replace(base.payload, mass=0.3))
    heavier = dataclasses.replace(
        base,
        upper_platform=dataclasses.replace(
            base.upper_platform, mass=base.upper_platform.mass + 0.3
        ),
    )
    np.testing.assert_allclose(
        dynamics.inverse_dynamics(carried, q, qd, qdd),
        dynamics.inverse_dynamics(heavier, q, qd, qdd),
        rtol=1e-12,
    )


def test_constraint_multipliers_are_finite_and_balance_gravity(robot):
    """At rest, B on top: the B_z equation reads ∂U/∂B_z = λ1 ∂γ1/∂B_z = 2 r_u λ1 (γ2 and
    γ3 do not involve B_z at θ = 0), so λ1 carries the platforms' weight."""
    q = np.zeros((1, 2))
    lam = dynamics.multipliers(robot, q, q, q, friction=False)[0]
    r_u, g = robot.upper_platform_radius, robot.gravity
    weight = (
        robot.upper_platform.mass + robot.lower_platform.mass * robot.lower_platform_radius / r_u
    ) * g
    assert lam[0] * 2 * r_u == pytest.approx(weight, rel=1e-12)


@settings(max_examples=30, deadline=None)
@given(states, st.booleans(), st.booleans())
def test_two_derivations_agree(robot, state, friction, exact):
    """The paper's redundant coordinates against Euler–Lagrange in θ directly."""
    from spm_opt.verify.minimal_coordinates import minimal_energy, minimal_inverse_dynamics

    payload = dataclasses.replace(robot.payload, mass=0.2, offset=np.array([0.01, -0.02, 0.03]))
    loaded = dataclasses.replace(robot, payload=payload)
    q, qd, qdd = state[None, 0:2], state[None, 2:4], state[None, 4:6]
    for each in (robot, loaded):
        ours = dynamics.inverse_dynamics(each, q, qd, qdd, friction=friction, exact=exact)
        theirs = minimal_inverse_dynamics(each, q, qd, qdd, friction=friction, exact=exact)
        np.testing.assert_allclose(ours, theirs, rtol=0.0, atol=1e-9)
        np.testing.assert_allclose(
            dynamics.mechanical_energy(each, q, qd),
            minimal_energy(each, q, qd),
            rtol=0.0,
            atol=1e-12,
        )


def test_two_derivations_agree_over_the_papers_trajectory(robot, baseline):
    from spm_opt.verify.minimal_coordinates import minimal_inverse_dynamics

    t = baseline.time_grid(100.0)
    args = (baseline.position(t), baseline.velocity(t), baseline.acceleration(t))
    np.testing.assert_allclose(
        dynamics.inverse_dynamics(robot, *args),
        minimal_inverse_dynamics(robot, *args),
        rtol=0.0,
        atol=1e-9,
    )


def test_compiled_torques_equal_casadis_interpreter(robot):
    rng = np.random.default_rng(3)
    q, qd, qdd = rng.uniform(-1.0, 1.0, size=(3, 500, 2))
    parameters = dynamics.parameter_vector(robot)
    frictionless, _, exact = dynamics._model().torque(q.T, qd.T, qdd.T, parameters)
    np.testing.assert_allclose(
        dynamics.inverse_dynamics(robot, q, qd, qdd), (frictionless + exact).full().T, atol=1e-13
    )
    # one state broadcast against many rates
    np.testing.assert_allclose(
        dynamics.inverse_dynamics(robot, q[0], qd, qdd),
        dynamics.inverse_dynamics(robot, np.repeat(q[:1], 500, axis=0), qd, qdd),
        atol=0,
    )
