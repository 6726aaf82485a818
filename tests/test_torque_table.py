"""The tabulated torque (spm_opt.model.torque_table) against the exact Lagrange model."""

import dataclasses

import casadi as ca
import numpy as np
import pytest

from spm_opt.model import dynamics
from spm_opt.model import torque_table as table
from spm_opt.model.params import Friction, Payload

SAMPLES = 2000
SPEED, ACCELERATION = 1.5, 1.0  # rad/s, rad/s²: the bound TORQUE_ERROR is stated for


@pytest.fixture(scope="module")
def robot(paper_problem):
    return paper_problem.robot


@pytest.fixture(scope="module")
def loaded(robot):
    """The prototype with a 0.2 kg tool off the platform's centre and other friction."""
    return dataclasses.replace(
        robot,
        payload=Payload(mass=0.2, offset=np.array([0.02, 0.01, -0.03])),
        friction=Friction(mu=0.1, smoothing=2e-3),
    )


@pytest.fixture(scope="module")
def torque(robot):
    return table.torque_function(robot.joint_range)


def samples(robot, seed: int):
    """Seeded states (N, 2) each: q within the joint range, q̇ and q̈ within the bound's."""
    rng = np.random.default_rng(seed)
    low, high = robot.joint_range[:, 0], robot.joint_range[:, 1]
    q = rng.uniform(low, high, (SAMPLES, 2))
    qd = rng.uniform(-SPEED, SPEED, (SAMPLES, 2))
    return q, qd, rng.uniform(-ACCELERATION, ACCELERATION, (SAMPLES, 2))


def tabulated(torque, robot, q, qd, qdd):
    mapped = torque.map("torques", "serial", len(q), [3], [])
    return np.array(mapped(q.T, qd.T, qdd.T, table.table_values(robot))).T


@pytest.mark.parametrize(("name", "seed"), [("robot", 1), ("loaded", 2)])
def test_within_documented_error_of_exact_model(name, seed, request, torque):
    robot = request.getfixturevalue(name)
    q, qd, qdd = samples(robot, seed)
    exact = dynamics.inverse_dynamics(robot, q, qd, qdd, exact=False)
    assert np.max(np.abs(tabulated(torque, robot, q, qd, qdd) - exact)) < table.TORQUE_ERROR


def test_one_function_serves_robots_that_differ(robot, loaded, torque):
    """Same joint range, same Function; the values carry the robot, and matter."""
    assert table.torque_function(loaded.joint_range) is torque
    q, qd, qdd = samples(robot, seed=7)
    difference = tabulated(torque, loaded, q, qd, qdd) - tabulated(torque, robot, q, qd, qdd)
    assert np.max(np.abs(difference)) > 1000 * table.TORQUE_ERROR


def test_exact_at_grid_points(loaded, torque):
    """The splines interpolate the tabulated maps: at the grid's points only the rounding of
    their reduction to R functions (~1e-12) is left, so the decomposition into base
    parameters is itself exact."""
    q1, q2 = np.meshgrid(*table.grid(loaded.joint_range), indexing="ij")
    q = np.stack([q1.ravel(), q2.ravel()], axis=1)[::7]
    rng = np.random.default_rng(3)
    qd = rng.uniform(-SPEED, SPEED, q.shape)
    qdd = rng.uniform(-ACCELERATION, ACCELERATION, q.shape)
    exact = dynamics.inverse_dynamics(loaded, q, qd, qdd, exact=False)
    assert tabulated(torque, loaded, q, qd, qdd) == pytest.approx(exact, abs=1e-10)


def expanded_derivatives(torque):
    """(x = (q, q̇, q̈), values, λ) -> λᵀτ, its gradient and Hessian in x, expanded to SX."""
    x, lam = ca.MX.sym("x", 6), ca.MX.sym("lam", 2)
    values = ca.MX.sym("values", torque.size1_in(3))
    lagrangian = ca.dot(lam, torque(x[0:2], x[2:4], x[4:6], values))
    hessian, gradient = ca.hessian(lagrangian, x)
    return ca.Function("d", [x, values, lam], [lagrangian, gradient, hessian]).expand()


STATE, MULTIPLIERS = np.array([0.3, -0.5, 0.4, -0.2, 0.5, 0.1]), np.array([1.0, -2.0])


def test_expands_to_sx_and_its_derivatives_are_the_splines(robot, torque):
    """Expanded, the gradient and Hessian evaluate with no call but the table's lookup and
    are those of the tabulated torque itself (central differences of its values and of its
    gradient): CasADi differentiates the Taylor expansion, not the lookup."""
    derivatives = expanded_derivatives(torque)
    assert derivatives.is_a("SXFunction")
    assert [f.name() for f in derivatives.find_functions()] == ["torque_table_lookup"]
    values, step = table.table_values(robot), 1e-6
    _, gradient, hessian = (np.array(v) for v in derivatives(STATE, values, MULTIPLIERS))
    for k in range(6):
        shift = step * np.eye(6)[k]
        up, down = (derivatives(STATE + s, values, MULTIPLIERS) for s in (shift, -shift))
        assert float(up[0] - down[0]) / (2 * step) == pytest.approx(gradient[k, 0], abs=1e-7)
        column = (np.array(up[1]) - np.array(down[1])) / (2 * step)
        assert column.ravel() == pytest.approx(hessian[:, k], abs=1e-5)


def test_hessian_near_the_exact_models(robot, torque):
    """The Hessian of λᵀτ to the splines' second-derivative accuracy (~1e-3 relative)."""
    hessian = np.array(
        expanded_derivatives(torque)(STATE, table.table_values(robot), MULTIPLIERS)[2]
    )
    x, lam = ca.SX.sym("x", 6), ca.SX.sym("lam", 2)
    parameters = ca.SX.sym("p", dynamics.parameter_vector(robot).size)
    frictionless, smooth, _ = dynamics._model().torque(x[0:2], x[2:4], x[4:6], parameters)
    lagrangian = ca.dot(lam, frictionless + smooth)
    exact = ca.Function("exact", [x, parameters, lam], [ca.hessian(lagrangian, x)[0]])
    reference = np.array(exact(STATE, dynamics.parameter_vector(robot), MULTIPLIERS))
    assert hessian == pytest.approx(reference, abs=1e-2 * np.max(np.abs(reference)))


def test_expanded_nlp_hessian_over_points(robot, torque):
    """Mapped over points in an MX graph and expanded (one lookup call per point, as in an
    NLP with ``expand``), the Hessian of Σ τᵀτ is finite and the unexpanded graph's."""
    points = 3
    x, values = ca.MX.sym("x", 6, points), ca.MX.sym("values", torque.size1_in(3))
    mapped = torque.map("torques", "serial", points, [3], [])
    effort = ca.sumsqr(mapped(x[0:2, :], x[2:4, :], x[4:6, :], values))
    hessian = ca.Function("h", [x, values], [ca.hessian(effort, ca.vec(x))[0]])
    state = np.tile(STATE[:, None], (1, points)) + 0.1 * np.arange(points)
    expanded = np.array(hessian.expand()(state, table.table_values(robot)))
    assert np.all(np.isfinite(expanded))
    assert expanded == pytest.approx(
        np.array(hessian(state, table.table_values(robot))), rel=1e-9, abs=1e-12
    )
