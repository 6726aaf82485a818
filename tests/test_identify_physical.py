"""Identification kept physical and reported in the lab's terms: a parameter the noise or a
bias pushes past its bound sits at it and is reported so, a body's inertia stays positive
definite with the triangle inequalities, the held-out stretch is never fitted, and the
report's one table says why each parameter is identified or not."""

from __future__ import annotations

import dataclasses
import itertools
import json

import numpy as np
import pytest
from conftest import HARDWARE_PROBLEM
from test_bad_inputs import assert_one_error, run_cli
from test_identify import ROBOTS, _log, synthetic_samples, with_efficiency

from spm_opt.identify.estimate import identify
from spm_opt.identify.report import report_markdown
from spm_opt.identify.robot_file import robot_file_text
from spm_opt.identify.validate import hold_out, joined, plan_period, prediction_rms
from spm_opt.model import dynamics
from spm_opt.model.params import Robot, load_robot
from spm_opt.model.regressor import BODIES

BIAS = -0.014
"""The viscous friction, N·m·s/rad, that the current read once a cycle at 500 Hz shows on a
plant without any: the plant's joint 1 has it, joint 2 has none."""


@pytest.fixture(scope="module")
def biased():
    """The prior, and the identification from synthetic torques of the plant with joint 1's
    viscous friction at :data:`BIAS` and joint 2's at 0."""
    prior = load_robot(ROBOTS / "prototype.toml")
    plant = load_robot(ROBOTS / "prototype_plant.toml")
    plant = with_efficiency(plant, 0.85, viscous_friction_nm_s_rad=(BIAS, 0.0))
    return prior, identify(prior, synthetic_samples(plant, seed=0))


def test_a_friction_pushed_below_zero_sits_at_its_bound_and_is_not_called_identified(biased):
    prior, identification = biased
    names = identification.names
    first = names.index("viscous_friction.theta1")
    second = names.index("viscous_friction.theta2")
    error = identification.standard_error[first]
    # the unconstrained weighted least squares sees the bias, many standard errors below 0
    assert identification.unconstrained[first] == pytest.approx(BIAS, abs=3 * error)
    beyond = -identification.unconstrained[first] / error
    assert beyond > 10.0
    # the consistent estimate sits at the bound, and says how far beyond it the data lay
    assert identification.estimate[first] == 0.0
    assert identification.at_bound[first] and not identification.identified[first]
    why = identification.reasons()[first]
    assert why == (
        "at its bound (viscous_friction.theta1 ≥ 0): the unconstrained fit, "
        f"{identification.unconstrained[first]:.3g}, lay {beyond:.1f} s.e. beyond"
    )
    assert "viscous_friction.theta1 >= 0" in identification.active
    # joint 2's true 0 with noise: never below 0, never identified
    assert identification.estimate[second] >= 0.0 and not identification.identified[second]
    # the robot written carries the bound, and says so
    robot = identification.robot
    assert robot.actuator.viscous_friction_nm_s_rad[0] == 0.0
    assert min(robot.actuator.viscous_friction_nm_s_rad) >= 0.0
    assert min(robot.actuator.coulomb_friction_nm) >= 0.0
    assert robot.actuator.rotor_inertia_kg_m2 >= 0.0 and robot.friction.mu >= 0.0
    text = robot_file_text(identification, PriorLoops(), "identified")  # type: ignore[arg-type]
    assert f"NOT identified ({why}): viscous_friction.theta1" in text
    assert "viscous_friction.theta1 >= 0" in text.split("this file's fit:")[1].splitlines()[0]
    # the report's one table: parameter, estimate ± error, prior, identified, why
    report = report_markdown(identification, prior, [("fitted", np.ones(2), np.ones(2))], 0.1)
    assert "| parameter | estimate ± std. error | prior | identified | why | unit |" in report
    row = next(line for line in report.splitlines() if line.startswith("| viscous_friction.theta1"))
    assert row == f"| viscous_friction.theta1 | 0 ± {error:.2g} | 0 | no | {why} | N·m·s/rad |"
    identified_rows = [line for line in report.splitlines() if "| yes | 2 s.e. within 10 %" in line]
    counted = int(np.sum(identification.identified)) + identification.efficiency_identified
    assert len(identified_rows) == counted
    assert "| upper_arc.inertia.xy | 0 | 0 | no | not seen by any motion: stays at its prior" in (
        report
    )


class PriorLoops:
    """A stand-in for the actuator loops of a synthetic log, which has no goals: the
    prior's, no comment."""

    def comment_lines(self) -> list[str]:
        return []

    def robot(self, robot: Robot) -> Robot:
        return robot


def _triangle_ok(inertia: np.ndarray) -> bool:
    """Positive definite with each principal moment below the sum of the others."""
    moments = np.linalg.eigvalsh(inertia)
    return bool(moments[0] > 0.0 and moments[2] < moments[0] + moments[1])


def _grid(robot: Robot, points: int = 9) -> np.ndarray:
    """Joint angles (points², 2) over the robot's joint range, rad."""
    axes = [np.linspace(low, high, points) for low, high in robot.joint_range]
    return np.array(list(itertools.product(*axes)))


def test_torques_that_would_make_an_inertia_indefinite_give_a_physical_robot(tmp_path):
    # torques of a plant whose lower arc's inertia about its axis is negative, as noise or a
    # bias could make it look: its mass matrix is indefinite over part of the joint range
    prior = load_robot(ROBOTS / "prototype.toml")
    plant = load_robot(ROBOTS / "prototype_plant.toml")
    inertia = plant.lower_arc.inertia.copy()
    inertia[1, 1] = -2e-2
    plant = dataclasses.replace(
        plant, lower_arc=dataclasses.replace(plant.lower_arc, inertia=inertia)
    )
    grid = _grid(prior)
    assert np.min(np.linalg.eigvalsh(dynamics.mass_matrix(plant, grid))) < 0.0
    identification = identify(prior, synthetic_samples(plant, seed=1, duration_s=30.0))
    path = tmp_path / "identified.toml"  # the robot as written, read back
    path.write_text(robot_file_text(identification, PriorLoops(), "identified"), encoding="utf-8")
    robot = load_robot(path)
    for body in BODIES:
        assert getattr(robot, body).mass > 0.0, body
        assert _triangle_ok(getattr(robot, body).inertia), body
    assert np.min(np.linalg.eigvalsh(dynamics.mass_matrix(robot, grid))) > 0.0
    # the consistent base estimate is that of a physical robot too, and says what held it
    bounded = identification.bounded
    assert np.all(identification.estimate[bounded] >= 0.0)
    assert np.any(identification.unconstrained[bounded] < 0.0)
    assert identification.active
    held = identification.at_bound | identification.moved
    assert np.any(held) and not np.any(identification.identified[held])


def test_the_held_out_stretch_is_not_fitted():
    plant = load_robot(ROBOTS / "prototype_plant.toml")
    prior = load_robot(ROBOTS / "prototype.toml")
    samples = synthetic_samples(plant, seed=2, duration_s=40.0)
    fitted, held = hold_out(samples, 0.2)
    assert held is not None
    assert len(fitted.q) + len(held.q) == len(samples.q)
    assert held.duration_s == pytest.approx(0.2 * samples.duration_s, abs=0.02)
    np.testing.assert_array_equal(held.torque, samples.torque[-len(held.q) :])
    # torques corrupted in the held-out stretch leave the estimate as it was, and show in
    # its prediction error alone
    corrupt = samples.torque.copy()
    corrupt[-len(held.q) :] += np.random.default_rng(0).normal(0.0, 0.5, (len(held.q), 2))
    fitted_again, held_again = hold_out(dataclasses.replace(samples, torque=corrupt), 0.2)
    assert held_again is not None
    clean, dirty = identify(prior, fitted), identify(prior, fitted_again)
    np.testing.assert_array_equal(clean.estimate, dirty.estimate)
    np.testing.assert_array_equal(clean.standard, dirty.standard)
    np.testing.assert_array_equal(
        prediction_rms(dirty.robot, fitted_again), prediction_rms(clean.robot, fitted)
    )
    assert np.all(prediction_rms(dirty.robot, held_again) > 10 * prediction_rms(clean.robot, held))


@pytest.mark.parametrize(
    ("period", "held_s"),
    [((4.0, 40.0), 8.0), ((10.0, 40.0), 10.0), ((4.0, 38.0), 8.0 + 1.99)],
)
def test_a_periodic_plan_holds_out_whole_periods(period, held_s):
    # 40 s logged: 20 % is 2 periods of 4 s, or at least one of 10 s; a plan of 38 s holds
    # out what the log holds after it too
    samples = synthetic_samples(load_robot(ROBOTS / "prototype.toml"), seed=0, duration_s=40.0)
    rate = samples.rates_hz[0]
    _, held = hold_out(samples, 0.2, period)
    assert held is not None
    assert len(held.q) == round(held_s * rate)


def test_no_holdout_fits_everything():
    samples = synthetic_samples(load_robot(ROBOTS / "prototype.toml"), seed=0, duration_s=10.0)
    fitted, held = hold_out(samples, 0.0)
    assert held is None and fitted is samples


@pytest.mark.parametrize("value", ["-0.1", "0.6", "nan", "inf"])
def test_a_bad_holdout_is_a_one_line_error(value, tmp_path, capsys):
    log = _log(tmp_path / "ok.csv", 3000)
    out = tmp_path / "out" / "robot.toml"
    argv = ["identify", str(log), "--problem", str(HARDWARE_PROBLEM), "--out", str(out)]
    status, shown = run_cli([*argv, "--holdout", value])
    assert_one_error(status, capsys.readouterr().err, (f"--holdout {value}",), tmp_path, shown)
    assert not out.parent.exists()


def test_logs_joined_filter_as_each_alone():
    robot = load_robot(ROBOTS / "prototype.toml")
    parts = [synthetic_samples(robot, seed=seed, duration_s=10.0) for seed in (0, 1)]
    both = joined(parts)
    assert both.duration_s == pytest.approx(sum(part.duration_s for part in parts))
    np.testing.assert_array_equal(
        both.parallel(both.torque), np.concatenate([part.parallel(part.torque) for part in parts])
    )


def test_a_log_s_header_gives_its_plan_s_period(tmp_path):
    log = tmp_path / "log.csv"
    header = log.with_suffix(".json")
    assert plan_period(log) is None  # no header
    header.write_text(json.dumps({"plan": {"planner": "cubic"}, "plan_duration_s": 40.0}))
    assert plan_period(log) is None  # not periodic
    plan = {"planner": "excitation", "excitation": {"period_s": 10.0, "periods": 12}}
    header.write_text(json.dumps({"plan": plan, "plan_duration_s": 120.0}))
    assert plan_period(log) == (10.0, 120.0)
