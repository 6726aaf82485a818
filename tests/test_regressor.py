"""The regressor τ = Y π + τ_payload and the base parameters, against the model's torques
and against torques recomputed for changed robots."""

import dataclasses

import casadi as ca
import numpy as np
import pytest

from spm_opt.model import dynamics, regressor
from spm_opt.model.base_parameters import base_parameters, random_states
from spm_opt.model.regressor import (
    BODIES,
    DRIVE_PARAMETERS,
    STANDARD_PARAMETERS,
    standard_parameters,
)

NAMES = list(STANDARD_PARAMETERS)


@pytest.fixture(scope="module")
def robot(paper_problem):
    """The prototype with a tool off-centre, a rotor and viscous and Coulomb friction at
    the joints."""
    robot = paper_problem.robot
    payload = dataclasses.replace(robot.payload, mass=0.05, offset=np.array([0.01, -0.02, 0.03]))
    actuator = dataclasses.replace(
        robot.actuator,
        rotor_inertia_kg_m2=2e-3,
        viscous_friction_nm_s_rad=(0.03, 0.05),
        coulomb_friction_nm=(0.02, 0.01),
    )
    return dataclasses.replace(robot, payload=payload, actuator=actuator)


@pytest.fixture(scope="module")
def states(robot):
    return random_states(robot, 300, seed=11)


def torques(robot, states):
    return dynamics.actuator_torque(robot, *states)


def predicted(robot, states, standard):
    y, payload = regressor.regressor(robot, *states)
    return y @ standard + payload


def test_y_pi_is_the_models_torque(robot, states):
    expected = torques(robot, states)
    assert np.max(np.abs(predicted(robot, states, standard_parameters(robot)) - expected)) <= (
        1e-10 * np.max(np.abs(expected))
    )


def test_the_columns_hold_none_of_the_parameters():
    function = regressor.link_function()
    names = dynamics.PARAMETER_NAMES
    parameters = ca.SX.sym("p", len(names))
    columns, _ = function(ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2), parameters)
    linear = [names.index(n) for n in NAMES if n.split(".")[0] in BODIES]
    linear += [names.index("mu")]  # the rails' columns are at μ = 1: μ is not in them
    assert ca.jacobian(columns, parameters[linear]).nnz() == 0


def _changed(robot, name, step):
    """``robot`` with the standard parameter ``name`` raised by ``step`` (bodies only)."""
    body, kind, *entry = name.split(".")
    part = getattr(robot, body)
    if kind == "mass":
        return dataclasses.replace(
            robot, **{body: dataclasses.replace(part, mass=part.mass + step)}
        )
    i, j = ("xyz".index(c) for c in entry[0])
    inertia = part.inertia.copy()
    inertia[i, j] += step
    inertia[j, i] = inertia[i, j]
    return dataclasses.replace(robot, **{body: dataclasses.replace(part, inertia=inertia)})


@pytest.mark.parametrize("name", [n for n in NAMES if n.split(".")[0] in BODIES])
def test_a_bodys_column_is_the_change_of_torque_per_unit(robot, states, name):
    step = 0.01 if name.endswith("mass") else 1e-4
    change = torques(_changed(robot, name, step), states) - torques(robot, states)
    y, _ = regressor.regressor(robot, *states)
    expected = step * y[:, :, NAMES.index(name)]
    rail = {"upper_platform.mass": "upper", "lower_platform.mass": "lower"}.get(name)
    if rail is not None:  # a platform's mass weighs on its rail too
        expected += robot.friction.mu * step * y[:, :, NAMES.index(f"rail_friction.{rail}")]
    assert np.max(np.abs(change - expected)) <= 1e-12 + 1e-9 * np.max(np.abs(change))


def test_the_rails_columns_are_the_friction_per_unit_of_mu_times_mass(robot, states):
    friction = dataclasses.replace(robot.friction, mu=robot.friction.mu + 0.1)
    change = torques(dataclasses.replace(robot, friction=friction), states) - torques(robot, states)
    y, _ = regressor.regressor(robot, *states)
    upper = robot.upper_platform.mass + robot.payload.mass
    rails = 0.1 * (upper * y[..., NAMES.index("rail_friction.upper")])
    rails += 0.1 * robot.lower_platform.mass * y[..., NAMES.index("rail_friction.lower")]
    assert np.max(np.abs(change - rails)) <= 1e-12


def test_the_drive_columns(robot, states):
    q, qd, qdd = states
    y, _ = regressor.regressor(robot, *states)
    for joint in (0, 1):
        other = 1 - joint
        for term, expected in [
            ("rotor_inertia", qdd[:, joint]),
            ("viscous_friction", qd[:, joint]),
            ("coulomb_friction", np.sign(qd[:, joint])),
            ("offset", np.ones(len(q))),
        ]:
            column = y[..., NAMES.index(f"{term}.theta{joint + 1}")]
            assert np.array_equal(column[:, joint], expected)
            assert np.all(column[:, other] == 0.0)
    assert len(DRIVE_PARAMETERS) == 8


def test_base_parameters_give_the_same_torques_at_new_states(robot):
    base = base_parameters(robot)
    assert base.rank == 22
    assert {NAMES[k] for k in base.unseen} == {
        f"upper_arc.inertia.{ij}" for ij in ("yy", "zz", "xy", "xz", "yz")
    } | {f"lower_arc.inertia.{ij}" for ij in ("xx", "zz", "xy", "xz", "yz")}
    fresh = random_states(robot, 200, seed=99)
    y, _ = regressor.regressor(robot, *fresh)
    standard = standard_parameters(robot)
    assert np.max(np.abs(base.columns(y) @ base.values(standard) - y @ standard)) <= 1e-13
    assert len(base.names()) == base.rank and base.names()[0].startswith(NAMES[base.independent[0]])


def test_each_dependent_direction_leaves_the_torques_unchanged(robot):
    """π + e_d − Σ K[i, d] e_i has the same torques: the dependences are exact."""
    base = base_parameters(robot)
    y, _ = regressor.regressor(robot, *random_states(robot, 200, seed=7))
    scale = np.max(np.abs(y))
    for column, dependent in enumerate(base.dependent):
        direction = np.zeros(len(NAMES))
        direction[dependent] = 1.0
        direction[base.independent] -= base.combination[:, column]
        assert np.max(np.abs(y @ direction)) <= 1e-12 * scale
