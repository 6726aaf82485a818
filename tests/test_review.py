"""The 3-D review page (spm_opt.report.review_page), its PNG (review_png), the robot drawn at
joint angles (robot_geometry) and the ``spm-opt review`` command."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import trimesh
from conftest import HARDWARE_PROBLEM, PAPER_PROBLEM
from test_bad_inputs import assert_one_error, run_cli

import spm_opt as so
from spm_opt.execution.log import COLUMNS, header_path
from spm_opt.judge.evaluate import evaluate
from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.problem.provenance import check_run_of
from spm_opt.report.review_inputs import ReviewInputs, review_inputs
from spm_opt.report.review_page import ASIDE_WIDTH, review_page
from spm_opt.report.review_png import review_png
from spm_opt.report.review_scene import (
    MAX_SKULL_FACES,
    SKULL_REACH,
    decimate,
    executed_angles,
    review_scene,
)
from spm_opt.report.robot_geometry import TOOL_OVERHANG, robot_pose
from spm_opt.skull.surface import Skull
from spm_opt.verify.executed_cut import MEASURED, read_log_checked

SKULL_RADIUS = 0.07
"""The test skull: a sphere of 70 mm about the isocenter, m."""


class _Sphere:
    """A skull surface of :data:`SKULL_RADIUS` in every direction."""

    def radius(self, directions: np.ndarray) -> np.ndarray:
        return np.full(len(np.atleast_2d(directions)), SKULL_RADIUS)

    def radius_gradient(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = np.atleast_2d(directions)
        return self.radius(p), np.zeros_like(p)


@pytest.fixture(scope="module")
def sphere() -> Skull:
    return Skull(surface=_Sphere())


@pytest.fixture(scope="module")
def page(paper_problem: so.Problem, sphere: Skull, baseline: so.Trajectory) -> str:
    return review_page(paper_problem, sphere, ReviewInputs(baseline))


def _log_table(trajectory: so.Trajectory, offset_rad: float = 0.002) -> dict[str, np.ndarray]:
    """An execution log's columns for a run that measures the plan ``offset_rad`` off, after
    an approach row and with one failed read (every measured value empty)."""
    t = np.linspace(trajectory.start_time, trajectory.end_time, 801)
    q = trajectory.position(t) + offset_rad
    columns: dict[str, np.ndarray] = {name: np.zeros(len(t) + 1) for name in COLUMNS}
    columns["time_s"] = np.concatenate([[-0.01], t])
    columns["phase"] = np.array(["approach", *["plan"] * len(t)], dtype=object)
    for joint in (0, 1):
        columns[f"position_theta{joint + 1}_rad"] = np.concatenate([[0.0], q[:, joint]])
    for name in MEASURED:
        columns[name][5] = np.nan  # a failed read
    return columns


def test_the_page_is_one_offline_file_with_the_landmarks_and_the_headline_figures(
    paper_problem: so.Problem, baseline: so.Trajectory, page: str
) -> None:
    assert page.startswith("<!DOCTYPE html>")
    assert not re.search(r"<script[^>]*\bsrc=", page), "a script loaded from elsewhere"
    assert "plotly.js" in page and len(page) > 3e6  # the library inlined
    assert "Plotly.addFrames" in page  # the robot over the plan
    for name in paper_problem.landmark_names:
        assert f'"{name}"' in page
    report = evaluate(paper_problem, baseline)
    for figure in (
        f"{report.duration_s:.2f} s",
        f"{report.max_contour_deviation_mm:.3f} mm",
        f"{report.max_tool_speed_mm_s:.2f} mm/s",
        f"<td>{len(report.violations)}</td>",
    ):
        assert figure in page, figure


def test_the_scene_maps_joint_angles_to_cut_points_on_the_skull(
    paper_problem: so.Problem, sphere: Skull, baseline: so.Trajectory
) -> None:
    log = _log_table(baseline)
    scene = review_scene(paper_problem, sphere, baseline, pd.DataFrame(log))
    planned = scene.planned
    assert np.allclose(np.linalg.norm(planned.points, axis=1), SKULL_RADIUS / MM)
    p = kinematics.forward_kinematics(baseline.position(planned.t[[0, -1]]), 1.0)
    assert np.allclose(planned.points[[0, -1]], SKULL_RADIUS * p / MM)
    report = evaluate(paper_problem, baseline)
    assert np.max(planned.deviation) == pytest.approx(report.max_contour_deviation_mm, rel=0.02)
    executed = scene.executed
    assert executed is not None and executed.t[0] >= baseline.start_time  # no approach row
    assert len(executed.t) == 800 and np.all(np.isfinite(executed.points))  # no failed read
    assert np.max(executed.deviation) > np.max(planned.deviation) - 1.0
    # the skull is drawn just inside the sphere, around the flap
    radii = np.linalg.norm(scene.skull_vertices, axis=1)
    assert np.all((radii < SKULL_RADIUS / MM) & (radii > SKULL_RADIUS / MM - 1.0))


def test_a_log_without_plan_rows_is_refused(baseline: so.Trajectory) -> None:
    log = _log_table(baseline)
    log["phase"][:] = "approach"
    with pytest.raises(so.InputError, match="no plan rows"):
        executed_angles(pd.DataFrame(log))


def test_a_mesh_skull_is_cut_to_the_flap_and_decimated(
    paper_problem: so.Problem, baseline: so.Trajectory
) -> None:
    mesh = trimesh.creation.icosphere(subdivisions=6, radius=SKULL_RADIUS)  # 81,920 faces
    scene = review_scene(paper_problem, Skull(surface=_Sphere(), outer_mesh=mesh), baseline)
    assert 1000 < len(scene.skull_faces) <= MAX_SKULL_FACES
    centroids = scene.skull_vertices[scene.skull_faces].mean(axis=1)
    cosine = centroids @ scene.flap_direction / np.linalg.norm(centroids, axis=1)
    assert np.min(cosine) > np.cos(SKULL_REACH + np.radians(3.0))
    vertices, faces = decimate(np.asarray(mesh.vertices), np.asarray(mesh.faces), 5000)
    assert 1000 < len(faces) <= 5000
    assert np.allclose(np.linalg.norm(vertices[np.unique(faces)], axis=1), SKULL_RADIUS, rtol=0.02)


def test_the_robot_is_drawn_on_its_arcs_at_the_joint_angles(paper_problem: so.Problem) -> None:
    robot = paper_problem.robot
    q = np.radians([12.0, -20.0])
    pose = robot_pose(robot, q)
    n_upper, n_lower = (np.array(n) for n in kinematics.arc_normals(*q))
    b = kinematics.forward_kinematics(q[None, :], 1.0)[0]
    for arc, normal, radius in (
        (pose.upper_arc, n_upper, robot.upper_arc.rail_radius),
        (pose.lower_arc, n_lower, robot.lower_arc.rail_radius),
    ):
        assert np.allclose(np.linalg.norm(arc, axis=1), radius)
        assert np.allclose(arc @ normal, 0.0, atol=1e-12)
        assert np.all(arc[:, 2] >= -1e-12)  # over the top
        assert np.min(np.linalg.norm(arc - radius * b, axis=1)) < radius * np.pi / 60
    for platform, radius in (
        (pose.upper_platform, robot.upper_platform_radius),
        (pose.lower_platform, robot.lower_platform_radius),
    ):
        assert np.allclose(platform[:-1].mean(axis=0), radius * b)
        assert np.allclose((platform - radius * b) @ b, 0.0, atol=1e-12)
    assert np.allclose(pose.tool[1], (robot.upper_platform_radius + TOOL_OVERHANG) * b)


def test_the_png_is_a_picture_of_sensible_size(
    paper_problem: so.Problem, sphere: Skull, baseline: so.Trajectory, tmp_path: Path
) -> None:
    from matplotlib.image import imread

    log = _log_file(_plan_file(baseline, tmp_path), tmp_path, paper_problem)
    given = review_inputs(paper_problem, tmp_path / "cubic.csv", log)
    data = review_png(paper_problem, sphere, given)
    assert data.startswith(b"\x89PNG\r\n\x1a\n") and 50_000 < len(data) < 3_000_000
    (tmp_path / "review.png").write_bytes(data)
    height, width, _ = imread(tmp_path / "review.png").shape
    assert 1000 < width < 3000 and 500 < height < 2000


def _plan_file(trajectory: so.Trajectory, folder: Path) -> Path:
    path = folder / "cubic.csv"
    trajectory.to_csv(path)
    return path


def _log_file(plan: Path, folder: Path, problem: so.Problem, header: dict | None = None) -> Path:
    """A log of the plan at ``plan`` (its CSV) run under ``problem``, with the header
    execute writes (the plan's metadata, its duration, the problem's record), updated by
    ``header``."""
    trajectory = so.Trajectory.from_csv(plan)
    log = folder / "run.csv"
    pd.DataFrame(_log_table(trajectory)).to_csv(log, index=False)
    written = {
        "plan": trajectory.metadata,
        "plan_duration_s": trajectory.duration,
        "problem": problem.record(),
        "settings": {"rate_hz": 100.0},
        **(header or {}),
    }
    header_path(log).write_text(json.dumps(written), encoding="utf-8")
    return log


def test_the_command_writes_the_page_and_the_png(
    paper_problem: so.Problem,
    baseline: so.Trajectory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    plan = _plan_file(baseline, tmp_path)
    log = _log_file(plan, tmp_path, paper_problem)
    out = tmp_path / "review"
    status, shown = run_cli(
        ["review", str(PAPER_PROBLEM), str(plan), "--log", str(log), "--out", str(out)]
    )
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert captured.err == "" and not shown
    assert sorted(p.name for p in out.iterdir()) == ["review.html", "review.png"]
    assert captured.out.split() == [str(out / "review.html"), str(out / "review.png")]
    assert "executed cut (measured)" in (out / "review.html").read_text(encoding="utf-8")


@pytest.mark.parametrize("fault", ["missing plan", "out is a file", "missing log"])
def test_the_command_refuses_bad_input_and_writes_nothing(
    fault: str,
    paper_problem: so.Problem,
    baseline: so.Trajectory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    plan = _plan_file(baseline, tmp_path)
    out = tmp_path / "review"
    argv = ["review", str(PAPER_PROBLEM), str(plan), "--out", str(out)]
    expected: tuple[str, ...] = ()
    if fault == "missing plan":
        argv[2], expected = str(tmp_path / "none.csv"), ("none.csv",)
    elif fault == "out is a file":
        out.write_text("a file", encoding="utf-8")
        expected = ("--out", "is a file")
    else:
        argv += ["--log", str(tmp_path / "none_log.csv")]
        expected = ("none_log.csv", "no such file")
    before = sorted(tmp_path.rglob("*"))
    status, shown = run_cli(argv)
    assert_one_error(status, capsys.readouterr().err, expected, tmp_path, shown)
    assert sorted(tmp_path.rglob("*")) == before  # nothing written


def _refusals(
    paper: so.Problem, hardware: so.Problem, folder: Path
) -> dict[str, tuple[list[str], str]]:
    """Per case, the review's arguments and the one line it must print: a plan or a log
    made for another problem, a log of another plan, a log without its header."""
    plan = _plan_file(so.plan(paper, "cubic"), folder)
    other_plan = folder / "other.csv"
    so.Trajectory.from_csv(plan).to_csv(other_plan, rate_hz=50.0)  # the same cut, resampled
    ran = so.Trajectory.from_csv(other_plan)
    paper_id, hardware_id = paper.fingerprint[:12], hardware.fingerprint[:12]
    cases = {}
    log = _log_file(plan, folder / "hardware", hardware)
    cases["log of another problem"] = (
        [str(PAPER_PROBLEM), str(plan), "--log", str(log)],
        f"log {log} refused: it ran under craniotomy_hardware (fingerprint {hardware_id}), "
        f"not under craniotomy_bone_flap ({paper_id}): their landmarks, limits or robot "
        "differ; review it under the problem it ran under, or allow it with --other-problem",
    )
    log = _log_file(other_plan, folder / "other", paper)
    cases["log of another plan"] = (
        [str(PAPER_PROBLEM), str(plan), "--log", str(log), "--other-problem"],
        f"log {log} refused: it is a run of another plan than {plan} (a cubic plan whose "
        f"CSV's SHA-256 is {ran.metadata['samples']['sha256'][:12]}, not "
        f"{so.Trajectory.from_csv(plan).metadata['samples']['sha256'][:12]}); give the plan "
        "it ran",
    )
    cases["plan of another problem"] = (
        [str(HARDWARE_PROBLEM), str(plan)],
        f"plan {plan} refused: the plan was made for craniotomy_bone_flap (fingerprint "
        f"{paper_id}), not for craniotomy_hardware ({hardware_id}): their landmarks, limits "
        "or robot differ; plan it again for this problem, or allow it with --other-problem",
    )
    log = _log_file(plan, folder / "headless", paper)
    header_path(log).unlink()
    cases["log without its header"] = (
        [str(PAPER_PROBLEM), str(plan), "--log", str(log), "--other-problem"],
        f"log {log}: no header run.json beside it (spm-opt execute writes the two together)",
    )
    return cases


@pytest.mark.parametrize(
    "case",
    [
        "log of another problem",
        "log of another plan",
        "plan of another problem",
        "log without its header",
    ],
)
def test_the_command_refuses_what_was_made_for_another_problem_or_plan(
    case: str,
    paper_problem: so.Problem,
    hardware_problem: so.Problem,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """As evaluate and execute refuse them: one line naming the file and what it was
    made for, exit status 2, nothing written (--other-problem lets through only what
    another problem made)."""
    for folder in ("hardware", "other", "headless"):
        (tmp_path / folder).mkdir()
    argv, line = _refusals(paper_problem, hardware_problem, tmp_path)[case]
    out = tmp_path / "review"
    before = sorted(tmp_path.rglob("*"))
    status, shown = run_cli(["review", *argv, "--out", str(out)])
    err = capsys.readouterr().err
    assert_one_error(status, err, (), tmp_path, shown)
    assert err.strip() == f"spm-opt: error: {line}"
    assert sorted(tmp_path.rglob("*")) == before  # nothing written


def test_a_plan_of_another_problem_is_drawn_on_request_with_a_warning(
    baseline: so.Trajectory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plan = _plan_file(baseline, tmp_path)
    out = tmp_path / "review"
    argv = ["review", str(HARDWARE_PROBLEM), str(plan), "--out", str(out), "--other-problem"]
    status, shown = run_cli(argv)
    err = capsys.readouterr().err
    assert status == 0 and not shown, err
    warning = f"plan {plan}: the plan was made for craniotomy_bone_flap (fingerprint "
    assert err.startswith(f"spm-opt: warning: {warning}") and len(err.splitlines()) == 1
    page = (out / "review.html").read_text(encoding="utf-8")
    assert f'<p class="warning">Warning: {warning}' in page
    assert "reviewed under craniotomy_hardware's limits.</p>" in page


def test_a_run_on_the_simulated_robot_is_reviewed_with_its_plan_only(
    hardware_problem: so.Problem, hardware_plan: so.Trajectory, tmp_path: Path
) -> None:
    """The header execute writes tells its plan: by its CSV's hash, else by its duration."""
    plan = tmp_path / "plan.csv"
    hardware_plan.to_csv(plan)
    read = so.Trajectory.from_csv(plan)
    backend = so.SimulatedRobot(hardware_problem.robot, start_rad=read.position(0.0))
    assert so.execute(read, backend, hardware_problem, tmp_path / "run.csv").completed
    given = review_inputs(hardware_problem, plan, tmp_path / "run.csv")
    assert given.warnings == () and len(given.log) > 1000
    _, header = read_log_checked(tmp_path / "run.csv")
    check_run_of(read, str(plan), header, "run.csv")
    unhashed = {**header, "plan": {"planner": "cubic"}}
    check_run_of(read, str(plan), unhashed, "run.csv")  # the same duration
    t, q, qd, qdd = read.samples()
    slower = 1.03125  # 16.5 s
    longer = so.Trajectory.from_samples(t * slower, q, qd / slower, qdd / slower**2)
    with pytest.raises(so.InputError, match=r"a cubic plan of 16 s, not 16\.5 s"):
        check_run_of(longer, "longer.csv", unhashed, "run.csv")


_MEASURE = """
function mul(m, v) {
  const out = [0, 0, 0, 0];
  for (let row = 0; row < 4; row++) {
    for (let k = 0; k < 4; k++) out[row] += m[k * 4 + row] * v[k];
  }
  return out;
}
function measure() {
  const gd = document.querySelector(".plotly-graph-div");
  const scene = gd && gd._fullLayout && gd._fullLayout.scene && gd._fullLayout.scene._scene;
  const camera = scene && scene.glplot && scene.glplot.cameraParams;
  if (!camera || !camera.projection) { setTimeout(measure, 200); return; }
  const scale = scene.dataScale;
  const robot = ["upper arc (θ1)", "lower arc (θ2)", "upper platform", "lower platform", "tool"];
  let reach = 0, points = 0;
  for (const trace of gd._fullData) {
    if (!robot.includes(trace.name)) continue;
    for (let i = 0; i < trace.x.length; i++) {
      const clip = mul(camera.projection, mul(camera.view, mul(camera.model,
        [trace.x[i] * scale[0], trace.y[i] * scale[1], trace.z[i] * scale[2], 1])));
      reach = Math.max(reach, Math.abs(clip[0] / clip[3]), Math.abs(clip[1] / clip[3]));
      points++;
    }
  }
  const box = (el) => {
    const r = el.getBoundingClientRect();
    return [r.left, r.top, r.right, r.bottom];
  };
  const out = {
    window: [window.innerWidth, window.innerHeight],
    plot: box(gd),
    slider: box(gd.querySelector(".slider-container")),
    labels: [...gd.querySelectorAll(".slider-label")].map(box),
    robot_points: points,
    robot_reach: reach,
  };
  const pre = document.createElement("pre");
  pre.id = "measured";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
}
setTimeout(measure, 500);
"""
"""Appended to the page for the browser: once plotly has drawn the scene, it writes into a
``<pre id="measured">`` the window's size, the plot's and the slider's boxes and each slider
label's (px), and the robot's farthest point from the view's centre in normalised device
coordinates (beyond 1: out of the picture), from the camera's own matrices."""


def _chromium(page: Path, size: tuple[int, int], folder: Path, *action: str) -> str:
    """Run headless Chromium on ``page`` at window ``size`` (px) with ``action``; stdout."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("chromium is not installed (apt-get install chromium)")
    command = [
        chromium,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--use-gl=swiftshader",
        "--enable-unsafe-swiftshader",
        "--hide-scrollbars",
        f"--user-data-dir={folder / 'profile'}",
        f"--window-size={size[0]},{size[1]}",
        "--virtual-time-budget=20000",
        *action,
        page.as_uri(),
    ]
    done = subprocess.run(command, capture_output=True, timeout=180, check=False, text=True)
    return done.stdout


@pytest.mark.slow
@pytest.mark.parametrize("size", [(1400, 900), (1400, 1600)])
def test_the_page_renders_in_headless_chromium(
    size: tuple[int, int], page: str, tmp_path: Path
) -> None:
    """The scene is drawn by WebGL on software GL (SwiftShader), right of the figures: the
    light grey skull is there; the plot fills the window's height, the whole robot is in
    the picture and the slider's labels in the window."""
    from matplotlib.image import imread

    html = tmp_path / "review.html"
    html.write_text(page.replace("</body>", f"<script>{_MEASURE}</script></body>"), "utf-8")
    shot = tmp_path / "shot.png"
    started = time.perf_counter()
    _chromium(html, size, tmp_path, f"--screenshot={shot}")
    seconds = time.perf_counter() - started
    assert shot.is_file(), f"no screenshot after {seconds:.1f} s"
    pixels = imread(shot)[..., :3]
    assert pixels.shape[:2] == (size[1], size[0])
    plot = pixels[:, int(ASIDE_WIDTH.removesuffix("px")) :].reshape(-1, 3)
    # the skull's shades of grey, darker than the light grey box plotly shows without WebGL
    darkest, lightest = plot.min(axis=1), plot.max(axis=1)
    skull = (lightest - darkest < 0.03) & (darkest > 0.6) & (lightest < 0.92)
    assert 0.005 < skull.mean() < 0.3, f"{skull.mean():.1%} skull after {seconds:.1f} s"
    dom = _chromium(html, size, tmp_path, "--dump-dom")
    found = re.search(r'<pre id="measured">(.*?)</pre>', dom)
    assert found is not None, "the page did not measure its plot"
    measured = json.loads(found.group(1))
    width, height = measured["window"]
    left, top, right, bottom = measured["plot"]
    assert bottom <= height + 1 and bottom - top >= 0.95 * height, measured["plot"]
    assert measured["robot_points"] > 100 and measured["robot_reach"] < 0.95, measured
    labels = np.array(measured["labels"])
    assert len(labels) > 5 and labels[:, 3].max() <= height and labels[:, 2].max() <= width
