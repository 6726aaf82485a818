"""The predicted cut: a plan run through the closed-loop model of a robot file before the
robot moves, judged as a run's true cut; ``spm-opt execute`` refuses a plan whose predicted
cut leaves the tube, unless told to warn."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from test_bad_inputs import assert_one_error, run_cli

import spm_opt as so
from spm_opt.execution import Executor, SimulatedRobot
from spm_opt.verify.executed_cut import evaluate_log
from spm_opt.verify.predicted_cut import FEED_RESOLUTION, highest_feed_inside, predict_cut

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
