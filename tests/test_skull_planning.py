"""Planning on a skull from imaging, checked without the project's surface code: the skull's
radius by ray casting the meshes with trimesh directly, and with it the plan against every
limit by the tests' own check (:mod:`plan_checks`: the cut points' speed by finite
differences, their distance from the great-circle arcs through the landmarks)."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path

import hypothesis
import numpy as np
import pytest
import tomli_w
import trimesh
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from plan_checks import Radius, assert_within_limits
from test_bad_inputs import assert_nothing_written, assert_one_error, run_cli

import spm_opt as so
from spm_opt.model import kinematics
from spm_opt.model.rigid import apply
from spm_opt.skull.example_problem import write_example_problem
from spm_opt.skull.markups import read_markups, write_markups

ROOT = Path(__file__).resolve().parents[1]
ROBOT = str(ROOT / "problems" / "robots" / "prototype.toml")
PLANNERS = ("toppra", "ocp-min-time", "ocp-min-energy", "ocp-min-jerk")


def example(folder: Path, **options) -> Path:
    return write_example_problem(folder / "skull_flap.toml", robot=ROBOT, **options)


def meshes_in_robot_frame(problem_path: Path) -> trimesh.Trimesh:
    """The outer mesh in the robot's frame, m, read with trimesh from the file's keys."""
    data = tomllib.loads(problem_path.read_text())
    skull = data["skull"]
    mesh = trimesh.load(problem_path.parent / skull["outer_mesh"], force="mesh")
    flip = np.diag([-1.0, -1.0, 1.0, 1.0]) if skull["frame"] == "LPS" else np.eye(4)
    if "image_to_robot" in skull:
        matrix = np.array(skull["image_to_robot"])
    else:  # the fiducials' transform, fitted here with trimesh's own rigid registration
        fiducials = skull["registration"]
        image = np.array(fiducials["image_fiducials_mm"]) * np.diag(flip)[:3]
        matrix, _, _ = trimesh.registration.procrustes(
            image, np.array(fiducials["robot_fiducials_mm"]), reflection=False, scale=False
        )
    mesh.apply_transform(np.diag([1e-3, 1e-3, 1e-3, 1.0]) @ matrix @ flip)
    return mesh


def ray_cast(mesh: trimesh.Trimesh, directions: np.ndarray) -> np.ndarray:
    """Where rays from the origin along unit directions (N, 3) meet the mesh: points, m."""
    locations, rays, _ = mesh.ray.intersects_location(
        np.zeros_like(directions), directions, multiple_hits=False
    )
    points = np.full(directions.shape, np.nan)
    points[rays] = locations
    assert np.all(np.isfinite(points)), "a ray missed the skull"
    return points


def mesh_radius(problem_path: Path) -> Radius:
    """The skull's radius, m, along unit directions (N, 3): trimesh's ray casts of the
    problem's outer mesh."""
    mesh = meshes_in_robot_frame(problem_path)
    return lambda directions: np.linalg.norm(ray_cast(mesh, directions), axis=1)


@pytest.fixture(scope="module")
def shipped() -> so.Problem:
    return so.load_problem(ROOT / "problems" / "skull_flap.toml")


def test_the_shipped_flap_moves_its_landmarks_onto_the_mesh_and_records_it(shipped):
    record = shipped.record()["skull"]
    assert record["mesh"] is True
    assert max(abs(v) for v in record["landmark_shifts_mm"].values()) < 0.05
    mesh = meshes_in_robot_frame(ROOT / "problems" / "skull_flap.toml")
    units = shipped.landmarks / np.linalg.norm(shipped.landmarks, axis=1, keepdims=True)
    np.testing.assert_allclose(ray_cast(mesh, units), shipped.landmarks, atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize(
    "variant",
    [
        {"seed": 1, "subdivisions": 5, "frame": "RAS"},
        {"seed": 0, "subdivisions": 4, "frame": "LPS"},
        {"seed": 0, "subdivisions": 6, "frame": "RAS"},
    ],
    ids=["another seed", "coarser, LPS", "finer, RAS"],
)
@pytest.mark.parametrize("planner", PLANNERS)
def test_planners_cut_clean_on_skulls_not_tuned_on(tmp_path, variant, planner):
    path = example(tmp_path, **variant)
    problem = so.load_problem(path)
    plan = so.plan(problem, planner)
    if plan.metadata["statistics"].get("transcription") == "time":
        # the radius the time-domain NLP read, against the mesh
        assert 0 < plan.metadata["statistics"]["skull_fit_error_mm"] < 0.05
    assert_within_limits(problem, plan, radius=mesh_radius(path))
    # what only the evaluator measures (a feed hold's room, coverage): toppra does not ask
    assert so.evaluate(problem, plan).violations == []


def test_a_matrix_and_its_fiducials_give_the_same_plan(tmp_path):
    plans = []
    for registration in (False, True):
        folder = tmp_path / str(registration)
        problem = so.load_problem(example(folder, subdivisions=4, registration=registration))
        plans.append(so.plan(problem, "toppra"))
        if registration:
            assert problem.record()["skull"]["registration_rms_mm"] < 1e-6
    t = np.linspace(0.0, min(p.duration for p in plans), 2000)
    assert np.max(np.abs(plans[0].position(t) - plans[1].position(t))) < 1e-6


def test_the_lps_and_ras_copies_of_one_skull_give_the_same_plan(tmp_path):
    plans = [
        so.plan(so.load_problem(example(tmp_path / frame, subdivisions=4, frame=frame)), "toppra")
        for frame in ("RAS", "LPS")
    ]
    t = np.linspace(0.0, plans[0].duration, 2000)
    assert plans[0].duration == pytest.approx(plans[1].duration, rel=1e-9)
    assert np.max(np.abs(plans[0].position(t) - plans[1].position(t))) < 1e-6


def test_the_plan_carries_the_tool_depth_over_the_inner_surface(shipped):
    plan = so.plan(shipped, "toppra")
    setpoint = plan.metadata["depth_setpoint"]
    t, depth = np.array(setpoint["t_s"]), np.array(setpoint["depth_mm"]) * 1e-3
    data = tomllib.loads((ROOT / "problems" / "skull_flap.toml").read_text())
    inner = trimesh.load(ROOT / "problems" / data["skull"]["inner_mesh"], force="mesh")
    inner.apply_transform(
        np.diag([1e-3, 1e-3, 1e-3, 1]) @ np.array(data["skull"]["image_to_robot"])
    )
    directions = kinematics.forward_kinematics(plan.position(t), 1.0)
    expected = np.linalg.norm(ray_cast(inner, directions), axis=1) + 0.5e-3
    np.testing.assert_allclose(depth, expected, atol=0.02e-3)  # the smooth fit, within 0.02 mm
    report = so.evaluate(shipped, plan)
    assert 0 < report.max_depth_speed_mm_s < 10 and np.isfinite(report.max_depth_acceleration_mm_s2)


def spm_opt_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "spm_opt.cli", *args], capture_output=True, text=True, timeout=300
    )


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


def refused(path: Path, tmp_path: Path, *fragments: str) -> None:
    out = tmp_path / "plan.csv"
    result = spm_opt_cli("plan", str(path), "--planner", "toppra", "--out", str(out))
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("spm-opt: error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    assert not out.exists()


def test_a_frame_named_wrongly_is_refused(tmp_path):
    path = example(tmp_path, subdivisions=3)
    edit(path, 'frame = "RAS"', 'frame = "ras"')
    refused(path, tmp_path, "skull.frame", "RAS", "LPS")


def test_a_mesh_whose_header_says_another_frame_is_refused(tmp_path):
    path = example(tmp_path, subdivisions=3)
    edit(path, 'frame = "RAS"', 'frame = "LPS"')
    refused(path, tmp_path, "SPACE=RAS")


def test_a_markups_file_without_points_is_refused(tmp_path):
    path = example(tmp_path, subdivisions=3)
    markups = tmp_path / "flap.mrk.json"
    data = markups.read_text()
    start = data.index('"controlPoints"')
    markups.write_text(data[:start] + '"controlPoints": [], "ignored": [' + data[start + 17 :])
    refused(path, tmp_path, "flap.mrk.json")


def test_a_markups_file_of_an_unknown_type_is_refused(tmp_path):
    path = example(tmp_path, subdivisions=3)
    edit(tmp_path / "flap.mrk.json", '"ClosedCurve"', '"Plane"')
    refused(path, tmp_path, "flap.mrk.json", "Plane")


def test_a_flap_over_bone_thinner_than_the_limit_is_refused(tmp_path):
    path = example(tmp_path, subdivisions=3)
    edit(path, "min_bone_thickness_mm = 3", "min_bone_thickness_mm = 9.5")
    refused(path, tmp_path, "min_bone_thickness_mm = 9.5", "the cut from")


def test_a_mesh_with_a_hole_under_the_cut_is_refused(tmp_path):
    path = example(tmp_path, subdivisions=4)
    problem = so.load_problem(path)
    data = tomllib.loads(path.read_text())
    outer_path = tmp_path / data["skull"]["outer_mesh"]
    mesh = trimesh.load(outer_path, force="mesh")
    matrix = np.array(data["skull"]["image_to_robot"])
    centres = trimesh.transform_points(mesh.triangles_center, matrix)
    point = problem.contour.point_at(np.array([problem.contour.length * 0.3]))[0] * 1e3
    keep = np.linalg.norm(centres - point, axis=1) > 8.0  # a hole of 8 mm about the cut
    mesh.update_faces(keep)
    header = outer_path.read_bytes()[:80]
    outer_path.write_bytes(header + mesh.export(file_type="stl")[80:])
    refused(path, tmp_path, "meets the outer surface 0 times")


def test_a_non_manifold_mesh_is_refused(tmp_path):
    path = example(tmp_path, subdivisions=3)
    data = tomllib.loads(path.read_text())
    outer_path = tmp_path / data["skull"]["outer_mesh"]
    mesh = trimesh.load(outer_path, force="mesh")
    a, b = mesh.edges_unique[0]
    fins = [mesh.vertices[a], mesh.vertices[b], mesh.vertices[a] * 1.1 + 1.0]
    fins += [mesh.vertices[a], mesh.vertices[b], mesh.vertices[b] * 1.1 - 1.0]
    extra = trimesh.Trimesh(np.array(fins), np.arange(6).reshape(2, 3), process=False)
    broken = trimesh.util.concatenate([mesh, extra])
    header = outer_path.read_bytes()[:80]
    outer_path.write_bytes(header + broken.export(file_type="stl")[80:])
    refused(path, tmp_path, "skull.outer_mesh", "non-manifold")


def test_the_comparison_names_the_skull_and_its_registration(tmp_path):
    from spm_opt.studies.comparison import comparison_markdown

    problem = so.load_problem(example(tmp_path, subdivisions=3, registration=True))
    summary = comparison_markdown(problem, [])
    assert f"outer mesh {len(problem.skull.outer_mesh.faces):,} triangles" in summary
    assert "image-to-robot registration: RMS error 0.000 mm" in summary
    assert "(each fiducial's residual: 0.000, 0.000, 0.000, 0.000 mm)" in summary


# --- what registration and the markups must be -----------------------------------------


def plan_refused(path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> str:
    """``spm-opt plan`` of the problem at ``path``, in this process: exit status 2, one
    line, no plan written; returns the line after ``spm-opt: error: ``."""
    out = tmp_path / "out" / "plan.csv"
    status, shown = run_cli(["plan", str(path), "--planner", "cubic", "--out", str(out)])
    err = capsys.readouterr().err
    assert_one_error(status, err, (), tmp_path, shown)
    assert_nothing_written(out, tmp_path)
    return err.strip().removeprefix("spm-opt: error: ")


def rewrite(path: Path, edit: Callable[[dict], None]) -> None:
    """Edit the problem file at ``path`` as TOML."""
    data = tomllib.loads(path.read_text())
    edit(data)
    path.write_text(tomli_w.dumps(data))


@pytest.fixture(scope="module")
def markups_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("markups")


@settings(max_examples=12, deadline=None)
@given(point=st.integers(0, 4), factor=st.floats(0.85, 5.0))
@hypothesis.example(point=0, factor=1.02)  # within the bound
@hypothesis.example(point=3, factor=0.97)
@hypothesis.example(point=2, factor=5.0)  # five times farther out than the skull
@hypothesis.example(point=1, factor=0.9)  # inside
def test_a_markups_point_far_from_the_mesh_is_refused_naming_it(markups_folder, point, factor):
    """One markups point moved along its direction from the isocenter (to between 0.85 and
    5 times its distance): refused exactly when it lies more than max_landmark_shift_mm
    (5 mm) from the outer mesh along that direction, as trimesh's ray cast measures it."""
    folder = markups_folder / f"{point}_{factor:.6f}"
    path = example(folder, subdivisions=3)
    matrix = np.array(tomllib.loads(path.read_text())["skull"]["image_to_robot"])
    markups = read_markups(folder / "flap.mrk.json")
    robot_mm = apply(matrix, markups.points_ras_mm)
    robot_mm[point] *= factor
    image_mm = apply(np.linalg.inv(matrix), robot_mm)
    write_markups(folder / "flap.mrk.json", markups.labels, image_mm, "RAS", markups.closed)
    direction = robot_mm[point] / np.linalg.norm(robot_mm[point])
    on_mesh = ray_cast(meshes_in_robot_frame(path), direction[None])[0] / 1e-3
    shift = np.linalg.norm(on_mesh) - np.linalg.norm(robot_mm[point])  # mm, + inwards
    assume(abs(abs(shift) - 5.0) > 1e-6 and abs((abs(shift) * 10) % 1 - 0.5) > 1e-6)
    if abs(shift) < 5.0:
        recorded = so.load_problem(path).record()["skull"]["landmark_shifts_mm"]
        assert recorded[markups.labels[point]] == pytest.approx(shift, abs=1e-6)
        return
    with pytest.raises(so.InputError) as refused:
        so.load_problem(path)
    side = "outside" if shift < 0 else "inside"
    assert str(refused.value) == (
        f"{path}: skull.max_landmark_shift_mm = 5: landmark {markups.labels[point]} of "
        f"flap.mrk.json lies {abs(shift):.1f} mm {side} the outer surface along its direction "
        "from the isocenter; expected at most 5 mm (a point of this skull, in its frame and "
        "units?)"
    )


def test_the_markups_bound_is_a_setting_and_refusing_writes_nothing(tmp_path, capsys):
    path = example(tmp_path, subdivisions=3)
    matrix = np.array(tomllib.loads(path.read_text())["skull"]["image_to_robot"])
    markups = read_markups(tmp_path / "flap.mrk.json")
    robot_mm = apply(matrix, markups.points_ras_mm)
    robot_mm[2] *= 5.0  # five times farther out than the skull
    image_mm = apply(np.linalg.inv(matrix), robot_mm)
    write_markups(tmp_path / "flap.mrk.json", markups.labels, image_mm, "RAS", markups.closed)
    line = plan_refused(path, tmp_path, capsys)
    assert line.startswith(f"{path}: skull.max_landmark_shift_mm = 5: landmark F-3 of ")
    rewrite(path, lambda data: data["skull"].update(max_landmark_shift_mm=1000.0))
    shifts = so.load_problem(path).record()["skull"]["landmark_shifts_mm"]
    assert shifts["F-3"] < -250.0


def _fiducials(path: Path) -> tuple[np.ndarray, np.ndarray]:
    registration = tomllib.loads(path.read_text())["skull"]["registration"]
    return (
        np.array(registration["image_fiducials_mm"]),
        np.array(registration["robot_fiducials_mm"]),
    )


def test_a_fiducial_20_mm_wrong_is_refused_naming_it_and_every_residual(tmp_path, capsys):
    path = example(tmp_path, subdivisions=3, registration=True)
    image, robot = _fiducials(path)
    robot[1, 0] += 20.0

    def wrong(data: dict) -> None:
        data["skull"]["registration"]["robot_fiducials_mm"] = robot.tolist()

    rewrite(path, wrong)
    matrix, _, _ = trimesh.registration.procrustes(image, robot, reflection=False, scale=False)
    residuals = np.linalg.norm(image @ matrix[:3, :3].T + matrix[:3, 3] - robot, axis=1)
    worst = int(np.argmax(residuals))
    each = ", ".join(f"{r:.2f}" for r in residuals)
    rms = np.sqrt(np.mean(residuals**2))
    assert plan_refused(path, tmp_path, capsys) == (
        f"{path}: skull.registration.max_fiducial_residual_mm = 2: fiducial {worst + 1} of 4 "
        f"has the largest residual, {residuals[worst]:.2f} mm (each: {each} mm; RMS {rms:.2f} "
        "mm); expected at most 2 mm: check where the fiducials were located in both frames "
        "(the fit spreads one's error over others)"
    )
    rewrite(path, lambda data: data["skull"]["registration"].update(max_fiducial_residual_mm=20))
    record = so.load_problem(path).record()["skull"]
    np.testing.assert_allclose(record["fiducial_residuals_mm"], residuals, atol=1e-9)
    assert record["registration_rms_mm"] == pytest.approx(rms, abs=1e-9)


def test_near_collinear_fiducials_are_named_at_registration(tmp_path, capsys):
    """0.001 mm off one line, located to 0.05 mm: named degenerate, not left to fail later
    as an isocenter outside the skull."""
    path = example(tmp_path, subdivisions=3, registration=True)
    image, robot = _fiducials(path)
    matrix, _, _ = trimesh.registration.procrustes(image, robot, reflection=False, scale=False)
    start, step = image[0], image[1] - image[0]
    line = np.array([start, start + step, start + 2 * step, start - step])
    across = np.cross(step, [0.0, 0.0, 1.0])
    line[3] += 0.001 * across / np.linalg.norm(across)
    noise = np.random.default_rng(1).normal(scale=0.05, size=line.shape)
    located = line @ matrix[:3, :3].T + matrix[:3, 3] + noise

    def collinear(data: dict) -> None:
        registration = data["skull"]["registration"]
        registration["image_fiducials_mm"] = line.tolist()
        registration["robot_fiducials_mm"] = located.tolist()

    rewrite(path, collinear)
    centred = line - line.mean(axis=0)
    singular = np.sqrt(np.sort(np.linalg.eigvalsh(centred.T @ centred))[::-1])
    assert plan_refused(path, tmp_path, capsys) == (
        f"{path}: skull.registration.image_fiducials_mm: the 4 image fiducials are "
        f"degenerate: they lie near one line (condition number {singular[0] / singular[1]:.3g}, "
        "their spread along it over their spread across it; at most 10), which leaves the "
        "rotation about it undetermined: expected at least 3 points spread well away from one "
        "line"
    )
