"""A reserve from the prediction: a plan whose cut predicted on a robot file leaves the tube
is re-planned once keeping for execution what the prediction says it takes, and the
re-plan's true cut, on that robot, is inside."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_bad_inputs import run_cli

import spm_opt as so
from spm_opt.execution.plant import closed_loop_settings
from spm_opt.verify.executed_cut import evaluate_log

ROOT = Path(__file__).resolve().parents[1]
FIVE = ROOT / "problems" / "craniotomy_five_landmarks.toml"
PLANT = ROOT / "problems" / "robots" / "prototype_plant.toml"
PROTOTYPE = ROOT / "problems" / "robots" / "prototype.toml"


def five_landmarks_and_the_plant(tmp_path: Path) -> tuple[Path, Path]:
    """The five-landmark flap at 4 mm/s in a 0.12 mm tube (planned on prototype.toml), and
    prototype_plant.toml with its encoder offsets at zero as the robot it runs on."""
    robot = tmp_path / "plant.toml"
    text = PLANT.read_text(encoding="utf-8")
    robot.write_text(
        text.replace("encoder_offset_deg = [0.05, -0.03]", "encoder_offset_deg = [0.0, 0.0]"),
        encoding="utf-8",
    )
    problem = FIVE.read_text(encoding="utf-8")
    problem = problem.replace(
        'robot = "robots/prototype.toml"', f'robot = "{PROTOTYPE.as_posix()}"'
    )
    problem = problem.replace("max_tool_speed_mm_s = 3.0", "max_tool_speed_mm_s = 4.0")
    problem = problem.replace("contour_tolerance_mm = 0.1", "contour_tolerance_mm = 0.12")
    path = tmp_path / "five.toml"
    path.write_text(problem, encoding="utf-8")
    return path, robot


@pytest.mark.slow
def test_a_plan_predicted_outside_is_replanned_once_and_its_true_cut_is_inside(tmp_path, capsys):
    """Measured: ocp-min-time's first plan predicted 0.153 mm from the contour; re-planned
    with 0.073 mm kept for execution, 0.109 mm (35.04 s against 34.90 s)."""
    problem_path, robot_path = five_landmarks_and_the_plant(tmp_path)
    plan_path = tmp_path / "plan.csv"
    command = ["plan", str(problem_path), "--planner", "ocp-min-time", "--out", str(plan_path)]
    status, _ = run_cli([*command, "--predicted-reserve", str(robot_path)])
    assert status == 0
    printed = capsys.readouterr().out
    assert "first plan: predicted cut on prototype_plant" in printed
    assert "outside the 0.12 mm tube" in printed
    assert "re-planned keeping 0." in printed and "inside the 0.12 mm tube" in printed
    sidecar = json.loads(plan_path.with_suffix(".json").read_text())
    problem = so.load_problem(problem_path)
    assert sidecar["problem"]["fingerprint"] == problem.fingerprint
    reserve = sidecar["execution_reserve_mm"]
    assert 0.03 < reserve < 0.12
    # the re-plan keeps its narrower tube: the problem's judge finds it inside the problem's
    plan = so.Trajectory.from_csv(plan_path)
    planned = so.evaluate(problem, plan).max_contour_deviation_mm
    assert planned <= 0.12 - reserve + 1e-3
    # the plant runs the file's loops, as a robot whose file identified them does (with
    # the control table's default gains instead, ωv 87 and 116 1/s against the file's 150,
    # a true cut was 0.014 mm beyond its prediction: beyond the margin)
    plant = so.load_robot(robot_path)
    backend = so.SimulatedRobot(
        problem.robot,
        start_rad=plan.position(0.0),
        settings=closed_loop_settings(plant),
        plant_robot=plant,
    )
    log = tmp_path / "run.csv"
    result = so.execute(plan, backend, problem, log)
    backend.trace.save(tmp_path / "run.npz")
    true = evaluate_log(problem, log, tmp_path / "run.npz").true
    assert result.completed and true.max_contour_deviation_mm <= 0.12
