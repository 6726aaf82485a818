"""The review page and its PNG say what the judge says: the violations in the page's
``verdict`` JSON are those ``spm-opt evaluate --json`` prints, for a plan, a clean run and
a violating run, each built and judged through the command line; the violations are
marked on the cut, and each cut is judged in its own tube."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import HARDWARE_PROBLEM, PAPER_PROBLEM, ROOT
from test_bad_inputs import run_cli

import spm_opt as so
from spm_opt.judge.evaluate import evaluate
from spm_opt.judge.limits import contour_tube
from spm_opt.judge.report import Violation
from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.report.review_figure import review_figure
from spm_opt.report.review_inputs import review_inputs
from spm_opt.report.review_png import MAX_LISTED, review_png_figure
from spm_opt.report.review_scene import review_scene
from spm_opt.report.review_verdict import judged_cuts, verdict_line
from spm_opt.skull.surface import Skull

PLANT = ROOT / "problems" / "robots" / "prototype_plant.toml"

_VERDICT = re.compile(r'<script type="application/json" id="verdict">\n(.*?)\n</script>', re.DOTALL)


def _cli_json(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, dict]:
    """``spm-opt evaluate --json``'s exit status and what it prints."""
    capsys.readouterr()
    status, _ = run_cli(["evaluate", *argv, "--json"])
    return status, json.loads(capsys.readouterr().out)


def _page_verdict(argv: list[str], out: Path, capsys: pytest.CaptureFixture[str]) -> dict:
    """The verdict in the page ``spm-opt review ARGV --out OUT`` writes."""
    status, _ = run_cli(["review", *argv, "--out", str(out)])
    assert status == 0, capsys.readouterr().err
    page = (out / "review.html").read_text(encoding="utf-8")
    match = _VERDICT.search(page)
    assert match is not None, "no verdict in the page"
    return json.loads(match.group(1))


def _sim_run(problem: so.Problem, plan: Path, log: Path, plant: Path | None = None) -> None:
    """``spm-opt execute PLAN --backend sim`` under ``problem``'s file (on ``plant``)."""
    source = PAPER_PROBLEM if problem.name == "craniotomy_bone_flap" else HARDWARE_PROBLEM
    argv = ["execute", str(plan), "--problem", str(source), "--backend", "sim", "--log", str(log)]
    argv += [] if plant is None else ["--plant-robot", str(plant), "--trace", str(log) + ".npz"]
    status, _ = run_cli(argv)
    assert status == 0


def _jolted(log: Path, into: Path) -> Path:
    """A copy of the log (header and all) whose encoders record a jolt of θ1 over 0.2 s
    early in the plan: a raised cosine of 0.03 rad in position, its rate in velocity."""
    table = pd.read_csv(log, keep_default_na=False, dtype=str)
    t = pd.to_numeric(table["time_s"]).to_numpy()
    start = t[np.flatnonzero(table["phase"].to_numpy() == "plan")[0]] + 1.0
    phase = np.clip((t - start) / 0.2, 0.0, 1.0)
    for column, bump in (
        ("position_theta1_rad", 0.015 * (1.0 - np.cos(2.0 * np.pi * phase))),
        ("velocity_theta1_rad_s", 0.015 * 2.0 * np.pi / 0.2 * np.sin(2.0 * np.pi * phase)),
    ):
        values = pd.to_numeric(table[column], errors="coerce").to_numpy()
        table[column] = [f"{v:.12g}" if np.isfinite(v) else "" for v in values + bump]
    table.to_csv(into, index=False)
    into.with_suffix(".json").write_text(log.with_suffix(".json").read_text(encoding="utf-8"))
    return into


@pytest.fixture(scope="module")
def hardware_files(
    hardware_problem: so.Problem,
    hardware_plan: so.Trajectory,
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, Path]:
    """The hardware problem's cubic plan, and a log of it run on the simulated robot."""
    folder = tmp_path_factory.mktemp("hardware")
    plan = folder / "plan.csv"
    hardware_plan.to_csv(plan)
    _sim_run(hardware_problem, plan, folder / "run.csv")
    return plan, folder / "run.csv"


def test_a_plans_verdict_is_the_judges(
    baseline: so.Trajectory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The paper's cubic plan breaks the acceleration step: the page lists what evaluate
    lists, and judges no run."""
    plan = tmp_path / "cubic.csv"
    baseline.to_csv(plan)
    status, judged = _cli_json([str(PAPER_PROBLEM), str(plan)], capsys)
    assert status == 1 and judged["violations"]
    out = tmp_path / "review"
    verdict = _page_verdict([str(PAPER_PROBLEM), str(plan)], out, capsys)
    assert verdict["plan"] == judged["violations"]
    assert verdict["run"] is None and verdict["run_true"] is None
    page = (out / "review.html").read_text(encoding="utf-8")
    tube = contour_tube(so.load_problem(PAPER_PROBLEM)) / MM
    assert html.escape(f"The planned cut, judged in ±{tube:.3f} mm (the plan's tube): ") in page


def test_a_clean_runs_verdict_and_figures_are_the_judges(
    hardware_files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plan, log = hardware_files
    status, judged = _cli_json([str(HARDWARE_PROBLEM), str(log)], capsys)
    assert status == 0 and judged["violations"] == []
    _, planned = _cli_json([str(HARDWARE_PROBLEM), str(plan)], capsys)
    out = tmp_path / "review"
    verdict = _page_verdict([str(HARDWARE_PROBLEM), str(plan), "--log", str(log)], out, capsys)
    assert verdict == {
        "plan": planned["violations"],
        "predicted": None,
        "run": [],
        "run_true": None,
    }
    page = (out / "review.html").read_text(encoding="utf-8")
    # the executed cut's figures are the judge's of the log, not the plan's
    for report in (planned, judged):
        assert f"<td>{report['max_contour_deviation_mm']:.3f} mm</td>" in page
        assert f"<td>{report['max_tool_speed_mm_s']:.2f} mm/s</td>" in page
    assert "The executed cut (measured), judged in none set: no limit is violated." in page


def test_a_violating_runs_verdict_is_the_judges_and_its_violations_are_marked(
    hardware_problem: so.Problem,
    hardware_files: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A run whose encoders record a jolt: evaluate rejects it, and the page says so, lists
    the violations and marks each on the executed cut at its time; so does the PNG."""
    plan, clean = hardware_files
    log = _jolted(clean, tmp_path / "jolted.csv")
    status, judged = _cli_json([str(HARDWARE_PROBLEM), str(log)], capsys)
    rules = {v["rule"] for v in judged["violations"]}
    assert status == 1 and {"joint acceleration", "joint jerk"} <= rules
    out = tmp_path / "review"
    verdict = _page_verdict([str(HARDWARE_PROBLEM), str(plan), "--log", str(log)], out, capsys)
    assert verdict["run"] == judged["violations"]
    page = (out / "review.html").read_text(encoding="utf-8")
    count = len(judged["violations"])
    assert f"judged in none set: {count} violation(s).</p>" in page
    for violation in judged["violations"]:
        assert f"<li>{Violation(**violation)}</li>" in page
    _assert_marked(hardware_problem, plan, log, judged["violations"])


def _assert_marked(problem: so.Problem, plan: Path, log: Path, violations: list[dict]) -> None:
    """The page's plot has a marker at each violation, where the log's measured angles put
    the cut at its time, its hover text the violation's; the PNG numbers and lists them."""
    given = review_inputs(problem, plan, log)
    cuts = judged_cuts(problem, evaluate(problem, given.trajectory), given.run)
    scene = review_scene(problem, Skull(surface=problem.surface), given.trajectory, given.log)
    figure = review_figure(problem, scene, given.trajectory, cuts)
    name = f"executed cut (measured): {len(violations)} violation(s)"
    (markers,) = [trace for trace in figure.data if trace.name == name]
    assert list(markers.text) == [str(Violation(**v)) for v in violations]
    table = given.log[given.log["phase"] != "approach"]
    times = pd.to_numeric(table["time_s"]).to_numpy()
    angles = table[["position_theta1_rad", "position_theta2_rad"]].astype(float).to_numpy()
    for k, violation in enumerate(violations):
        row = np.argmin(np.abs(times - violation["time_s"]))
        p = kinematics.forward_kinematics(angles[row : row + 1], 1.0)[0]
        expected = problem.surface.radius(p[None, :])[0] * p / MM
        drawn = np.array([markers.x[k], markers.y[k], markers.z[k]])
        assert np.linalg.norm(drawn - expected) < 0.01, violation
    png = review_png_figure(problem, scene, given.trajectory, cuts)
    texts = [text.get_text() for axis in png.axes for text in axis.texts]
    assert all(verdict_line(cut) in texts for cut in cuts)
    listed = min(len(violations), MAX_LISTED)
    assert [
        f"{k}. executed cut (measured): {Violation(**violations[k - 1])}" in texts
        for k in range(1, listed + 1)
    ] == [True] * listed


@pytest.mark.slow
def test_a_run_on_another_plant_is_judged_measured_and_true_in_the_executed_tube(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The paper's toppra plan run on the prototype's plant breaks the acceleration, jerk
    and tool-speed limits (about 25 s): the page gives evaluate's verdicts of the measured
    and the true cut, the plan judged in the plan's tube and the run in the whole
    tolerance."""
    problem = so.load_problem(PAPER_PROBLEM)
    plan, log = tmp_path / "toppra.csv", tmp_path / "run.csv"
    so.plan(problem, "toppra").to_csv(plan)
    _sim_run(problem, plan, log, PLANT)
    trace = ["--trace", str(log) + ".npz"]
    status, judged = _cli_json([str(PAPER_PROBLEM), str(log), *trace], capsys)
    assert status == 1 and judged["measured"]["violations"] and judged["true"]["violations"]
    out = tmp_path / "review"
    argv = [str(PAPER_PROBLEM), str(plan), "--log", str(log), *trace]
    verdict = _page_verdict(argv, out, capsys)
    assert verdict["run"] == judged["measured"]["violations"]
    assert verdict["run_true"] == judged["true"]["violations"]
    page = (out / "review.html").read_text(encoding="utf-8")
    planned, executed = contour_tube(problem) / MM, contour_tube(problem, executed=True) / MM
    assert planned < executed
    assert f"<td>±{planned:.3f} mm (the plan&#x27;s tube)</td>" in page
    assert f"<td>±{executed:.3f} mm (an executed cut&#x27;s tube)</td>" in page


def test_the_predicted_cuts_verdict_is_what_predict_says(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``review --predict ROBOT`` draws the plan's cut predicted on that robot's closed-loop
    model and lists what ``spm-opt predict --json`` finds (the same model and settings),
    its violations marked on the predicted cut."""
    problem = so.load_problem(PAPER_PROBLEM)
    plan = tmp_path / "toppra.csv"
    so.plan(problem, "toppra").to_csv(plan)
    capsys.readouterr()
    status, _ = run_cli(
        ["predict", str(plan), "--problem", str(PAPER_PROBLEM), "--robot", str(PLANT), "--json"]
    )
    predicted = json.loads(capsys.readouterr().out)
    assert status == 1 and predicted["violations"]  # the plant's stick-slip at the stops
    out = tmp_path / "review"
    verdict = _page_verdict([str(PAPER_PROBLEM), str(plan), "--predict", str(PLANT)], out, capsys)
    assert verdict["predicted"] == predicted["violations"]
    assert verdict["run"] is None and verdict["run_true"] is None
    page = (out / "review.html").read_text(encoding="utf-8")
    tube = contour_tube(problem, executed=True) / MM
    said = (
        f"The predicted cut (on prototype_plant), judged in ±{tube:.3f} mm (an executed cut's tube)"
    )
    assert html.escape(said) in page
    assert f"<td>{predicted['max_contour_deviation_mm']:.3f} mm</td>" in page
    assert "predicted cut (before the run)" in page
