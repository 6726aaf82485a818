"""Problem and robot files: the shipped ones load, and a problem checks itself."""

import dataclasses
import logging
from pathlib import Path

import numpy as np
import pytest

import spm_opt as so
from spm_opt.model.params import MM
from spm_opt.problem.problem import PLAUSIBLE_CONTOUR_TOLERANCE_MM

PROBLEMS = sorted((Path(__file__).resolve().parents[1] / "problems").glob("*.toml"))


@pytest.mark.parametrize("path", PROBLEMS, ids=lambda p: p.stem)
def test_every_shipped_problem_loads_and_plans_within_its_limits(path):
    problem = so.load_problem(path)
    report = so.evaluate(problem, so.plan(problem, "cubic"))
    # the baseline plans neither the tool's speed nor the cut's distance from the contour
    # (so it leaves stretches of the contour uncut), and its cubics start and stop with a
    # step in acceleration
    planned_for = {"tool speed", "contour deviation", "coverage"}
    steps = {f"theta{joint} acceleration step" for joint in (1, 2)}
    assert {v.limit for v in report.violations} <= planned_for | steps
    assert report.max_landmark_error_mm < 1e-9


def test_paper_problem_in_si(paper_problem):
    assert paper_problem.robot.upper_platform_radius == pytest.approx(0.17133)
    assert paper_problem.limits.max_joint_speed == pytest.approx(13.7 * 2 * np.pi / 60)
    assert paper_problem.visit_names == ["A1", "A2", "A3", "A4", "A1"]
    np.testing.assert_allclose(np.linalg.norm(paper_problem.platform_points, axis=1), 0.17133)
    assert len(paper_problem.source_sha256) == 64


def test_hardware_problem_is_the_same_flap_faster(paper_problem):
    hardware = so.load_problem(PROBLEMS[0].parent / "craniotomy_hardware.toml")
    np.testing.assert_array_equal(hardware.landmarks, paper_problem.landmarks)
    assert hardware.segment_durations.sum() < paper_problem.segment_durations.sum()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"landmarks": np.array([[0, 0, 68.08], [0, 0, 68.08]]) * MM}, "same direction"),
        (
            {"landmarks": np.array([[0, 0, 0.06808], [-22.14, -11.39, 63.1]]) * MM},
            "positions are in mm",
        ),
        ({"landmarks": np.array([[0, 0, 68.08], [60.0, 0, 10.0]]) * MM}, "landmark A2: θ2"),
        ({"landmarks": np.array([[0, 0, 68.08], [60.0, 0, -1.0]]) * MM}, "isocenter plane"),
        ({"segment_durations": np.array([1.0, np.nan])}, "segment_durations_s"),
        ({"segment_durations": np.array([1.0])}, "expected 2 durations"),
    ],
)
def test_a_problem_built_in_code_checks_itself(paper_problem, change, message):
    two = {
        "landmark_names": ("A1", "A2"),
        "landmarks": paper_problem.landmarks[:2],
        "closed": True,
        "segment_durations": np.array([5.0, 5.0]),
    }
    with pytest.raises(so.InputError, match=message):
        dataclasses.replace(paper_problem, **{**two, **change})


def test_overrides_replace_values_before_validation():
    path = Path(__file__).resolve().parents[1] / "problems" / "craniotomy_bone_flap.toml"
    problem = so.load_problem(
        path,
        {
            "robot.friction.mu": 0.04,
            "robot.payload.mass_kg": 0.5,
            "limits.max_tool_speed_mm_s": 5.0,
            "segment_durations_s": [5.0, 6.0, 7.0, 8.0],
        },
    )
    assert problem.robot.friction.mu == 0.04 and problem.robot.payload.mass == 0.5
    assert problem.limits.max_tool_speed == pytest.approx(5e-3)
    assert list(problem.segment_durations) == [5.0, 6.0, 7.0, 8.0]
    with pytest.raises(so.InputError, match=r"friction\.mu = -1: expected a number"):
        so.load_problem(path, {"robot.friction.mu": -1})
    with pytest.raises(so.InputError, match="limits.max_tool_sped_mm_s: unknown key"):
        so.load_problem(path, {"limits.max_tool_sped_mm_s": 5.0})
    with pytest.raises(so.InputError, match="override name.x: name is not a table"):
        so.load_problem(path, {"name.x": 1})


@pytest.mark.parametrize(
    ("tolerance_mm", "warned"),
    [(100.0, True), (2.5, True), (2.0, False), (0.1, False), (0.03, False), (0.0001, True)],
)
def test_an_implausible_contour_tolerance_is_loaded_with_a_warning(
    tolerance_mm, warned, caplog: pytest.LogCaptureFixture
):
    """Outside the plausible range, one warning line names the key, the value and the
    range; the value is kept (only zero and less are refused)."""
    paper = Path(__file__).resolve().parents[1] / "problems" / "craniotomy_bone_flap.toml"
    with caplog.at_level(logging.WARNING, logger="spm_opt"):
        problem = so.load_problem(paper, {"limits.contour_tolerance_mm": tolerance_mm})
    assert problem.limits.contour_tolerance == pytest.approx(tolerance_mm * 1e-3)
    messages = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    if not warned:
        assert messages == []
        return
    low, high = PLAUSIBLE_CONTOUR_TOLERANCE_MM
    (message,) = messages
    assert f"limits.contour_tolerance_mm = {tolerance_mm:g}" in message, message
    assert f"{low:g} to {high:g} mm" in message and "\n" not in message, message


def test_the_execution_reserve_is_part_of_the_tolerance():
    """The plan's share of the tube is the tolerance less the reserve: 0.03 mm by default,
    at most half a narrow tube, never all of it, and none without a tube."""
    root = Path(__file__).resolve().parents[1] / "problems"
    paper, hardware = root / "craniotomy_bone_flap.toml", root / "craniotomy_hardware.toml"
    assert so.load_problem(paper).limits.execution_reserve == pytest.approx(0.03e-3)
    narrow = so.load_problem(paper, {"limits.contour_tolerance_mm": 0.04})
    assert narrow.limits.execution_reserve == pytest.approx(0.02e-3)
    given = so.load_problem(paper, {"limits.execution_reserve_mm": 0.05})
    assert given.limits.execution_reserve == pytest.approx(0.05e-3)
    assert so.load_problem(hardware).limits.execution_reserve == 0.0
    with pytest.raises(so.InputError, match=r"execution_reserve_mm = 0.1: expected less than"):
        so.load_problem(paper, {"limits.execution_reserve_mm": 0.1})
    with pytest.raises(so.InputError, match=r"execution_reserve_mm = 0.01: expected no reserve"):
        so.load_problem(hardware, {"limits.execution_reserve_mm": 0.01})
