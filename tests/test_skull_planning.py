"""Planning on a skull from imaging, checked without the project's surface code: the skull's
radius by ray casting the meshes with trimesh directly, and with it the plan against every
limit by the tests' own check (:mod:`plan_checks`: the cut points' speed by finite
differences, their distance from the great-circle arcs through the landmarks)."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import trimesh
from plan_checks import Radius, assert_within_limits

import spm_opt as so
from spm_opt.model import kinematics
from spm_opt.skull.example_problem import write_example_problem

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
    from spm_opt.comparison import comparison_markdown

    problem = so.load_problem(example(tmp_path, subdivisions=3, registration=True))
    summary = comparison_markdown(problem, [])
    assert f"outer mesh {len(problem.skull.outer_mesh.faces):,} triangles" in summary
    assert "image-to-robot registration: RMS error 0.000 mm" in summary
