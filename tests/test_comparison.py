"""The planner comparison: one row per planner from the one evaluator, failures as rows,
the files and figures the command line writes, and the experiment scripts."""

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import experiment_module

import spm_opt as so
from spm_opt.cli import main
from spm_opt.model.params import MM
from spm_opt.planners import PLANNERS
from spm_opt.studies.comparison import COLUMNS

ROOT = Path(__file__).resolve().parents[1]
FAST = ["cubic", "ruckig", "toppra"]


class FailingPlanner:
    name = "always-fails"

    def plan(self, problem):
        raise so.PlanningError("always-fails: no plan, on purpose")


@pytest.fixture
def failing_planner(monkeypatch):
    monkeypatch.setitem(PLANNERS, FailingPlanner.name, FailingPlanner())
    return FailingPlanner.name


def test_one_row_per_planner_with_the_evaluators_figures(paper_problem):
    table = so.compare(paper_problem, FAST)
    assert list(table.columns) == list(COLUMNS)
    assert table["planner"].tolist() == FAST
    for name, row in table.set_index("planner").iterrows():
        report = so.evaluate(paper_problem, so.plan(paper_problem, name))
        assert row["duration_s"] == pytest.approx(report.duration_s)
        assert row["max_contour_deviation_mm"] == pytest.approx(report.max_contour_deviation_mm)
        assert row["effort_n2m2s"] == pytest.approx(report.effort_n2m2s, rel=1e-9)
        assert row["peak_joint_speed_over_limit"] == pytest.approx(
            max(report.peak_joint_speed_rad_s) / report.joint_speed_limit_rad_s
        )
    cubic = table.set_index("planner").loc["cubic"]
    assert cubic["status"] == "5 violation(s)" and "contour deviation" in cubic["violations"]
    assert table.set_index("planner").loc["toppra", "status"] == "ok"


def test_a_failing_planner_is_a_row_and_the_others_still_run(paper_problem, failing_planner):
    table = so.compare(paper_problem, ["cubic", failing_planner, "ruckig"]).set_index("planner")
    failed = table.loc[failing_planner]
    assert failed["status"] == "failed"
    assert failed["error"] == "PlanningError: always-fails: no plan, on purpose"
    assert np.isnan(failed["duration_s"])
    assert table.loc["ruckig", "duration_s"] > 0 and table.loc["cubic", "duration_s"] == 40.0


def test_unknown_planner_is_refused_before_anything_runs(paper_problem):
    with pytest.raises(so.UnknownPlannerError, match=r"planner = 'fastest': unknown"):
        so.compare(paper_problem, ["cubic", "fastest"])


def test_command_writes_the_table_the_summary_and_the_figures(tmp_path, failing_planner, capsys):
    out = tmp_path / "comparison"
    problem = ROOT / "problems" / "craniotomy_bone_flap.toml"
    planners = f"cubic,ruckig,{failing_planner}"
    status = main(["compare", str(problem), "--planners", planners, "--out", str(out)])
    assert status == 1  # a planner failed; the others' table and figures are written
    figures = ["cuts.png", "headline.png", "joints.png", "tool_speed.png", "torques.png"]
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["comparison.csv", "comparison.md", *figures]
    )
    for name in figures:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = (out / "comparison.md").read_text()
    above_the_table = summary.split("| planner |")[0]
    stated = (
        "craniotomy_bone_flap",
        "A1 → A2 → A3 → A4 → A1",
        "tool speed on the skull: 3 mm/s",
        "contour tolerance: 0.1 mm",
        "37.52 s",
    )
    assert all(text in above_the_table for text in stated)
    assert f"**{failing_planner}** failed: PlanningError" in summary
    progress = capsys.readouterr().err
    assert "[3/3] always-fails: PlanningError" in progress
    assert progress.splitlines()[-1] == "spm-opt: 1 of 3 planners failed: always-fails"


def test_the_executed_cut_study_refuses_a_repeat_count_out_of_range(tmp_path):
    out = tmp_path / "study"
    script = [sys.executable, str(ROOT / "experiments" / "executed_cut.py"), "--out", str(out)]
    result = subprocess.run(
        [*script, "--repeats", "0"], capture_output=True, text=True, timeout=120, check=False
    )
    assert result.returncode == 2
    assert result.stderr.splitlines()[-1].endswith(
        "--repeats 0: expected a whole number from 1 to 20"
    )
    assert not out.exists()


@pytest.mark.parametrize(
    "part",
    [{"rows": []}, "not json", ["a", "list"]],
    ids=["an older study's part", "a damaged part", "not a part"],
)
def test_the_compensated_cut_merge_refuses_a_part_it_cannot_read(tmp_path, part):
    text = part if isinstance(part, str) else json.dumps(part)
    (tmp_path / "compensated_cut.part0of1.4mm_s.json").write_text(text)
    script = ROOT / "experiments" / "compensated_cut.py"
    result = subprocess.run(
        [sys.executable, str(script), "--merge", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 2
    assert "compensated_cut.part0of1.4mm_s.json" in result.stderr.splitlines()[-1]
    assert not (tmp_path / "compensated_cut.md").exists()


def test_command_refuses_an_unknown_planner_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "comparison"
    problem = ROOT / "problems" / "craniotomy_bone_flap.toml"
    assert main(["compare", str(problem), "--planners", "cubic,fast", "--out", str(out)]) == 2
    assert "planner = 'fast': unknown" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(
    "command",
    [
        pytest.param(["compare_planners.py", "--planners", "cubic,ruckig"], marks=pytest.mark.slow),
        ["reproduce_paper.py"],
        ["calibrate_prototype.py"],
        ["hardware_verification.py"],
        pytest.param(["feed_hold.py", "--holds", "2"], marks=pytest.mark.slow),
        [
            "executed_cut.py",
            *("--planners", "toppra", "--problems", "craniotomy_hardware", "--repeats", "2"),
        ],
        pytest.param(
            ["hardware_verification.py", "--backend", "emulator"],
            marks=[pytest.mark.slow, pytest.mark.real_time],
        ),
        # the identification experiments' fits load both cores (OpenBLAS): in the real-time
        # tests' group, so that the emulator's runs never share the machine with them
        pytest.param(
            ["identify_prototype.py", "--fit-seconds", "40"],
            marks=[pytest.mark.slow, pytest.mark.xdist_group("real time")],
        ),
        pytest.param(
            ["identification_coverage.py", "--seeds", "1", "--plants", "1", "--fit-seconds", "30"],
            marks=[pytest.mark.slow, pytest.mark.xdist_group("real time")],
        ),
        ["compensated_cut.py", "--merge"],  # its tables from a part (the study: 25 min)
        ["kinematic_calibration.py", "--robots", "3", "--skip-flap"],
    ],
    ids=lambda c: " ".join(c),
)
def test_every_experiment_script_runs(tmp_path, command):
    """Each script in experiments/ in a small setting (every script must be listed here)."""
    listed = {
        "compare_planners.py",
        "reproduce_paper.py",
        "calibrate_prototype.py",
        "hardware_verification.py",
        "identify_prototype.py",
        "identification_coverage.py",
        "feed_hold.py",
        "executed_cut.py",
        "compensated_cut.py",
        "kinematic_calibration.py",
    }
    assert {p.name for p in (ROOT / "experiments").glob("*.py")} == listed
    out = ["--out", str(tmp_path)] if command[0] != "calibrate_prototype.py" else []
    if command[0] == "compensated_cut.py":
        part = json.loads((ROOT / "docs" / "compensated_cut" / "compensated_cut.json").read_text())
        (tmp_path / "compensated_cut.part0of1.json").write_text(
            json.dumps(
                {"rows_layout": experiment_module("compensated_cut").ROWS_LAYOUT, "rows": part[:6]}
            )
        )
    script = [sys.executable, str(ROOT / "experiments" / command[0]), *command[1:], *out]
    result = subprocess.run(script, capture_output=True, text=True, timeout=600, check=False)
    assert result.returncode == 0, result.stderr
    if command[0] == "compare_planners.py":
        table = (tmp_path / "all_problems.csv").read_text().splitlines()
        problems = len(list((ROOT / "problems").glob("*.toml")))
        assert len(table) == 1 + 2 * problems
    if command[0] == "identify_prototype.py":
        study = (tmp_path / "identification_study.md").read_text()
        assert "| gear efficiency η |" in study and "∫τᵀτ dt on the plant" in study
        assert (tmp_path / "identified.toml").is_file() and (tmp_path / "identified.png").is_file()
    if command[0] == "compensated_cut.py":
        rows = json.loads((tmp_path / "compensated_cut.json").read_text())
        assert len(rows) == 6 and "true cut inside" in (tmp_path / "compensated_cut.md").read_text()
        assert (tmp_path / "compensated_cut.png").is_file()
        assert (tmp_path / "compensated_cut_limits.png").is_file()
    if command[0] == "kinematic_calibration.py":
        study = json.loads((tmp_path / "kinematic_calibration.json").read_text())
        assert study["robots"] == 3 and set(study["coverage_40_poses"]) >= {"encoder_zero_1"}
        assert (tmp_path / "kinematic_calibration.png").is_file()
    if command[0] == "identification_coverage.py":
        rows = json.loads((tmp_path / "coverage.json").read_text())
        assert [row["sweep"] for row in rows] == [
            "plant equal to the model",
            "family around prototype.toml",
        ]
        assert all(0.0 <= row["coverage_all"] <= 1.0 for row in rows)
    if command[0] == "hardware_verification.py":
        summary = json.loads((tmp_path / "hardware_verification.json").read_text())
        assert summary["run"]["completed"]
        if "emulator" not in command:  # the simulated robot names the robot it integrates
            assert summary["run"]["plant_robot"] == "prototype_plant"
        assert {p.name for p in tmp_path.glob("fig*.png")} == {
            "fig15_tracking.png",
            "fig19_torque_theta1.png",
            "fig20_torque_theta2.png",
            "fig25_motion_capture.png",
        }
        assert (tmp_path / "executed_cut.png").is_file()
    if command[0] == "executed_cut.py":
        rows = json.loads((tmp_path / "executed_cut.json").read_text())
        assert [r["plant"] for r in rows] == ["prototype_plant"] * 4 + ["offsets at zero"] * 4
        assert [(r["tracking"], r["repeat"]) for r in rows[:4]] == [
            ("none", 0),
            ("none", 1),
            ("lead", 0),
            ("lead", 1),
        ]
        for first, again in zip(rows[::2], rows[1::2], strict=True):  # the simulated robot
            assert again["worst_share_of_limit"] == first["worst_share_of_limit"]  # repeats
            assert again["true_deviation_mm"] == first["true_deviation_mm"]  # a run exactly
        assert "Each run made 2 times" in (tmp_path / "executed_cut.md").read_text()
        none, lead = rows[0], rows[2]
        assert lead["completed"] and lead["tracking"] == "lead" and none["tracking"] == "none"
        assert lead["true_tracking_error_deg"] < 0.2 * none["true_tracking_error_deg"]
        assert (tmp_path / "executed_cut.png").is_file()
    if command[0] == "feed_hold.py":
        rows = json.loads((tmp_path / "feed_hold.json").read_text())
        assert len(rows) == 2 and all(row["completed"] for row in rows)
        assert all(0.0 < row["goal_stop_mm"] < 1.0 for row in rows)
        # led goals: the tool stops where the reference does (measured 0.0005 and 0.0016 mm
        # apart; unled, the tool overran it by its lag)
        assert all(abs(row["tool_stop_mm"] - row["goal_stop_mm"]) < 0.01 for row in rows)


def test_the_summary_says_which_plans_share_a_duration(paper_problem):
    """cubic and a copy of it share 40 s; toppra's time-optimal plan is shorter."""
    from spm_opt.studies.comparison import Outcome, comparison_markdown

    cubic = so.plan(paper_problem, "cubic")
    toppra = so.plan(paper_problem, "toppra")
    outcomes = [
        Outcome("cubic", 0.0, cubic, so.evaluate(paper_problem, cubic)),
        Outcome("again", 0.0, cubic, so.evaluate(paper_problem, cubic)),
        Outcome("toppra", 0.0, toppra, so.evaluate(paper_problem, toppra)),
    ]
    text = comparison_markdown(paper_problem, outcomes)
    assert "Plans that share a duration" in text
    assert "cubic, again (40.00 s)" in text
    assert "toppra (" not in text


def test_the_summary_names_the_plans_tube_and_the_executed_cuts(paper_problem):
    """A plan is judged against the contour tolerance less the execution reserve, an
    executed cut against the whole: the limits and cubic's contour violation say which."""
    from spm_opt.judge.limits import contour_tube
    from spm_opt.studies.comparison import comparison_markdown, run_planner

    whole = contour_tube(paper_problem, executed=True) / MM
    plan = contour_tube(paper_problem) / MM
    kept = paper_problem.limits.execution_reserve / MM
    assert kept > 0.0
    text = comparison_markdown(paper_problem, [run_planner(paper_problem, "cubic")])
    (limit,) = [line for line in text.splitlines() if line.startswith("- contour tolerance:")]
    assert f"plan's tube {plan:.4g} mm ({whole:.4g} mm less {kept:.4g} mm kept for execution)" in (
        limit
    )
    assert f"executed cut's tube {whole:.4g} mm" in limit
    violations = text.split("## Violations and failures")[1]
    assert (
        f"(limit {plan:.4g} mm: the plan's tube, {whole:.4g} mm less {kept:.4g} mm kept for "
        "execution)" in violations
    )


def test_without_a_reserve_the_summary_names_one_tube(paper_problem):
    from spm_opt.studies.comparison import comparison_markdown, run_planner

    limits = dataclasses.replace(paper_problem.limits, execution_reserve=0.0)
    problem = dataclasses.replace(paper_problem, limits=limits)
    text = comparison_markdown(problem, [run_planner(problem, "cubic")])
    whole = problem.limits.contour_tolerance / MM
    assert f"- contour tolerance: {whole:.4g} mm — tube {whole:.4g} mm (a plan's and" in text
    assert "plan's tube" not in text and f"(limit {whole:.4g} mm)" in text


def test_a_violation_names_the_plans_tube_only_when_it_keeps_a_reserve():
    plain = so.Violation("contour deviation", 0.116, 0.07, "mm", 5.064, "contour deviation")
    assert str(plain) == "contour deviation: 0.116 mm at t = 5.064 s (limit 0.07 mm)"
    named = dataclasses.replace(plain, reserve=0.03)
    assert str(named) == (
        "contour deviation: 0.116 mm at t = 5.064 s "
        "(limit 0.07 mm: the plan's tube, 0.1 mm less 0.03 mm kept for execution)"
    )
