"""The MuJoCo multibody model: kinematics, statics, power balance and open-loop tracking."""

from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

import spm_opt as so  # noqa: E402
from spm_opt.model import kinematics  # noqa: E402
from spm_opt.model.params import Robot, load_robot  # noqa: E402
from spm_opt.verify import multibody as mb  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PROTOTYPE = ROOT / "problems" / "robots" / "prototype.toml"
HARDWARE = ROOT / "problems" / "craniotomy_hardware.toml"
DEG = np.pi / 180.0


@pytest.fixture(scope="module")
def robot() -> Robot:
    return load_robot(PROTOTYPE)


@pytest.fixture(scope="module")
def model(robot: Robot) -> "mujoco.MjModel":
    return mb.build_model(robot)


def _random_configurations(n: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-60.0 * DEG, 60.0 * DEG, size=(n, 2))


def test_model_has_four_hinges_and_one_loop_closure(model: "mujoco.MjModel") -> None:
    assert model.nv == 4 and model.nq == 4
    assert model.neq == 1 and model.eq_type[0] == mujoco.mjtEq.mjEQ_CONNECT
    assert model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert np.all(model.dof_damping == 0.0) and np.all(model.dof_armature == 0.0)
    assert np.all(model.dof_frictionloss == 0.0)


def test_kinematics_match_eq_5_and_eq_17(robot: Robot, model: "mujoco.MjModel") -> None:
    data = mujoco.MjData(model)
    q = _random_configurations(12)
    qd = np.random.default_rng(2).normal(size=q.shape)
    points = kinematics.forward_kinematics(q, robot.upper_platform_radius)
    upper, lower = kinematics.platform_frames(q)
    ratio = robot.lower_platform_radius / robot.upper_platform_radius
    up, low = model.body("upper_platform").id, model.body("lower_platform").id
    up_arc, low_arc = model.body("upper_arc").id, model.body("lower_arc").id
    for k in range(q.shape[0]):
        mb.set_state(model, data, q[k], qd[k])
        c1, s1, c2, s2 = np.cos(q[k, 0]), np.sin(q[k, 0]), np.cos(q[k, 1]), np.sin(q[k, 1])
        np.testing.assert_allclose(data.xipos[up], points[k], rtol=0, atol=1e-14)
        np.testing.assert_allclose(data.xipos[low], ratio * points[k], rtol=0, atol=1e-14)
        np.testing.assert_allclose(data.xmat[up].reshape(3, 3), upper[k], rtol=0, atol=1e-14)
        np.testing.assert_allclose(data.xmat[low].reshape(3, 3), lower[k], rtol=0, atol=1e-14)
        rx = np.array([[1, 0, 0], [0, c1, -s1], [0, s1, c1]])
        ry = np.array([[c2, 0, s2], [0, 1, 0], [-s2, 0, c2]])
        np.testing.assert_allclose(data.xmat[up_arc].reshape(3, 3), rx, rtol=0, atol=1e-15)
        np.testing.assert_allclose(data.xmat[low_arc].reshape(3, 3), ry, rtol=0, atol=1e-15)
        # the loop is closed, and the passive rates keep it closed
        assert np.max(np.abs(data.efc_pos[: data.nefc])) < 1e-15
        jacobian = mb.equality_jacobian(model, data)
        assert jacobian.shape == (3, 4) and np.linalg.matrix_rank(jacobian, tol=1e-12) == 2
        np.testing.assert_allclose(jacobian @ data.qvel, 0.0, rtol=0, atol=1e-15)


def test_passive_rates_and_accelerations_differentiate_the_angles() -> None:
    q = _random_configurations(5, seed=3)
    rng = np.random.default_rng(4)
    qd, qdd = rng.normal(size=q.shape), rng.normal(size=q.shape)
    h = 1e-4

    def phi(t: float) -> np.ndarray:
        return mb.passive_angles(q + qd * t + 0.5 * qdd * t * t)

    _, phid, phidd = mb.passive_motion(q, qd, qdd)
    np.testing.assert_allclose(phid, (phi(h) - phi(-h)) / (2 * h), rtol=0, atol=1e-7)
    np.testing.assert_allclose(phidd, (phi(h) - 2 * phi(0) + phi(-h)) / h**2, rtol=0, atol=1e-5)


def _potential(robot: Robot, q: np.ndarray) -> np.ndarray:
    b_z = kinematics.forward_kinematics(q, robot.upper_platform_radius)[:, 2]
    ratio = robot.lower_platform_radius / robot.upper_platform_radius
    return robot.gravity * (
        robot.upper_platform.mass * b_z
        + robot.lower_platform.mass * ratio * b_z
        + robot.upper_arc.mass * robot.upper_arc.com_radius * np.cos(q[:, 0])
        + robot.lower_arc.mass * robot.lower_arc.com_radius * np.cos(q[:, 1])
    )


def test_statics_equal_the_gradient_of_the_potential(robot: Robot, model: "mujoco.MjModel") -> None:
    assert robot.payload.mass == 0.0
    q = _random_configurations(10, seed=5)
    torque, residual = mb.multibody_inverse_dynamics(
        robot, q, np.zeros_like(q), np.zeros_like(q), model=model, return_residual=True
    )
    h = 1e-5
    gradient = np.stack(
        [
            (_potential(robot, q + h * e) - _potential(robot, q - h * e)) / (2 * h)
            for e in np.eye(2)
        ],
        axis=-1,
    )
    scale = np.max(np.abs(gradient))
    np.testing.assert_allclose(torque, gradient, rtol=0, atol=1e-7 * scale)
    assert np.max(residual) < 1e-12


def test_payload_is_merged_into_the_upper_platform(robot: Robot) -> None:
    from dataclasses import replace

    from spm_opt.model.params import Payload

    offset = np.array([0.01, -0.02, 0.03])
    loaded = replace(robot, payload=Payload(mass=0.2, offset=offset))
    model = mb.build_model(loaded)
    data = mujoco.MjData(model)
    q = np.array([0.3, -0.4])
    mb.set_state(model, data, q)
    upper, _ = kinematics.platform_frames(q[None])
    point = kinematics.forward_kinematics(q[None], robot.upper_platform_radius)[0]
    centre = (robot.upper_platform.mass * point + 0.2 * (point + upper[0] @ offset)) / (
        robot.upper_platform.mass + 0.2
    )
    np.testing.assert_allclose(data.xipos[model.body("upper_platform").id], centre, atol=1e-14)
    # the extra static torque is the payload's weight through its Jacobian
    h = 1e-6
    extra = np.empty(2)
    for j, e in enumerate(np.eye(2)):
        heights = []
        for sign in (1.0, -1.0):
            qq = (q + sign * h * e)[None]
            frame, _ = kinematics.platform_frames(qq)
            b = kinematics.forward_kinematics(qq, robot.upper_platform_radius)[0]
            heights.append((b + frame[0] @ offset)[2])
        extra[j] = 0.2 * robot.gravity * (heights[0] - heights[1]) / (2 * h)
    zero = np.zeros((1, 2))
    difference = mb.multibody_inverse_dynamics(loaded, q[None], zero, zero) - (
        mb.multibody_inverse_dynamics(robot, q[None], zero, zero)
    )
    np.testing.assert_allclose(difference[0], extra, rtol=1e-6, atol=1e-10)


def test_power_balance_along_the_paper_trajectory(
    robot: Robot, model: "mujoco.MjModel", baseline: so.Trajectory
) -> None:
    """∫ τ·θ̇ dt over each 10 s segment equals the change of MuJoCo's own K + U.

    Gauss-Legendre nodes on each cubic piece (the integrand is smooth inside a piece):
    4 × 50 = 200 samples.
    """
    nodes, weights = np.polynomial.legendre.leggauss(50)
    data = mujoco.MjData(model)
    edges = baseline.breakpoints
    assert len(edges) == 5

    def total_energy(t: float) -> float:
        mb.set_state(
            model,
            data,
            baseline.position(t)[0] if np.ndim(baseline.position(t)) == 2 else baseline.position(t),
            baseline.velocity(t),
        )
        potential, kinetic = mb.energy(model, data)
        return potential + kinetic

    for start, end in zip(edges[:-1], edges[1:], strict=True):
        half = 0.5 * (end - start)
        t = start + half * (nodes + 1.0)
        q, qd, qdd = baseline.position(t), baseline.velocity(t), baseline.acceleration(t)
        power = np.sum(mb.multibody_inverse_dynamics(robot, q, qd, qdd, model=model) * qd, 1)
        work = half * np.dot(weights, power)
        change = total_energy(end) - total_energy(start)
        scale = half * np.dot(weights, np.abs(power))
        assert abs(work - change) < 1e-6 * scale, (start, work, change)


def test_energy_matches_the_potential_by_hand(robot: Robot, model: "mujoco.MjModel") -> None:
    data = mujoco.MjData(model)
    q = _random_configurations(4, seed=7)
    for k in range(q.shape[0]):
        mb.set_state(model, data, q[k])
        potential, kinetic = mb.energy(model, data)
        assert kinetic == 0.0
        assert potential == pytest.approx(_potential(robot, q[k : k + 1])[0], rel=1e-13)


def test_open_loop_simulation_follows_the_plan(robot: Robot) -> None:
    """The inverse-dynamics torques, fed open loop to MuJoCo, reproduce the planned motion
    (the robot is unstable under gravity, so this also checks the torques are right)."""
    trajectory = so.plan(so.load_problem(HARDWARE), "cubic")
    error = mb.open_loop_deviation(robot, trajectory, start_s=1.0, duration_s=1.0)
    assert error < 0.01 * DEG, error
    # the check has teeth: torques 0.1 % off leave the plan by far more than 0.01°
    drifted = mb.open_loop_deviation(robot, trajectory, 1.0, 1.0, torque_scale=1.001)
    assert drifted > 0.1 * DEG


def test_agrees_with_the_lagrange_model(robot: Robot, model: "mujoco.MjModel") -> None:
    """The redundant-coordinate Lagrange model (Eq. 7) of spm_opt.model.dynamics gives the
    same frictionless torques as the multibody engine, to rounding."""
    from spm_opt.model import dynamics

    rng = np.random.default_rng(8)
    q = _random_configurations(20, seed=9)
    qd, qdd = rng.normal(size=q.shape), rng.normal(size=q.shape)
    expected = mb.multibody_inverse_dynamics(robot, q, qd, qdd, model=model)
    torque = dynamics.inverse_dynamics(robot, q, qd, qdd, friction=False)
    np.testing.assert_allclose(torque, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))


def test_agrees_with_the_lagrange_model_with_the_rails_friction(robot: Robot) -> None:
    """With μ = 0.24 and an off-centre tool, the friction forces MuJoCo's side computes from
    its own body velocities, masses and frames (applied at B and D) give the Lagrange
    model's torques with exact friction (Eqs. 20–22) to 1e-6 relative RMS."""
    import dataclasses

    from spm_opt.model import dynamics

    payload = dataclasses.replace(robot.payload, mass=0.05, offset=np.array([0.01, 0.0, 0.02]))
    friction = dataclasses.replace(robot.friction, mu=0.24)
    robot = dataclasses.replace(robot, payload=payload, friction=friction)
    rng = np.random.default_rng(4)
    q = _random_configurations(40, seed=5)
    qd, qdd = rng.normal(0.0, 0.3, q.shape), rng.normal(0.0, 1.0, q.shape)
    expected = dynamics.inverse_dynamics(robot, q, qd, qdd, friction=True, exact=True)
    torque = mb.multibody_inverse_dynamics(robot, q, qd, qdd, friction=True)

    def rms(values: np.ndarray) -> float:
        return float(np.sqrt(np.mean(values**2)))

    frictionless = dynamics.inverse_dynamics(robot, q, qd, qdd, friction=False)
    assert rms(expected - frictionless) > 0.1 * rms(expected)  # the friction is there
    assert rms(torque - expected) <= 1e-6 * rms(expected)
