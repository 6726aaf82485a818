"""The excitation planner: at rest at the first landmark at both ends, within every robot
limit as the evaluator measures it, and far better conditioned than a plan of the cut."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import PAPER_PROBLEM

from spm_opt.base.errors import InputError
from spm_opt.judge.evaluate import evaluate
from spm_opt.judge.limits import CUT, ROBOT, RULES
from spm_opt.model.base_parameters import base_parameters
from spm_opt.model.regressor import regressor
from spm_opt.planners import contour_planners, plan
from spm_opt.planners.excitation import (
    FourierBasis,
    designed,
    fourier_motion,
    rest_constraints,
)
from spm_opt.problem.problem import load_problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.studies.comparison import run_planners

SMALL = {"duration_s": 20.0, "periods": 2, "harmonics": 3, "points_per_period": 120}


def _problem(**options):
    return load_problem(
        PAPER_PROBLEM,
        {"planner": {"excitation": {**SMALL, **options}}},
    )


@pytest.fixture(scope="module")
def excitation():
    problem = _problem()
    return problem, plan(problem, "excitation")


def _condition(problem, trajectory: Trajectory, rate_hz: float = 50.0) -> float:
    """cond of the base regressor (unit-norm columns) over the plan, from the numpy
    regressor (exact Coulomb sign), not the planner's design."""
    t = trajectory.time_grid(rate_hz)
    q, qd, qdd, _ = trajectory.states(t)
    y, _ = regressor(problem.robot, q, qd, qdd)
    base = base_parameters(problem.robot)
    w = base.columns(y).reshape(-1, base.rank)
    return float(np.linalg.cond(w / np.linalg.norm(w, axis=0)))


def test_the_fourier_basis_is_the_derivative_of_its_positions():
    t = np.linspace(0.0, 7.0, 2001)
    basis = FourierBasis.at(t, 7.0, 4)
    h = t[1] - t[0]
    for lower, upper in (
        (basis.position, basis.rate),
        (basis.rate, basis.acceleration),
        (basis.acceleration, basis.jerk),
    ):
        assert np.allclose(np.gradient(lower, h, axis=0)[2:-2], upper[2:-2], atol=1e-3)


def test_the_rest_rows_stop_the_series_at_every_whole_period():
    rng = np.random.default_rng(3)
    rows = rest_constraints(4)
    x = rng.normal(size=16)
    for joint in range(2):  # project each joint's coefficients onto the rows' null space
        part = x[8 * joint : 8 * joint + 8]
        x[8 * joint : 8 * joint + 8] = part - np.linalg.pinv(rows) @ (rows @ part)
    q, qd, qdd = fourier_motion(np.array([0.1, -0.2]), x, 5.0, np.array([0.0, 5.0, 10.0]))
    assert np.allclose(q, [[0.1, -0.2]] * 3, atol=1e-12)
    assert np.allclose(qd, 0.0, atol=1e-12) and np.allclose(qdd, 0.0, atol=1e-12)


def test_the_plan_starts_and_ends_at_rest_at_the_first_landmark(excitation):
    problem, trajectory = excitation
    first = problem.landmark_angles[problem.visit_order[0]]
    assert trajectory.duration == pytest.approx(SMALL["duration_s"])
    for time in (trajectory.start_time, trajectory.end_time):
        q, qd, qdd, _ = trajectory.states(np.array([time]))
        assert np.allclose(q[0], first, atol=1e-9)
        assert np.allclose(qd[0], 0.0, atol=1e-12) and np.allclose(qdd[0], 0.0, atol=1e-12)


def test_the_evaluator_finds_the_robot_limits_kept_and_judges_no_cut(excitation):
    problem, trajectory = excitation
    report = evaluate(problem, trajectory)
    assert report.violations == [] and not report.contour_judged
    # the same motion claimed as a cut breaks the cut's limits: they are measured, not judged
    claimed = Trajectory(trajectory._q, {})
    broken = evaluate(problem, claimed).violations
    assert broken and all(RULES[v.rule].judges == CUT for v in broken)
    # it uses the room it has: some robot limit is close to active
    limits = problem.limits
    assert max(report.peak_joint_acceleration_rad_s2) > 0.9 * limits.max_joint_acceleration
    assert all(RULES[name].judges == ROBOT for name in ("joint range", "joint speed"))


def test_the_plan_is_far_better_conditioned_than_the_cut(excitation):
    problem, trajectory = excitation
    cut = plan(problem, "cubic")
    excited, cutting = _condition(problem, trajectory), _condition(problem, cut)
    assert excited < 50.0
    assert excited < cutting / 20.0
    assert trajectory.metadata["statistics"]["condition_number"] < 50.0


def test_the_comparison_leaves_the_excitation_out_unless_asked():
    assert "excitation" not in contour_planners() and "cubic" in contour_planners()
    problem = _problem()
    (outcome,) = run_planners(problem, ["excitation"])
    assert outcome.report is not None and outcome.report.violations == []


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        ({"periods": 0}, "planner.excitation.periods = 0: expected an integer in [1, 1000]"),
        ({"duration_s": float("nan")}, "planner.excitation.duration_s = nan: expected a number"),
        ({"cycles": 3}, "planner.excitation.cycles: unknown key"),
    ],
)
def test_bad_settings_are_one_line_errors(options, expected):
    with pytest.raises(InputError) as error:
        plan(_problem(**options), "excitation")
    assert expected in str(error.value) and "\n" not in str(error.value)


def test_the_design_counts_what_a_motion_can_bring_out(paper_problem):
    base = base_parameters(paper_problem.robot)
    counted = designed(base)
    names = counted.names()
    assert counted.rank == 14 and base.rank == 22
    leading = [name.split(" ")[0] for name in names]
    assert not any(n.startswith("offset.") or n.endswith(("xy", "xz", "yz")) for n in leading)
    # what it keeps is base's own rows: the same combinations
    kept = [base.names().index(n) for n in names]
    assert np.array_equal(base.independent[kept], counted.independent)
    assert np.array_equal(base.combination[kept], counted.combination)
