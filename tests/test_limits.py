"""What a limit means is written once (spm_opt.judge.limits) and every planner keeps it as the
evaluator judges it."""

import dataclasses

import numpy as np
import pytest

import spm_opt as so
from spm_opt.judge.limits import RULES, planner_bounds, torque_limit
from spm_opt.model import dynamics
from spm_opt.model.actuator import CurrentTorqueMap

GEAR_EFFICIENCY = 0.8
ROTOR_INERTIA = 0.05  # kg·m², reflected: 0.05 N·m at 1 rad/s²
TORQUE_LIMIT = 0.26  # N·m: below the free plans' peaks (about 0.28), above holding / η


@pytest.fixture(scope="module")
def geared_problem(paper_problem):
    """The paper's flap on actuators with gear losses and rotor inertia, and a torque
    limit that binds."""
    actuator = dataclasses.replace(
        paper_problem.robot.actuator,
        gear_efficiency=GEAR_EFFICIENCY,
        rotor_inertia_kg_m2=ROTOR_INERTIA,
    )
    robot = dataclasses.replace(paper_problem.robot, actuator=actuator)
    limits = dataclasses.replace(paper_problem.limits, max_joint_torque=TORQUE_LIMIT)
    return dataclasses.replace(paper_problem, robot=robot, limits=limits)


def test_the_torque_limit_binds(geared_problem):
    """Without the limit, toppra's plan needs more than it allows: the test below tests
    something."""
    free = dataclasses.replace(
        geared_problem, limits=dataclasses.replace(geared_problem.limits, max_joint_torque=14.0)
    )
    report = so.evaluate(free, so.plan(free, "toppra"))
    assert max(report.peak_torque_nm) > TORQUE_LIMIT * 1.03


@pytest.mark.parametrize("planner", ["toppra", "ruckig", "ocp-min-time", "ocp-min-jerk"])
def test_every_planner_keeps_the_torque_the_evaluator_judges(geared_problem, planner):
    """The evaluator measures the actuator's torque (rotor inertia, 1/η while driving);
    each planner must keep it, not its own idea of it. ruckig's straight joint-space lines
    leave the contour (a cut violation, its nature); no robot limit may be broken."""
    report = so.evaluate(geared_problem, so.plan(geared_problem, planner))
    assert max(report.peak_torque_nm) <= RULES["actuator torque"].allowed(TORQUE_LIMIT)
    broken = [v for v in report.violations if RULES[v.rule].judges == "robot"]
    assert broken == []
    if planner != "ruckig":
        assert report.violations == []


def test_planners_bound_the_load_side_by_efficiency_times_the_limit(geared_problem):
    bounds = planner_bounds(geared_problem, 0.01)
    assert bounds.load_torque == pytest.approx(GEAR_EFFICIENCY * TORQUE_LIMIT * 0.99)
    limits = geared_problem.limits
    tube = limits.contour_tolerance - limits.execution_reserve  # the reserve is execution's
    assert limits.execution_reserve > 0.0
    assert bounds.contour_tolerance == pytest.approx(tube * 0.99)
    assert np.array_equal(bounds.joint_range, geared_problem.robot.joint_range)


def test_the_continuous_current_can_lower_the_torque_limit(paper_problem):
    """A current map with a no-load offset gives less than the rated torque at the rated
    current: that, not the torque rating, is the limit."""
    current_map = CurrentTorqueMap(currents_a=(0.0, 0.7, 1.9), torques_nm=(0.0, 0.0, 12.0))
    actuator = dataclasses.replace(paper_problem.robot.actuator, current_map=current_map)
    problem = dataclasses.replace(
        paper_problem, robot=dataclasses.replace(paper_problem.robot, actuator=actuator)
    )
    assert torque_limit(problem) == pytest.approx(12.0)
    assert torque_limit(paper_problem) == pytest.approx(14.0)


def test_every_rule_is_relative_half_a_percent_or_hard():
    hard = {name for name, rule in RULES.items() if rule.tolerance == 0.0}
    assert hard == {"joint range", "singularity margin"}
    assert {rule.tolerance for rule in RULES.values()} == {0.0, 0.005}
    assert RULES["contour deviation"].allowed(0.1) == pytest.approx(0.1005)
    assert RULES["singularity margin"].allowed(0.2, upper=False) == 0.2


def test_the_holding_torque_leaves_room(geared_problem):
    """The set-up is feasible: holding the robot anywhere on the contour needs less than
    the planners' load-side bound."""
    contour = geared_problem.contour
    q = geared_problem.contour_angles(np.linspace(0.0, contour.length, 400))
    holding = np.max(np.abs(dynamics.gravity_torque(geared_problem.robot, q)))
    assert holding < planner_bounds(geared_problem, 0.02).load_torque
