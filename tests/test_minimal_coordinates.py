"""The minimal-coordinate Euler–Lagrange torques (spm_opt.verify.minimal_coordinates).

References independent of the code under test: central finite differences of the energy
(plain numpy, no CasADi derivative), the work–energy theorem integrated with scipy along
the paper's cubic trajectory, friction forces written out by hand from Eqs. 20–22 with
the numpy kinematics, and a hand derivation at θ = 0.
"""

import dataclasses
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import fixed_quad

import spm_opt as so
from spm_opt.base.errors import InputError
from spm_opt.model import kinematics as kin
from spm_opt.model.params import Payload, Robot, load_robot
from spm_opt.verify.minimal_coordinates import minimal_energy, minimal_inverse_dynamics

ROOT = Path(__file__).resolve().parents[1]
PROTOTYPE = ROOT / "problems" / "robots" / "prototype.toml"
LIMIT = np.radians(60.0)  # the prototype's joint box, rad

FAST = settings(max_examples=40, deadline=None)

angle = st.floats(-LIMIT, LIMIT, allow_nan=False, allow_infinity=False)
rate = st.floats(-2.0, 2.0, allow_nan=False, allow_infinity=False)
accel = st.floats(-5.0, 5.0, allow_nan=False, allow_infinity=False)
pair = lambda s: st.tuples(s, s).map(np.array)  # noqa: E731
states = st.tuples(pair(angle), pair(rate), pair(accel))


@pytest.fixture(scope="module")
def robot() -> Robot:
    return load_robot(PROTOTYPE)


def with_payload(robot: Robot) -> Robot:
    """The prototype carrying a 50 g tool off the platform's mass centre."""
    return dataclasses.replace(
        robot, payload=Payload(mass=0.05, offset=np.array([0.01, -0.02, 0.03]))
    )


# Fourth-order central difference: f'(0) ≈ [f(−2h) − 8 f(−h) + 8 f(h) − f(2h)] / 12h.
STEPS = np.array([-2.0, -1.0, 1.0, 2.0])
WEIGHTS = np.array([1.0, -8.0, 8.0, -1.0]) / 12.0
H = 1e-3  # s
FLOOR = 1e-10  # W: roundoff of the stencil on energies of ~1 J (2e-16 · 1 J / 1e-3 s)


def energy_rate(robot: Robot, q0, qd0, qdd0) -> float:
    """d(K+U)/dt at t = 0 along q(t) = q0 + qd0 t + ½ qdd0 t², by finite differences."""
    t = STEPS[:, None] * H
    q = q0 + qd0 * t + 0.5 * qdd0 * t**2
    qd = qd0 + qdd0 * t
    kinetic, potential = minimal_energy(robot, q, qd)
    return float(WEIGHTS @ (kinetic + potential) / H)


def hand_friction_power(robot: Robot, q, qd) -> float:
    """−(F_fu·Ḃ + F_fl·Ḋ), W, with the forces of Eqs. 20–22 written out with numpy."""
    r_u, r_l = robot.upper_platform_radius, robot.lower_platform_radius
    mu, g = robot.friction.mu, robot.gravity
    b = kin.forward_kinematics(q[None], r_u)[0]
    b_dot = kin.platform_jacobian(q[None], r_u)[0] @ qd
    d_dot = (r_l / r_u) * b_dot
    rot_u, rot_l = (r[0] for r in kin.platform_frames(q[None]))
    x_u, y_l = rot_u[:, 0], rot_l[:, 1]
    m_u = robot.upper_platform.mass + robot.payload.mass
    f_fu = np.sign(-b_dot @ x_u) * (b[2] / r_u) * m_u * g * mu * x_u
    f_fl = np.sign(-b_dot @ y_l) * (b[2] / r_u) * robot.lower_platform.mass * g * mu * y_l
    return float(-(f_fu @ b_dot + f_fl @ d_dot))


# --- 1: power balance without friction ----------------------------------------------


@FAST
@given(state=states)
def test_power_balance_without_friction(robot, state):
    """τ·θ̇ = d(K+U)/dt for any motion, with and without a payload."""
    q0, qd0, qdd0 = state
    for body in (robot, with_payload(robot)):
        tau = minimal_inverse_dynamics(body, q0[None], qd0[None], qdd0[None], friction=False)
        assert tau.shape == (1, 2)
        power = float(tau[0] @ qd0)
        scale = float(np.abs(tau[0]) @ np.abs(qd0))
        assert power == pytest.approx(
            energy_rate(body, q0, qd0, qdd0), rel=0, abs=1e-6 * scale + FLOOR
        )


def test_work_energy_over_the_paper_trajectory(robot, paper_problem, baseline):
    """∫ τ·θ̇ dt over [0, 40] s equals E(40) − E(0) (a closed path from rest to rest)."""
    assert paper_problem.robot.upper_platform.mass == robot.upper_platform.mass

    def power(t: np.ndarray) -> np.ndarray:
        q, qd, qdd = baseline.position(t), baseline.velocity(t), baseline.acceleration(t)
        tau = minimal_inverse_dynamics(robot, q, qd, qdd, friction=False)
        return np.sum(tau * qd, axis=1)

    edges = baseline.breakpoints
    assert edges[0] == 0.0 and edges[-1] == pytest.approx(40.0)
    work = sum(fixed_quad(power, a, b, n=40)[0] for a, b in pairwise(edges))
    gross = sum(fixed_quad(lambda t: np.abs(power(t)), a, b, n=200)[0] for a, b in pairwise(edges))
    ends = np.array([edges[0], edges[-1]])
    kinetic, potential = minimal_energy(robot, baseline.position(ends), baseline.velocity(ends))
    delta = (kinetic[1] + potential[1]) - (kinetic[0] + potential[0])
    assert gross > 1e-3  # the actuators do real work along the way
    assert work == pytest.approx(delta, rel=0, abs=1e-6 * gross)


# --- 2: statics -----------------------------------------------------------------------


@FAST
@given(q=pair(angle))
def test_static_torque_is_potential_gradient(robot, q):
    """At rest τ = ∂U/∂θ (friction on: at rest it exerts nothing)."""
    body = with_payload(robot)
    zero = np.zeros((1, 2))
    tau = minimal_inverse_dynamics(body, q[None], zero, zero, friction=True)[0]
    h = 1e-4  # rad
    gradient = np.empty(2)
    for k in range(2):
        dq = np.zeros(2)
        dq[k] = h
        points = q + STEPS[:, None] * dq
        _, potential = minimal_energy(body, points, np.zeros_like(points))
        gradient[k] = WEIGHTS @ potential / h
    np.testing.assert_allclose(tau, gradient, rtol=1e-7, atol=1e-9)


# --- 3: friction dissipates exactly the power of Eqs. 20–22 ---------------------------


@FAST
@given(state=states)
def test_friction_power_matches_hand_forces(robot, state):
    q0, qd0, qdd0 = state
    body = with_payload(robot)
    tau = minimal_inverse_dynamics(body, q0[None], qd0[None], qdd0[None], exact=True)[0]
    dissipated = float(tau @ qd0) - energy_rate(body, q0, qd0, qdd0)
    expected = hand_friction_power(body, q0, qd0)
    scale = float(np.abs(tau) @ np.abs(qd0))
    assert expected >= 0.0
    assert dissipated >= -(1e-6 * scale + FLOOR)
    assert dissipated == pytest.approx(expected, rel=0, abs=1e-6 * scale + FLOOR)
    # the smooth sign never generates energy either
    smooth = minimal_inverse_dynamics(body, q0[None], qd0[None], qdd0[None], exact=False)[0]
    assert float(smooth @ qd0) - energy_rate(body, q0, qd0, qdd0) >= -(1e-6 * scale + FLOOR)


def test_smooth_friction_approaches_exact_when_sliding_fast(robot):
    """Sliding rates ≫ ε: the smooth sign is within ½(ε/v)² of the exact one."""
    q, qd, qdd = np.array([[0.2, -0.3]]), np.array([[0.5, 0.4]]), np.zeros((1, 2))
    exact = minimal_inverse_dynamics(robot, q, qd, qdd, exact=True)
    smooth = minimal_inverse_dynamics(robot, q, qd, qdd, exact=False)
    np.testing.assert_allclose(smooth, exact, rtol=0, atol=1e-6)


# --- 4: friction at θ = 0 by hand -----------------------------------------------------


def test_friction_by_hand_at_the_origin(robot):
    """θ = 0, θ̇ = (0.1, 0) rad/s, θ̈ = 0.

    Eq. 17 at θ = 0: b = (0, 0, 1), N_u = (0, 1, 0), N_L = (1, 0, 0), so
    x_u = y_u × z_u = (0,1,0) × (0,0,1) = (1, 0, 0) and y_L = z_L × x_L = (0, 1, 0).
    Eq. 5 near 0: b ≈ (θ2, −θ1, 1), so ∂B/∂θ1 = r_u (0, −1, 0) and Ḃ = (0, −0.1 r_u, 0).
    Upper rail: −Ḃ·x_u = 0, so F_fu = 0 (the upper arc carries the platform along).
    Lower rail: −Ḃ·y_L = +0.1 r_u > 0, so F_fl = +(B_z/r_u) m_L g μ y_L = m_L g μ (0,1,0).
    Q_θ1 = (∂B/∂θ1)·(r_L/r_u) F_fl = −r_L m_L g μ, Q_θ2 = 0 (∂B/∂θ2 = r_u (1,0,0)).
    Friction torque τ_f = −Q_θ = (+r_L m_L g μ, 0): it pushes WITH the motion.
    """
    q, qd, qdd = np.zeros((1, 2)), np.array([[0.1, 0.0]]), np.zeros((1, 2))
    on = minimal_inverse_dynamics(robot, q, qd, qdd, friction=True)
    off = minimal_inverse_dynamics(robot, q, qd, qdd, friction=False)
    expected = robot.lower_platform_radius * robot.lower_platform.mass * robot.gravity
    expected *= robot.friction.mu
    assert expected == pytest.approx(0.13633 * 0.0878 * 9.81 * 0.24)
    np.testing.assert_allclose(on - off, [[expected, 0.0]], rtol=1e-12, atol=1e-15)
    # reversing the motion reverses the friction torque; θ̇2 alone uses the upper rail
    back = minimal_inverse_dynamics(robot, q, -qd, qdd) - minimal_inverse_dynamics(
        robot, q, -qd, qdd, friction=False
    )
    np.testing.assert_allclose(back, [[-expected, 0.0]], rtol=1e-12, atol=1e-15)
    qd2 = np.array([[0.0, 0.1]])
    # ∂B/∂θ2 = r_u (1,0,0): −Ḃ·x_u = −0.1 r_u < 0, F_fu = −m_u g μ x_u, Q_θ2 = −r_u m_u g μ
    upper = minimal_inverse_dynamics(robot, q, qd2, qdd) - minimal_inverse_dynamics(
        robot, q, qd2, qdd, friction=False
    )
    expected_2 = robot.upper_platform_radius * robot.upper_platform.mass * robot.gravity
    expected_2 *= robot.friction.mu
    np.testing.assert_allclose(upper, [[0.0, expected_2]], rtol=1e-12, atol=1e-15)


# --- 5: a payload at the mass centre is extra platform mass ---------------------------


@FAST
@given(state=states, mass=st.floats(0.0, 0.5))
def test_payload_at_mass_centre_equals_heavier_platform(robot, state, mass):
    q0, qd0, qdd0 = (x[None] for x in state)
    carrying = dataclasses.replace(robot, payload=Payload(mass=mass, offset=np.zeros(3)))
    heavier = dataclasses.replace(
        robot,
        upper_platform=dataclasses.replace(
            robot.upper_platform, mass=robot.upper_platform.mass + mass
        ),
    )
    for friction in (False, True):
        np.testing.assert_allclose(
            minimal_inverse_dynamics(carrying, q0, qd0, qdd0, friction=friction),
            minimal_inverse_dynamics(heavier, q0, qd0, qdd0, friction=friction),
            rtol=1e-10,
            atol=1e-12,
        )


# --- shapes and bad input ---------------------------------------------------------------


def test_vectorised_matches_one_by_one(robot):
    rng = np.random.default_rng(0)
    q = rng.uniform(-LIMIT, LIMIT, (7, 2))
    qd, qdd = rng.normal(size=(7, 2)), rng.normal(size=(7, 2))
    batch = minimal_inverse_dynamics(robot, q, qd, qdd)
    single = np.vstack(
        [minimal_inverse_dynamics(robot, *(a[i : i + 1] for a in (q, qd, qdd))) for i in range(7)]
    )
    np.testing.assert_allclose(batch, single, rtol=1e-14, atol=1e-15)
    kinetic, potential = minimal_energy(robot, q, qd)
    assert kinetic.shape == potential.shape == (7,)
    assert np.all(kinetic > 0.0)


def test_bad_shapes_are_rejected(robot):
    with pytest.raises(InputError, match="qd"):
        minimal_inverse_dynamics(robot, np.zeros((3, 2)), np.zeros((2, 2)), np.zeros((3, 2)))
    with pytest.raises(InputError, match="q"):
        minimal_energy(robot, np.zeros((3, 3)), np.zeros((3, 3)))
    with pytest.raises(InputError, match="finite"):
        minimal_energy(robot, np.full((1, 2), np.nan), np.zeros((1, 2)))


def test_paper_robot_is_the_prototype(paper_problem):
    assert so.load_robot(PROTOTYPE).upper_platform_radius == pytest.approx(
        paper_problem.robot.upper_platform_radius
    )
