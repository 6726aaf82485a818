"""The optimal-control planners' constraint table: every limit declared once, with a bound
the evaluator's findings tighten and rule names the evaluator uses."""

import dataclasses

import numpy as np
import pytest

from spm_opt.base.errors import PlanningError
from spm_opt.judge.limits import RELATIVE_TOLERANCE, RULES, PlannerBounds
from spm_opt.judge.report import Violation
from spm_opt.planners.ocp.constraints import (
    ACCELERATION,
    JERK,
    LIMITS,
    ON_DEMAND,
    POSITION,
    VELOCITY,
    keeping,
)
from spm_opt.planners.ocp.refinement import COVERAGE_TIGHTENING, tightened

KEPT = [rule for limit in LIMITS for rule in limit.rules]
NOT_KEPT = {
    # kept otherwise (landmarks at fixed nodes, a hard range on q) or not by these planners:
    # a plan that breaks one is a planning error, never a re-solve
    "landmark visit",
    "joint range",
    "singularity margin",
    "tool incidence",
    "depth speed",
    "depth acceleration",
}
BOUNDS = PlannerBounds(
    joint_speed=2.0,
    joint_acceleration=3.0,
    joint_jerk=4.0,
    tool_speed=0.005,
    contour_tolerance=1e-4,
    load_torque=1.5,
    joint_range=np.array([[-1.0, 1.0], [-0.5, 0.5]]),
    min_singularity_margin=0.1,
)


def violation(rule: str, worst: float = 1.1, allowed: float = 1.0) -> Violation:
    return Violation(rule, worst, allowed, RULES[rule].unit, 0.0, rule)


def test_every_rule_a_limit_keeps_is_the_evaluators():
    """The evaluator names its findings by :data:`spm_opt.judge.limits.RULES` alone."""
    assert set(KEPT) <= set(RULES)


def test_each_rule_is_kept_by_one_limit_at_most():
    assert len(KEPT) == len(set(KEPT))


def test_every_evaluator_rule_is_kept_or_refused_on_purpose():
    """A rule the evaluator gains must be given to a limit or named here."""
    assert set(RULES) - set(KEPT) == NOT_KEPT


def test_each_limit_has_a_bound_in_planner_bounds_and_a_way_to_keep_it():
    fields = {field.name for field in dataclasses.fields(PlannerBounds)}
    for limit in LIMITS:
        assert limit.bound is None or limit.bound in fields
        assert limit.constraints or limit.variable is not None
        assert limit.variable in (None, POSITION, VELOCITY, ACCELERATION, JERK)
        if limit.variable is not None:
            assert limit.bound is not None


def test_each_variable_is_bounded_once_and_every_constraint_named_once():
    variables = [limit.variable for limit in LIMITS if limit.variable is not None]
    assert sorted(variables) == sorted([POSITION, VELOCITY, ACCELERATION, JERK])
    names = [c.name for limit in LIMITS for c in limit.constraints]
    assert len(names) == len(set(names))


def test_on_demand_rows_answer_the_rule_that_demands_them():
    """The planner adds a constraint's on-demand rows when the evaluator finds its rule."""
    for name in ON_DEMAND:
        limit = keeping(name)
        assert limit is not None
        assert name in [c.name for c in limit.constraints]


@pytest.mark.parametrize("rule", [rule for rule in KEPT if keeping(rule).bound is not None])
def test_a_broken_rule_tightens_its_limits_bound_alone(rule):
    bound = keeping(rule).bound
    after = tightened(BOUNDS, [violation(rule)])
    for field in dataclasses.fields(PlannerBounds):
        before_value, after_value = getattr(BOUNDS, field.name), getattr(after, field.name)
        if field.name == bound:
            factor = 1.0 / 1.1 * (1 - RELATIVE_TOLERANCE / 2)  # allowed / worst, less
            if rule == "coverage":  # a gap's length says nothing about the tube
                factor = COVERAGE_TIGHTENING
            assert after_value == pytest.approx(before_value * factor)
        else:
            assert np.array_equal(after_value, before_value)


@pytest.mark.parametrize("rule", ["backtracking", *sorted(NOT_KEPT)])
def test_a_rule_no_bound_keeps_is_a_planning_error(rule):
    with pytest.raises(PlanningError, match="the plan breaks a limit no bound keeps"):
        tightened(BOUNDS, [violation(rule)])
