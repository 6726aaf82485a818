"""The predicted cut: a plan run through the closed-loop model of a robot file before the
robot moves, judged as a run's true cut; ``spm-opt execute`` refuses a plan whose predicted
cut leaves the tube, unless told to warn, and says which robot limit its predicted run
breaks, or refuses it when told to."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from test_bad_inputs import assert_one_error, run_cli

import spm_opt as so
from spm_opt.execution import Executor, SimulatedRobot
from spm_opt.judge.limits import ROBOT, RULES
from spm_opt.verify.executed_cut import evaluate_log
from spm_opt.verify.predicted_cut import (
    FEED_RESOLUTION,
    LIMIT_SHARES,
    highest_feed_inside,
    predict_cut,
)

ROOT = Path(__file__).resolve().parents[1]
FLAP = ROOT / "problems" / "craniotomy_bone_flap.toml"
PLANT = ROOT / "problems" / "robots" / "prototype_plant.toml"


@pytest.fixture(scope="module")
def flap_plan():
    problem = so.load_problem(FLAP)
    return problem, so.plan(problem, "toppra")


def test_the_prediction_holds_the_true_cut_of_a_plant_whose_loops_it_does_not_know(
    flap_plan, tmp_path
):
    """The model is prototype_plant.toml with its file's loops (ωv 150 1/s); the plant runs
    the control table's default gains, whose ωv is 87 and 116 1/s on that plant: the
    predicted cut lies within 0.01 mm of the true one (measured: 0.0868 against 0.0894)."""
    problem, plan = flap_plan
    plant = so.load_robot(PLANT)
    predicted = predict_cut(problem, plan, plant)
    backend = SimulatedRobot(problem.robot, start_rad=plan.position(0.0), plant_robot=plant)
    result = Executor(problem, backend).run(plan, tmp_path / "run.csv")
    assert result.completed
    backend.trace.save(tmp_path / "trace.npz")
    true = evaluate_log(problem, tmp_path / "run.csv", tmp_path / "trace.npz").true
    assert predicted.report.completed and predicted.report.angles == "true"
    assert abs(predicted.deviation_mm - true.max_contour_deviation_mm) <= 0.01
    assert predicted.deviation_mm > 0.05  # the plant's offsets and friction: far from 0
    assert predicted.inside and "inside the 0.1 mm tube" in predicted.summary()
    assert predicted.farthest_at.startswith("the cut from A")


def test_the_prediction_names_the_robot_limits_the_true_run_breaks(flap_plan, tmp_path):
    """toppra's plan of the paper's flap, on prototype_plant.toml running its own loops: the
    plant sticks where a joint comes to rest and breaks away after it, which breaks the
    joint acceleration and jerk limits that the plan keeps (measured: theta2 jerk 30.1
    rad/s³ true, 23.6 predicted, both at t = 21.00 s). The prediction names the same robot
    limits, with each worst within 0.1 s of the true one's."""
    problem, plan = flap_plan
    plant = so.load_robot(PLANT)
    assert not so.evaluate(problem, plan).violations
    predicted = predict_cut(problem, plan, plant)
    backend = SimulatedRobot(problem.robot, start_rad=plan.position(0.0), plant_robot=plant)
    Executor(problem, backend).run(plan, tmp_path / "run.csv")
    backend.trace.save(tmp_path / "trace.npz")
    true = evaluate_log(problem, tmp_path / "run.csv", tmp_path / "trace.npz").true
    robot_rules = {name for name, rule in RULES.items() if rule.judges == ROBOT}
    true_broken = {v.limit: v for v in true.violations if v.rule in robot_rules}
    assert {"joint jerk", "joint acceleration"} <= {v.rule for v in true_broken.values()}
    assert {v.limit for v in predicted.broken_limits} == set(true_broken)
    for violation in predicted.broken_limits:
        assert abs(violation.time_s - true_broken[violation.limit].time_s) <= 0.1
    worst = predicted.broken_limits[0]
    assert worst.worst / worst.allowed >= max(v.worst / v.allowed for v in predicted.broken_limits)
    assert predicted.limits_line().startswith(f"predicted run on prototype_plant breaks {worst}")


def test_a_predicted_run_inside_a_joint_limit_but_past_its_margin_does_not_keep_it():
    """toppra's hardware plan runs θ1 at its speed limit. At 0.97 of its pace its predicted
    run breaks no robot limit, but takes θ1's speed past the 95 % of the limit the margin
    allows (measured: 98.6 %); at 0.9 of the pace it keeps every margin (91.5 %). Each
    share is the judged figure over its limit; a run past a margin does not keep the limits,
    and its line says which and by how much."""
    problem = so.load_problem(ROOT / "problems" / "craniotomy_hardware.toml")
    plan = so.plan(problem, "toppra")
    near = predict_cut(problem, plan.time_scaled(0.97))
    assert not near.broken_limits and not near.keeps_limits
    shares = near.report.limit_shares
    assert set(shares) == {f"theta{j} {f}" for j in (1, 2) for f in LIMIT_SHARES}
    assert LIMIT_SHARES["speed"] < shares["theta1 speed"] <= 1.005
    assert [name for name, _ in near.past_margin] == ["theta1 speed"]
    speed = near.report.peak_joint_speed_rad_s[0] / near.report.joint_speed_limit_rad_s
    assert shares["theta1 speed"] == pytest.approx(speed, rel=1e-12)
    assert near.limits_line() == (
        f"predicted run on prototype takes theta1 speed to {shares['theta1 speed']:.1%} of its "
        "limit, past the 95% kept for what the model does not see"
    )
    slower = predict_cut(problem, plan.time_scaled(0.9))
    assert slower.keeps_limits and not slower.past_margin and slower.limits_line() == ""
    assert slower.report.limit_shares["theta1 speed"] < LIMIT_SHARES["speed"]


def test_the_commands_help_states_the_margins_the_prediction_keeps(capsys):
    """``execute --predicted-limits`` and ``slow-breakaways`` say the shares
    :data:`LIMIT_SHARES` keeps, as a person reads them in the help."""
    speed, jerk = (f"{LIMIT_SHARES[f]:.0%}".replace("%", " %") for f in ("speed", "jerk"))
    assert LIMIT_SHARES["acceleration"] == LIMIT_SHARES["jerk"]
    for command in ("execute", "slow-breakaways"):
        assert run_cli([command, "--help"])[0] == 0
        text = " ".join(capsys.readouterr().out.split())
        assert f"speed past {speed}" in text or f"speed within {speed}" in text
        assert f"jerk past {jerk}" in text or f"jerk within {jerk}" in text


def tight_problem(tmp_path: Path) -> Path:
    """The paper's flap on prototype_plant.toml, with a 0.05 mm tube."""
    text = FLAP.read_text(encoding="utf-8")
    text = text.replace('robot = "robots/prototype.toml"', f'robot = "{PLANT.as_posix()}"')
    text = text.replace("contour_tolerance_mm = 0.1", "contour_tolerance_mm = 0.05")
    path = tmp_path / "tight.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_execute_refuses_a_plan_whose_predicted_cut_leaves_the_tube_unless_told_to_warn(
    tmp_path, capsys
):
    problem_path = tight_problem(tmp_path)
    plan = tmp_path / "plans" / "plan.csv"
    plan.parent.mkdir()
    so.plan(so.load_problem(problem_path), "toppra").to_csv(plan)
    log = tmp_path / "logs" / "run.csv"
    command = ["execute", str(plan), "--problem", str(problem_path), "--backend", "sim"]
    command += ["--log", str(log)]
    status, shown = run_cli(command)
    expected = ("plan refused: predicted cut on prototype_plant", "outside the 0.05 mm tube")
    assert_one_error(status, capsys.readouterr().err, expected, tmp_path, shown)
    assert not log.parent.exists() or not any(log.parent.iterdir())

    status, _ = run_cli([*command, "--predicted-outside", "warn"])
    assert status == 0
    assert "outside the 0.05 mm tube; run all the same" in capsys.readouterr().err
    assert log.exists()

    status, _ = run_cli(["predict", str(plan), "--problem", str(problem_path), "--json"])
    assert status == 1
    report = json.loads(capsys.readouterr().out)
    assert report["angles"] == "true" and report["completed"]
    assert report["max_contour_deviation_mm"] > 0.05
    assert "outside the 0.05 mm tube" in report["summary"]
    assert any(v["rule"] == "contour deviation" for v in report["violations"])


def test_execute_says_which_robot_limit_the_predicted_run_breaks_and_refuses_when_told(
    flap_plan, tmp_path, capsys
):
    """The paper's flap on its own model: toppra's plan is predicted inside the tube, and
    its predicted run breaks the joint jerk limit where the joints stick and break away."""
    plan = tmp_path / "plans" / "plan.csv"
    plan.parent.mkdir()
    flap_plan[1].to_csv(plan)
    log = tmp_path / "logs" / "run.csv"
    command = ["execute", str(plan), "--problem", str(FLAP), "--backend", "sim"]
    command += ["--log", str(log)]
    status, shown = run_cli([*command, "--predicted-limits", "refuse"])
    expected = ("plan refused: predicted run on prototype breaks theta", "jerk")
    assert_one_error(status, capsys.readouterr().err, expected, tmp_path, shown)
    assert not log.parent.exists() or not any(log.parent.iterdir())

    status, _ = run_cli(command)
    assert status == 0
    said = capsys.readouterr().err
    assert "predicted run on prototype breaks theta" in said
    assert "run all the same (--predicted-limits refuse refuses it; spm-opt slow-breakaways" in said
    assert log.exists()


@pytest.mark.slow
def test_the_highest_feed_found_is_predicted_inside_and_the_next_tried_above_it_outside():
    """The paper's flap on prototype_plant.toml with its encoder offsets at zero, in a
    0.022 mm tube: toppra's plan is predicted at 0.028 mm at full feed, 0.024 at 0.75 and
    0.019 at 0.5 (the lag and the friction's share shrink with the pace)."""
    problem = so.load_problem(FLAP, {"limits.contour_tolerance_mm": 0.022})
    plan = so.plan(problem, "toppra")
    plant = dataclasses.replace(so.load_robot(PLANT), encoder_offset=np.zeros(2))
    tried: dict[float, bool] = {}
    found = highest_feed_inside(
        problem, plan, plant, progress=lambda feed, cut: tried.__setitem__(feed, cut.inside)
    )
    assert found is not None
    feed, predicted = found
    assert predicted.inside and tried[feed] and not tried[1.0]
    outside_above = [f for f, inside in tried.items() if not inside and f > feed]
    assert min(outside_above) - feed <= FEED_RESOLUTION + 1e-9
    assert all(inside for f, inside in tried.items() if f < feed)
    assert 0.5 <= feed < 0.75
