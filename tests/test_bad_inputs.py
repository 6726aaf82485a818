"""Bad inputs to the ``spm-opt`` command line.

Every user mistake must end the same way: exit status 2, exactly one line on stderr that
starts with ``spm-opt: error:`` and names the offending field, file or option, no
traceback, no warning lines, and no output file left behind (neither the CSV, nor its JSON
sidecar, nor a temporary file).

Bad files are made from the shipped ones by string replacement, so each case differs from
a known-good input by one edit; ``test_shipped_inputs_succeed`` proves that the unedited
copies do pass, so a case can only fail for the reason it is about.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import spm_opt as so
from spm_opt.cli import main

ROOT = Path(__file__).resolve().parents[1]
PROBLEM_TEXT = (ROOT / "problems" / "craniotomy_bone_flap.toml").read_text(encoding="utf-8")
ROBOT_TEXT = (ROOT / "problems" / "robots" / "prototype.toml").read_text(encoding="utf-8")

DURATIONS = "segment_durations_s = [10.0, 10.0, 10.0, 10.0]"
A1 = "position_mm = [0.0, 0.0, 68.08]"
A2 = "position_mm = [-22.14, -11.39, 63.10]"
A3 = "position_mm = [-32.44, 22.58, 60.42]"
SPEED = "max_joint_speed_rpm = 13.7"
TOLERANCE = "contour_tolerance_mm = 0.1"
LIMITS = PROBLEM_TEXT[PROBLEM_TEXT.index("[limits]") :]  # the table, to the end of the file
THETA1 = "theta1_range_deg = [-60.0, 60.0]"

HEADER = "t,q1,q2,qd1,qd2,qdd1,qdd2\n"
GOOD_ROWS = "0.0,0.0,0.0,0.0,0.0,0.0,0.0\n1.0,0.1,0.1,0.0,0.0,0.0,0.0\n"

# Warnings a plain `python` run does not print; every other warning is a stray stderr line.
_HIDDEN_WARNINGS = (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning)


# --- helpers ------------------------------------------------------------------------------


def edit(text: str, edits: tuple[tuple[str, str], ...]) -> str:
    """Apply (old, new) replacements, each of text that must be there."""
    for old, new in edits:
        assert old in text, f"the shipped file no longer contains {old!r}"
        text = text.replace(old, new, 1)
    return text


def write_problem(
    directory: Path,
    problem_edits: tuple[tuple[str, str], ...] = (),
    robot_edits: tuple[tuple[str, str], ...] = (),
) -> Path:
    """problem.toml and robots/prototype.toml in ``directory``, edited."""
    (directory / "robots").mkdir(parents=True, exist_ok=True)
    (directory / "robots" / "prototype.toml").write_text(
        edit(ROBOT_TEXT, robot_edits), encoding="utf-8"
    )
    problem = directory / "problem.toml"
    problem.write_text(edit(PROBLEM_TEXT, problem_edits), encoding="utf-8")
    return problem


def run_cli(argv: list[str]) -> tuple[int, list[str]]:
    """Run ``main(argv)`` in-process: the exit status (argparse's SystemExit included) and
    the warnings a real process would print on stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            status = main(argv)
        except SystemExit as exit_:
            status = exit_.code
    shown = [
        f"{w.category.__name__}: {w.message}"
        for w in caught
        if not issubclass(w.category, _HIDDEN_WARNINGS)
    ]
    return status, shown


def assert_one_error(
    status: object,
    stderr: str,
    expected: tuple[str, ...],
    tmp_path: Path,
    shown_warnings: list[str] = (),
) -> None:
    """Status 2, one ``spm-opt: error:`` line containing every ``expected`` substring."""
    assert "Traceback" not in stderr, stderr
    assert status == 2, f"exit status {status!r}, stderr:\n{stderr}"
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, f"expected one stderr line, got {len(lines)}:\n{stderr}"
    assert not shown_warnings, f"warnings would reach stderr: {shown_warnings}"
    line = lines[0]
    assert line.startswith("spm-opt: error:"), line
    # The temporary directory's name contains the test's name; keep it out of the match.
    named = line.replace(str(tmp_path), "<tmp>")
    for text in expected:
        assert text in named, f"{text!r} not in the error line: {line}"


def assert_nothing_written(out: Path, tmp_path: Path) -> None:
    """Neither the CSV nor its sidecar exists, and no temporary file lies anywhere."""
    assert not out.exists(), f"{out} was written"
    assert not out.with_suffix(".json").exists(), f"{out.with_suffix('.json')} was written"
    if out.parent.exists():
        assert sorted(p.name for p in out.parent.iterdir()) == [], "stray files in --out's folder"
    for folder, _, files in os.walk(tmp_path):
        stray = [name for name in files if name.endswith(".tmp")]
        assert not stray, f"temporary files left in {folder}: {stray}"


# --- the known-good inputs ----------------------------------------------------------------


def test_shipped_inputs_succeed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The unedited copies plan and evaluate; every bad case below is one edit away."""
    problem = write_problem(tmp_path)
    out = tmp_path / "out" / "plan.csv"
    status, shown = run_cli(["plan", str(problem), "--out", str(out)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert captured.err == ""
    assert not shown
    assert out.is_file() and out.with_suffix(".json").is_file()

    trajectory = tmp_path / "hand.csv"
    trajectory.write_text(HEADER + GOOD_ROWS, encoding="utf-8")
    status, _ = run_cli(["evaluate", str(problem), str(trajectory)])
    captured = capsys.readouterr()
    # a plan that records no problem is refused, as execute refuses it ...
    assert status == 2 and "records no problem" in captured.err
    status, _ = run_cli(["evaluate", str(problem), str(trajectory), "--other-problem"])
    captured = capsys.readouterr()
    # ... and read and judged when asked: the hand-made motion breaks limits (exit 1)
    assert status == 1, captured.err
    warning, verdict = captured.err.splitlines()
    assert warning.startswith("spm-opt: warning: plan ") and "records no problem" in warning
    assert verdict.startswith("spm-opt: the planned cut: ")


# --- bad problem and robot files, through `spm-opt plan` -----------------------------------


@dataclass(frozen=True)
class Case:
    """A bad problem (or robot) file: edits of the shipped text, options, what to name."""

    expected: tuple[str, ...]
    problem: tuple[tuple[str, str], ...] = ()
    robot: tuple[tuple[str, str], ...] = ()
    options: tuple[str, ...] = ()


def _durations(text: str) -> tuple[tuple[str, str], ...]:
    return ((DURATIONS, f"segment_durations_s = {text}"),)


PLAN_CASES = {
    # missing, wrong type, not finite
    "missing-required-key": Case(("segment_durations_s", "missing"), problem=((DURATIONS, ""),)),
    "missing-name": Case(("name",), problem=(('name = "craniotomy_bone_flap"\n', ""),)),
    "string-for-number-in-list": Case(
        ("segment_durations_s",), problem=_durations('[10.0, "ten", 10.0, 10.0]')
    ),
    "string-for-number": Case(
        ("limits.max_joint_speed_rpm",), problem=((SPEED, 'max_joint_speed_rpm = "13.7"'),)
    ),
    "bool-for-number": Case(
        ("landmarks[0].position_mm",), problem=((A1, "position_mm = [0.0, true, 68.08]"),)
    ),
    "string-for-bool": Case(("closed",), problem=(("closed = true", 'closed = "yes"'),)),
    "number-for-table": Case(
        ("problem.toml: limits = 5",),
        problem=((LIMITS, ""), ("closed = true", "closed = true\nlimits = 5")),
    ),
    "nan-position": Case(
        ("landmarks[0].position_mm",), problem=((A1, "position_mm = [0.0, nan, 68.08]"),)
    ),
    "inf-position": Case(
        ("landmarks[1].position_mm",), problem=((A2, "position_mm = [-22.14, inf, 63.10]"),)
    ),
    "minus-inf-position": Case(
        ("landmarks[1].position_mm",), problem=((A2, "position_mm = [-inf, -11.39, 63.10]"),)
    ),
    "inf-duration": Case(("segment_durations_s",), problem=_durations("[10.0, inf, 10.0, 10.0]")),
    "nan-speed-limit": Case(
        ("max_joint_speed_rpm",), problem=((SPEED, "max_joint_speed_rpm = nan"),)
    ),
    "two-coordinates": Case(
        ("landmarks[0].position_mm",), problem=((A1, "position_mm = [0.0, 68.08]"),)
    ),
    # landmarks the robot cannot take, or that make no cut
    "landmark-on-isocenter-plane": Case(
        ("A3",), problem=((A3, "position_mm = [-32.44, 22.58, 0.0]"),)
    ),
    "landmark-below-isocenter-plane": Case(
        ("problem.toml: landmark A3", "position_mm = [-32.44, 22.58, -60.42]", "z = -60.42 mm"),
        problem=((A3, "position_mm = [-32.44, 22.58, -60.42]"),),
    ),
    "landmark-outside-joint-range": Case(
        ("A3",), problem=((A3, "position_mm = [60.0, 0.0, 10.0]"),)
    ),
    "landmark-in-metres": Case(("A1",), problem=((A1, "position_mm = [0.0, 0.0, 0.06808]"),)),
    "landmark-tiny-z": Case(("A1",), problem=((A1, "position_mm = [0.0, 0.0, 1e-300]"),)),
    "landmark-huge-z": Case(
        ("landmarks[0].position_mm", "1000"), problem=((A1, "position_mm = [0.0, 0.0, 1e300]"),)
    ),
    "duplicated-consecutive-landmarks": Case(
        ("A1", "A2"), problem=((A2, "position_mm = [0.0, 0.0, 68.08]"),)
    ),
    "closed-cut-repeats-first-landmark": Case(
        ("A5", "A1"),
        problem=(
            (DURATIONS, "segment_durations_s = [10.0, 10.0, 10.0, 10.0, 10.0]"),
            ("[limits]", '[[landmarks]]\nname = "A5"\nposition_mm = [0.0, 0.0, 68.08]\n\n[limits]'),
        ),
    ),
    "duplicated-landmark-name": Case(("A1",), problem=(('name = "A2"', 'name = "A1"'),)),
    "unknown-landmark-key": Case(
        ("landmarks[0].colour", "unknown key"), problem=((A1, f'{A1}\ncolour = "red"'),)
    ),
    "landmark-wrong-unit-key": Case(
        ("landmarks[0].position_m:", "did you mean 'position_mm'"),
        problem=((A1, "position_m = [0.0, 0.0, 0.06808]"),),
    ),
    # segment durations
    "zero-duration": Case(("segment_durations_s",), problem=_durations("[10.0, 0.0, 10.0, 10.0]")),
    "negative-duration": Case(
        ("segment_durations_s",), problem=_durations("[10.0, -5.0, 10.0, 10.0]")
    ),
    "too-few-durations": Case(("segment_durations_s",), problem=_durations("[10.0, 10.0, 10.0]")),
    "too-many-durations": Case(
        ("segment_durations_s",), problem=_durations("[10.0, 10.0, 10.0, 10.0, 10.0]")
    ),
    "empty-durations": Case(("segment_durations_s",), problem=_durations("[]")),
    # keys: units and typos
    "unknown-unit-key": Case(
        ("segment_durations_ms", "did you mean 'segment_durations_s'"),
        problem=((DURATIONS, "segment_durations_ms = [10000.0, 10000.0, 10000.0, 10000.0]"),),
    ),
    "typo-in-limits": Case(
        ("limits.max_joint_sped_rpm", "did you mean 'max_joint_speed_rpm'"),
        problem=((SPEED, "max_joint_sped_rpm = 13.7"),),
    ),
    "unknown-planner-option": Case(
        ("planner.cubic.foo",), problem=((SPEED, f"{SPEED}\n\n[planner.cubic]\nfoo = 1"),)
    ),
    # limits
    "speed-above-actuator": Case(
        ("max_joint_speed_rpm", "13.7"), problem=((SPEED, "max_joint_speed_rpm = 20.0"),)
    ),
    "zero-tolerance": Case(
        ("problem.toml: limits.contour_tolerance_mm = 0.0", "> 0"),
        problem=((TOLERANCE, "contour_tolerance_mm = 0.0"),),
    ),
    "negative-tolerance": Case(
        ("limits.contour_tolerance_mm = -0.1",),
        problem=((TOLERANCE, "contour_tolerance_mm = -0.1"),),
    ),
    "zero-speed-limit": Case(
        ("max_joint_speed_rpm",), problem=((SPEED, "max_joint_speed_rpm = 0.0"),)
    ),
    # files
    "robot-file-missing": Case(
        ("robot", "robots/missing.toml"),
        problem=(('robot = "robots/prototype.toml"', 'robot = "robots/missing.toml"'),),
    ),
    "invalid-toml": Case(("problem.toml", "TOML"), problem=(("closed = true", "closed = tru e"),)),
    # bad robot files
    "robot-inverted-joint-range": Case(
        ("joints.theta1_range_deg",), robot=((THETA1, "theta1_range_deg = [60.0, -60.0]"),)
    ),
    "robot-inverted-joint-range-value": Case(
        ("joints.theta1_range_deg = [60.0, -60.0]",),
        robot=((THETA1, "theta1_range_deg = [60.0, -60.0]"),),
    ),
    "robot-joint-range-beyond-89-deg": Case(
        ("joints.theta1_range_deg",), robot=((THETA1, "theta1_range_deg = [-95.0, 60.0]"),)
    ),
    "robot-unknown-key": Case(
        ("upper_arc.rail_width_mm",),
        robot=(("rail_radius_mm = 160.0", "rail_radius_mm = 160.0\nrail_width_mm = 5.0"),),
    ),
    "robot-wrong-unit-key": Case(
        ("upper_arc.rail_radius_cm", "did you mean 'rail_radius_mm'"),
        robot=(("rail_radius_mm = 160.0", "rail_radius_cm = 16.0"),),
    ),
    "robot-unknown-actuator": Case(
        ("actuator.model",), robot=(('model = "L54-50-S500-R"', 'model = "XM430"'),)
    ),
    "robot-nan-radius": Case(
        ("upper_platform.com_radius_mm",),
        robot=(("com_radius_mm = 171.33", "com_radius_mm = nan"),),
    ),
    "robot-invalid-toml": Case(("prototype.toml", "TOML"), robot=(("[joints]", "[joints"),)),
    "robot-encoder-offset-too-large": Case(
        ("joints.encoder_offset_deg",),
        robot=((THETA1, f"{THETA1}\nencoder_offset_deg = [0.0, 45.0]"),),
    ),
    "robot-coulomb-friction-not-a-pair": Case(
        ("actuator.coulomb_friction_nm",),
        robot=(("gear_efficiency = 1.0", "gear_efficiency = 1.0\ncoulomb_friction_nm = 0.1"),),
    ),
    "robot-negative-viscous-friction": Case(
        ("actuator.viscous_friction_nm_s_per_rad",),
        robot=(
            (
                "gear_efficiency = 1.0",
                "gear_efficiency = 1.0\nviscous_friction_nm_s_per_rad = [0.1, -1]",
            ),
        ),
    ),
    # options
    "unknown-planner": Case(
        ("planner", "no_such_planner"), options=("--planner", "no_such_planner")
    ),
    "zero-rate": Case(("--rate",), options=("--rate", "0")),
    "nan-rate": Case(("--rate",), options=("--rate", "nan")),
    "non-numeric-rate": Case(("--rate",), options=("--rate", "fast")),
}


def _plan_params() -> list[pytest.param]:
    return [pytest.param(case, id=name) for name, case in PLAN_CASES.items()]


@pytest.mark.parametrize("case", _plan_params())
def test_bad_problem_or_robot(
    case: Case, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    problem = write_problem(tmp_path, case.problem, case.robot)
    out = tmp_path / "out" / "plan.csv"
    status, shown = run_cli(["plan", str(problem), "--out", str(out), *case.options])
    assert_one_error(status, capsys.readouterr().err, case.expected, tmp_path, shown)
    assert_nothing_written(out, tmp_path)


# --- unreasonable durations: the planner or the writer fails on them ----------------------


@pytest.mark.parametrize(
    "durations",
    [
        pytest.param(
            "[1e12, 10.0, 10.0, 10.0]",
            id="astronomical-duration",
        ),
        pytest.param(
            "[1e-300, 10.0, 10.0, 10.0]",
            id="vanishing-duration",
        ),
    ],
)
def test_unreasonable_durations(
    durations: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    problem = write_problem(tmp_path, _durations(durations))
    out = tmp_path / "out" / "plan.csv"
    status, shown = run_cli(["plan", str(problem), "--out", str(out)])
    assert_one_error(status, capsys.readouterr().err, ("segment_durations_s",), tmp_path, shown)
    assert_nothing_written(out, tmp_path)


# --- problem paths and the --out option ----------------------------------------------------


def test_problem_file_missing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out" / "plan.csv"
    status, shown = run_cli(["plan", str(tmp_path / "missing_problem.toml"), "--out", str(out)])
    assert_one_error(status, capsys.readouterr().err, ("missing_problem.toml",), tmp_path, shown)
    assert_nothing_written(out, tmp_path)


def test_problem_path_is_a_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "a_folder.toml"
    folder.mkdir()
    out = tmp_path / "out" / "plan.csv"
    status, shown = run_cli(["plan", str(folder), "--out", str(out)])
    assert_one_error(status, capsys.readouterr().err, ("a_folder.toml",), tmp_path, shown)
    assert_nothing_written(out, tmp_path)


@pytest.mark.parametrize(
    ("command", "option"),
    [
        ("predict PLAN --problem MISSING", "--problem"),
        ("predict PLAN --problem PROBLEM --robot MISSING", "--robot"),
        ("predict PLAN --problem PROBLEM --robot PROBLEM", "--robot"),
        ("compensate PLAN --problem PROBLEM --other-problem --robot MISSING --out OUT", "--robot"),
        (
            "slow-breakaways PLAN --problem PROBLEM --other-problem --robot MISSING --out OUT",
            "--robot",
        ),
        (
            "execute PLAN --problem PROBLEM --backend sim --plant-robot MISSING --log OUT",
            "--plant-robot",
        ),
        ("calibrate --problem MISSING --out OUT", "--problem"),
        ("identify PLAN --problem MISSING --out OUT", "--problem"),
    ],
)
def test_a_bad_file_names_its_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, option: str
) -> None:
    """A missing or wrong file given by an option: the error line starts with the option."""
    problem = write_problem(tmp_path / "inputs")
    plan = tmp_path / "inputs" / "plan.csv"
    plan.write_text(HEADER + GOOD_ROWS, encoding="utf-8")
    argv = command.split()
    out = tmp_path / "out" / ("robot.toml" if argv[0] in ("calibrate", "identify") else "out.csv")
    names = {"PLAN": plan, "PROBLEM": problem, "MISSING": tmp_path / "missing.toml", "OUT": out}
    status, shown = run_cli([str(names.get(part, part)) for part in argv])
    assert_one_error(status, capsys.readouterr().err, (f"error: {option} <tmp>/",), tmp_path, shown)
    assert not out.exists() and not out.parent.exists()


def test_out_not_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    problem = write_problem(tmp_path)
    out = tmp_path / "out" / "plan.txt"
    status, shown = run_cli(["plan", str(problem), "--out", str(out)])
    assert_one_error(status, capsys.readouterr().err, ("--out", "plan.txt"), tmp_path, shown)
    assert_nothing_written(out, tmp_path)
    assert_nothing_written(out.with_suffix(".csv"), tmp_path)


def test_out_missing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    problem = write_problem(tmp_path)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    status, shown = run_cli(["plan", str(problem)])
    assert_one_error(status, capsys.readouterr().err, ("--out",), tmp_path, shown)
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_out_is_a_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    problem = write_problem(tmp_path)
    out = tmp_path / "out" / "plan.csv"
    out.mkdir(parents=True)
    status, shown = run_cli(["plan", str(problem), "--out", str(out)])
    assert_one_error(status, capsys.readouterr().err, ("plan.csv",), tmp_path, shown)
    assert out.is_dir() and not any(out.iterdir())
    assert sorted(p.name for p in out.parent.iterdir()) == ["plan.csv"]


def test_out_folder_is_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    problem = write_problem(tmp_path)
    (tmp_path / "out").write_text("not a folder\n", encoding="utf-8")
    out = tmp_path / "out" / "plan.csv"
    status, shown = run_cli(["plan", str(problem), "--out", str(out)])
    assert_one_error(status, capsys.readouterr().err, ("out",), tmp_path, shown)
    assert (tmp_path / "out").read_text(encoding="utf-8") == "not a folder\n"
    for folder, _, files in os.walk(tmp_path):
        assert not [name for name in files if name.endswith(".tmp")], folder


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        pytest.param(["replan", "x.toml"], ("replan",), id="unknown-command"),
        pytest.param([], ("command",), id="no-command"),
    ],
)
def test_usage_error(
    argv: list[str], expected: tuple[str, ...], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    status, shown = run_cli(argv)
    assert_one_error(status, capsys.readouterr().err, expected, tmp_path, shown)


def test_reproduce_problem_missing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "results"
    argv = ["reproduce", "--problem", str(tmp_path / "missing_problem.toml"), "--out", str(out)]
    status, shown = run_cli(argv)
    assert_one_error(status, capsys.readouterr().err, ("missing_problem.toml",), tmp_path, shown)
    assert not out.exists() or not any(out.iterdir())


# --- bad trajectory files, through `spm-opt evaluate` --------------------------------------


EVALUATE_CASES = {
    "wrong-header": (
        "t,q1,q2,qd1,qd2,qdd1\n0,0,0,0,0,0\n1,0,0,0,0,0\n",
        ("trajectory.csv", "header"),
    ),
    "renamed-column": (
        "time,q1,q2,qd1,qd2,qdd1,qdd2\n" + GOOD_ROWS,
        ("trajectory.csv", "header"),
    ),
    "empty-file": ("", ("trajectory.csv",)),
    "non-numeric-value": (
        HEADER + "0.0,0.0,0.0,0.0,0.0,0.0,0.0\n1.0,abc,0.0,0.0,0.0,0.0,0.0\n",
        ("trajectory.csv", "line 3", "q1"),
    ),
    "nan-value": (
        HEADER + "0.0,0.0,0.0,0.0,0.0,0.0,0.0\n1.0,0.1,nan,0.0,0.0,0.0,0.0\n",
        ("trajectory.csv", "line 3", "q2"),
    ),
    "inf-value": (
        HEADER + "0.0,0.0,0.0,inf,0.0,0.0,0.0\n1.0,0.1,0.1,0.0,0.0,0.0,0.0\n",
        ("trajectory.csv", "line 2", "qd1"),
    ),
    "times-not-increasing": (
        HEADER + "0.0,0.0,0.0,0.0,0.0,0.0,0.0\n1.0,0.1,0.1,0.0,0.0,0.0,0.0\n"
        "0.5,0.2,0.2,0.0,0.0,0.0,0.0\n",
        ("trajectory.csv", "line 4", "column t"),
    ),
    "repeated-time": (
        HEADER + "0.0,0.0,0.0,0.0,0.0,0.0,0.0\n0.0,0.1,0.1,0.0,0.0,0.0,0.0\n",
        ("trajectory.csv", "column t"),
    ),
    "short-row": (
        HEADER + "0.0,0.0,0.0,0.0,0.0,0.0,0.0\n1.0,0.1,0.1\n",
        ("trajectory.csv", "line 3"),
    ),
    "one-sample": (HEADER + "0.0,0.0,0.0,0.0,0.0,0.0,0.0\n", ("trajectory.csv",)),
}


@pytest.mark.parametrize(
    ("text", "expected"),
    [pytest.param(text, expected, id=name) for name, (text, expected) in EVALUATE_CASES.items()],
)
def test_bad_trajectory_csv(
    text: str, expected: tuple[str, ...], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    problem = write_problem(tmp_path)
    trajectory = tmp_path / "trajectory.csv"
    trajectory.write_text(text, encoding="utf-8")
    status, shown = run_cli(["evaluate", str(problem), str(trajectory)])
    captured = capsys.readouterr()
    assert_one_error(status, captured.err, expected, tmp_path, shown)
    assert captured.out == ""


def test_trajectory_not_utf8(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    problem = write_problem(tmp_path)
    trajectory = tmp_path / "trajectory.csv"
    trajectory.write_bytes(b"\xff\xfe" + HEADER.encode("utf-16-le"))
    status, shown = run_cli(["evaluate", str(problem), str(trajectory)])
    assert_one_error(status, capsys.readouterr().err, ("trajectory.csv",), tmp_path, shown)


def test_trajectory_file_missing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    problem = write_problem(tmp_path)
    status, shown = run_cli(["evaluate", str(problem), str(tmp_path / "missing.csv")])
    assert_one_error(status, capsys.readouterr().err, ("missing.csv",), tmp_path, shown)


@pytest.mark.parametrize(
    ("sidecar", "expected"),
    [
        pytest.param("{", ("trajectory.json",), id="invalid-json"),
        pytest.param("[1, 2]", ("trajectory.json",), id="not-an-object"),
        pytest.param(
            '{"landmark_times_s": "soon"}',
            ("landmark_times_s",),
            id="landmark-times-not-numbers",
        ),
        pytest.param(
            '{"landmark_times_s": 5}',
            ("landmark_times_s",),
            id="landmark-times-not-a-list",
        ),
    ],
)
def test_bad_trajectory_sidecar(
    sidecar: str, expected: tuple[str, ...], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    problem = write_problem(tmp_path)
    trajectory = tmp_path / "trajectory.csv"
    trajectory.write_text(HEADER + GOOD_ROWS, encoding="utf-8")
    (tmp_path / "trajectory.json").write_text(sidecar, encoding="utf-8")
    status, shown = run_cli(["evaluate", str(problem), str(trajectory)])
    assert_one_error(status, capsys.readouterr().err, expected, tmp_path, shown)


def test_trajectory_astronomical_duration(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    problem = write_problem(tmp_path)
    trajectory = tmp_path / "trajectory.csv"
    trajectory.write_text(
        HEADER + "0.0,0.0,0.0,0.0,0.0,0.0,0.0\n1e12,0.1,0.1,0.0,0.0,0.0,0.0\n", encoding="utf-8"
    )
    status, shown = run_cli(["evaluate", str(problem), str(trajectory)])
    assert_one_error(status, capsys.readouterr().err, ("trajectory.csv",), tmp_path, shown)


# --- a real process -------------------------------------------------------------------------


def test_real_process_prints_one_line(tmp_path: Path) -> None:
    """The console entry point in its own process: one line, status 2, nothing written."""
    problem = write_problem(tmp_path, ((A1, "position_mm = [0.0, nan, 68.08]"),))
    out = tmp_path / "out" / "plan.csv"
    result = subprocess.run(
        [sys.executable, "-m", "spm_opt.cli", "plan", str(problem), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        check=False,
    )
    assert_one_error(result.returncode, result.stderr, ("landmarks[0].position_mm",), tmp_path)
    assert result.stdout == ""
    assert_nothing_written(out, tmp_path)


# --- execute and emulate -----------------------------------------------------------------

HARDWARE_PROBLEM = ROOT / "problems" / "craniotomy_hardware.toml"


@pytest.fixture(scope="module")
def hardware_plan_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    plan = tmp_path_factory.mktemp("plan") / "plan.csv"
    assert main(["plan", str(HARDWARE_PROBLEM), "--out", str(plan)]) == 0
    return plan


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        pytest.param(["--rate", "nan"], ("--rate: rate_hz = nan", "[1.0, 2000.0]"), id="rate-nan"),
        pytest.param(["--rate", "0"], ("--rate: rate_hz = 0.0",), id="rate-zero"),
        pytest.param(["--feed", "nan"], ("--feed: feed = nan", "[0.1, 4.0]"), id="feed-nan"),
        pytest.param(["--feed", "-0.5"], ("--feed: feed = -0.5",), id="feed-negative"),
        pytest.param(
            ["--max-hold", "-1"], ("--max-hold: max_hold_s = -1.0",), id="max-hold-negative"
        ),
        pytest.param(["--start-deg", "5"], ("--start-deg '5'", "two float"), id="start-one"),
        pytest.param(["--start-deg", "5,5"], ("5.000 deg away", "approach"), id="start-away"),
        pytest.param(["--backend", "robot"], ("--backend", "invalid choice"), id="backend"),
        pytest.param(["--backend", "dynamixel"], ("--port: required",), id="no-port"),
        pytest.param(
            ["--backend", "dynamixel", "--port", "/dev/null", "--ids", "1"],
            ("--ids '1'",),
            id="ids-one",
        ),
        pytest.param(
            ["--backend", "dynamixel", "--port", "/dev/null", "--baud", "12345"],
            ("baud", "12345"),
            id="baud",
        ),
        pytest.param(
            ["--problem", str(ROOT / "problems" / "craniotomy_bone_flap.toml")],
            ("plan refused: the plan was made for craniotomy_hardware", "--other-problem"),
            id="other-problem",
        ),
        pytest.param(
            ["--problem", str(ROOT / "problems" / "craniotomy_bone_flap.toml"), "--other-problem"],
            ("plan refused: theta", "acceleration step"),
            id="limit-broken",
        ),
        pytest.param(
            ["--plant-robot", str(ROOT / "problems" / "robots" / "missing.toml")],
            ("missing.toml",),
            id="plant-robot-missing",
        ),
        pytest.param(
            ["--backend", "dynamixel", "--port", "/dev/null", "--plant-robot", "x.toml"],
            ("--plant-robot: only with --backend sim",),
            id="plant-robot-on-hardware",
        ),
    ],
)
def test_bad_execute(
    options: list[str],
    expected: tuple[str, ...],
    hardware_plan_csv: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    log = tmp_path / "logs" / "run.csv"
    argv = ["execute", str(hardware_plan_csv), "--problem", str(HARDWARE_PROBLEM)]
    argv += ["--backend", "sim", "--log", str(log), *options]
    status, shown = run_cli(argv)
    assert_one_error(status, capsys.readouterr().err, expected, tmp_path, shown)
    assert_nothing_written(log, tmp_path)


def test_execute_log_not_csv(
    hardware_plan_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "run.txt"
    argv = ["execute", str(hardware_plan_csv), "--problem", str(HARDWARE_PROBLEM)]
    status, shown = run_cli([*argv, "--backend", "sim", "--log", str(log)])
    assert_one_error(
        status, capsys.readouterr().err, ("run.txt", "ending in .csv"), tmp_path, shown
    )
    assert not log.exists()


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        pytest.param(["--fault", "melt:at=1"], ("fault: unknown kind 'melt'",), id="kind"),
        pytest.param(["--fault", "overload:at=1"], ("field 'id' is required",), id="no-id"),
        pytest.param(["--start-deg", "x,1"], ("--start-deg 'x,1'",), id="start"),
        pytest.param(["--plant-robot", "missing.toml"], ("missing.toml",), id="plant-robot"),
    ],
)
def test_bad_emulate(
    options: list[str],
    expected: tuple[str, ...],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    status, shown = run_cli(["emulate", *options])
    assert_one_error(status, capsys.readouterr().err, expected, tmp_path, shown)


# --- bad execution logs, through `spm-opt evaluate` -------------------------------------------

BONE_FLAP = ROOT / "problems" / "craniotomy_bone_flap.toml"


@pytest.fixture(scope="module")
def executed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with a run of the hardware problem's toppra plan, slowed at its breakaways
    (at the full pace the loops' answer to each goal step takes θ1 past its speed limit),
    on the simulated robot: run.csv, run.json and the plant's true state, true.npz."""
    folder = tmp_path_factory.mktemp("executed")
    problem = so.load_problem(HARDWARE_PROBLEM)
    plan = so.slowed_for_breakaways(problem, so.plan(problem, "toppra")).trajectory
    backend = so.SimulatedRobot(problem.robot, start_rad=plan.position(0.0))
    so.execute(plan, backend, problem, folder / "run.csv")
    backend.trace.save(folder / "true.npz")
    return folder


def _edit_table(edit: Callable[[pd.DataFrame], pd.DataFrame]) -> Callable[[Path], None]:
    def apply(folder: Path) -> None:
        table = pd.read_csv(folder / "run.csv", dtype=str, keep_default_na=False)
        edit(table).to_csv(folder / "run.csv", index=False)

    return apply


def _nan_in_a_read(table: pd.DataFrame) -> pd.DataFrame:
    table.loc[100, "position_theta2_rad"] = "nan"  # line 102
    return table


def _times_swapped(table: pd.DataFrame) -> pd.DataFrame:
    table.loc[[50, 51], "time_s"] = table.loc[[51, 50], "time_s"].to_numpy()  # lines 52, 53
    return table


def _trace_cut(folder: Path) -> None:
    with np.load(folder / "true.npz") as data:
        arrays = {name: data[name][: len(data["time_s"]) // 2] for name in data.files}
    with open(folder / "true.npz", "wb") as file:
        np.savez(file, **arrays)


LOG_CASES = {
    "log-missing": (lambda folder: (folder / "run.csv").unlink(), [], ("run.csv",)),
    "columns-missing": (
        _edit_table(lambda table: table.drop(columns=["reference_theta1_rad", "status"])),
        [],
        ("run.csv", "missing columns reference_theta1_rad, status"),
    ),
    "no-plan-rows": (
        _edit_table(lambda table: table.assign(phase="approach")),
        [],
        ("run.csv", "no plan rows"),
    ),
    "nan-in-a-read": (
        _edit_table(_nan_in_a_read),
        [],
        ("run.csv", "line 102", "position_theta2_rad is empty or NaN", "read did not fail"),
    ),
    "time-not-increasing": (
        _edit_table(_times_swapped),
        [],
        ("run.csv", "line 53", "time_s does not increase"),
    ),
    "header-missing": (
        lambda folder: (folder / "run.json").unlink(),
        [],
        ("run.csv", "no header run.json"),
    ),
    "header-not-json": (
        lambda folder: (folder / "run.json").write_text("{", encoding="utf-8"),
        [],
        ("run.json", "not JSON"),
    ),
    "other-problem": (
        lambda folder: None,
        ["--problem-file", str(BONE_FLAP)],
        ("run.csv refused", "ran under craniotomy_hardware", "--other-problem"),
    ),
    "trace-short": (_trace_cut, ["--trace", "true.npz"], ("true.npz", "covers", "this run")),
    "trace-missing": (
        lambda folder: (folder / "true.npz").unlink(),
        ["--trace", "true.npz"],
        ("true.npz", "no such file"),
    ),
    "trace-not-a-trace": (
        lambda folder: (folder / "true.npz").write_bytes(b"not a zip"),
        ["--trace", "true.npz"],
        ("true.npz", "not a trace"),
    ),
}


def _evaluate_argv(folder: Path, options: list[str]) -> list[str]:
    """``spm-opt evaluate`` of the copied log: the problem it ran under unless
    ``--problem-file`` says another, the trace's file name taken in ``folder``."""
    problem = HARDWARE_PROBLEM
    if "--problem-file" in options:
        problem = Path(options[options.index("--problem-file") + 1])
        options = [o for o in options if o not in ("--problem-file", str(problem))]
    options = [str(folder / o) if o.endswith(".npz") else o for o in options]
    return ["evaluate", str(problem), str(folder / "run.csv"), *options]


def _copy(executed: Path, tmp_path: Path) -> Path:
    folder = tmp_path / "logs"
    shutil.copytree(executed, folder)
    return folder


def test_an_executed_log_is_judged(
    executed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The unedited copy is judged, with its trace: every bad case below is one edit away."""
    folder = _copy(executed, tmp_path)
    status, shown = run_cli(_evaluate_argv(folder, ["--trace", "true.npz", "--json"]))
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert captured.err == "" and not shown
    assert set(json.loads(captured.out)) == {"measured", "true"}


@pytest.mark.parametrize(
    ("edit", "options", "expected"),
    [pytest.param(*case, id=name) for name, case in LOG_CASES.items()],
)
def test_bad_execution_log(
    edit: Callable[[Path], None],
    options: list[str],
    expected: tuple[str, ...],
    executed: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    folder = _copy(executed, tmp_path)
    edit(folder)
    before = sorted(folder.iterdir())
    status, shown = run_cli(_evaluate_argv(folder, options))
    captured = capsys.readouterr()
    assert_one_error(status, captured.err, expected, tmp_path, shown)
    assert captured.out == ""
    assert sorted(folder.iterdir()) == before  # nothing written


def test_trace_with_a_trajectory(
    hardware_plan_csv: Path, executed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["evaluate", str(HARDWARE_PROBLEM), str(hardware_plan_csv)]
    status, shown = run_cli([*argv, "--trace", str(executed / "true.npz")])
    captured = capsys.readouterr()
    assert_one_error(
        status, captured.err, ("--trace: only with an execution log",), tmp_path, shown
    )
    assert captured.out == ""
