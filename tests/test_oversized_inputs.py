"""Inputs of any size get an answer, not an out-of-memory kill.

Each oversized input goes to the real command line in a process of its own whose address
space is capped (:data:`MEMORY_CAP_BYTES`); it must end in status 2 with one short
``spm-opt: error:`` line, within :data:`TIMEOUT_S` (a guard against hangs, not a bound on
speed). The inputs are made here, in the test's temporary directory. Before the limits of
:mod:`spm_opt.base.input_limits`, the dotted key took 23.7 GB, the nested arrays a traceback of
3,001 lines, the landmarks 466 TiB, the durations 51 s and a 100 MB line, the sweep
minutes, and the log a ``MemoryError`` traceback at 7.8 GB.
"""

from __future__ import annotations

import dataclasses
import os
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_bad_inputs import DURATIONS, assert_one_error, write_problem

import spm_opt as so
from spm_opt.base.errors import InputError
from spm_opt.base.fields import parse_toml
from spm_opt.base.input_limits import MAX_LANDMARKS, MAX_LOG_ROWS, MAX_TRAJECTORY_ROWS
from spm_opt.execution.log import COLUMNS
from spm_opt.studies.sweep.spec import load_sweep_spec

MEMORY_CAP_BYTES = 3 << 30
"""Address space of each command (3 GiB; importing numpy, scipy and CasADi and planning
the paper's problem reserves 0.6 GiB)."""
TIMEOUT_S = 60.0
LONGEST_LINE = 400
"""Characters of the error line: enough for a path and a message, not for an echo."""
ROOT = Path(__file__).resolve().parents[1]
HARDWARE_PROBLEM = ROOT / "problems" / "craniotomy_hardware.toml"


def _cap_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP_BYTES, MEMORY_CAP_BYTES))


def run_capped(argv: list[str], tmp_path: Path) -> subprocess.CompletedProcess[str]:
    """``spm-opt argv`` in a process of its own, its memory capped, one BLAS thread."""
    threads = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    return subprocess.run(
        [sys.executable, "-m", "spm_opt.cli", *argv],
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        cwd=tmp_path,
        env={**os.environ, **threads},
        preexec_fn=_cap_memory,
        check=False,
    )


def assert_refused(argv: list[str], expected: tuple[str, ...], tmp_path: Path) -> None:
    """The command ends in status 2 with one short error line holding ``expected``."""
    result = run_capped(argv, tmp_path)
    assert_one_error(result.returncode, result.stderr, expected, tmp_path)
    assert len(result.stderr.strip()) <= LONGEST_LINE, result.stderr[:1000]


def plan_argv(problem: Path) -> list[str]:
    return ["plan", str(problem), "--out", str(problem.parent / "out" / "plan.csv")]


def test_the_capped_command_line_plans_a_real_problem(tmp_path: Path) -> None:
    """The cap leaves room for real work: every refusal below is the input's."""
    result = run_capped(plan_argv(write_problem(tmp_path)), tmp_path)
    assert result.returncode == 0, result.stderr


def test_a_dotted_key_100000_deep(tmp_path: Path) -> None:
    problem = write_problem(tmp_path)
    key = ".".join(["a"] * 100_000)
    problem.write_text(problem.read_text() + f"\n[planner.cubic]\n{key} = 1\n")
    assert_refused(plan_argv(problem), ("problem.toml", "a dotted key of 100,000 parts"), tmp_path)


def test_arrays_nested_1000_deep(tmp_path: Path) -> None:
    nested = "x = " + "[" * 1000 + "]" * 1000 + "\n"
    problem = write_problem(tmp_path, (("[limits]", nested + "[limits]"),))
    expected = ("problem.toml", "line", "nested more than 32 deep")
    assert_refused(plan_argv(problem), expected, tmp_path)


def _landmarks(count: int) -> str:
    """``count`` [[landmarks]] tables on a circle on the skull, mm."""
    return "".join(
        f'[[landmarks]]\nname = "L{i}"\nposition_mm = [{20 + i % 7}.0, {i % 11}.0, 60.0]\n'
        for i in range(count)
    )


def _with_landmarks(tmp_path: Path, count: int) -> Path:
    """The shipped problem with ``count`` landmarks (and durations) instead of its own."""
    problem = write_problem(tmp_path)
    text = problem.read_text()
    head, tail = text[: text.index("[[landmarks]]")], text[text.index("[limits]") :]
    durations = "segment_durations_s = [" + ", ".join(["1.0"] * count) + "]"
    problem.write_text(head.replace(DURATIONS, durations) + _landmarks(count) + tail)
    return problem


def test_a_million_landmarks(tmp_path: Path) -> None:
    problem = _with_landmarks(tmp_path, 1_000_000)
    assert_refused(plan_argv(problem), ("problem.toml", "bytes; expected a TOML file"), tmp_path)


def test_more_landmarks_than_allowed(tmp_path: Path) -> None:
    problem = _with_landmarks(tmp_path, MAX_LANDMARKS + 1)
    expected = ("problem.toml", f"{MAX_LANDMARKS + 1} of them", f"at most {MAX_LANDMARKS}")
    assert_refused(plan_argv(problem), expected, tmp_path)


def test_100_mb_of_segment_durations(tmp_path: Path) -> None:
    durations = "segment_durations_s = [" + "10.0, " * 16_666_666 + "10.0]"
    problem = write_problem(tmp_path, ((DURATIONS, durations),))
    assert_refused(plan_argv(problem), ("problem.toml", "bytes"), tmp_path)


def test_many_segment_durations_are_not_echoed(tmp_path: Path) -> None:
    durations = "segment_durations_s = [" + ", ".join(["10.0"] * 5000) + "]"
    problem = write_problem(tmp_path, ((DURATIONS, durations),))
    expected = ("segment_durations_s = [10.0, 10.0", "(5,000 items)", "expected 4 durations")
    assert_refused(plan_argv(problem), expected, tmp_path)


def test_a_sweep_of_ten_million_tasks(tmp_path: Path) -> None:
    write_problem(tmp_path)
    spec = tmp_path / "sweep.toml"
    spec.write_text(
        'name = "huge"\nproblem = "problem.toml"\nplanners = ["cubic"]\n'
        "[random]\nsamples = 100000\n[random.ranges]\n"
        '"limits.max_tool_speed_mm_s" = [2.0, 6.0]\n'
        "[flaps]\ncount = 100\nsize_mm = [20.0, 50.0]\n"
    )
    expected = ("sweep.toml", "10,000,000 tasks", "at most 100,000", "--max-tasks")
    assert_refused(["sweep", str(spec), "--out", str(tmp_path / "out")], expected, tmp_path)


def _log(path: Path, rows: int) -> Path:
    """A log of ``rows`` rows that hold a time and a phase only (27 bytes each)."""
    row = b"0.0,plan" + b"," * (len(COLUMNS) - 2) + b"\n"
    with open(path, "wb") as file:
        file.write(",".join(COLUMNS).encode() + b"\n")
        for _ in range(rows // 1_000_000):
            file.write(row * 1_000_000)
        file.write(row * (rows % 1_000_000))
    return path


def identify_argv(log: Path) -> list[str]:
    out = str(log.parent / "out" / "robot.toml")
    return ["identify", str(log), "--problem", str(HARDWARE_PROBLEM), "--out", out]


@pytest.mark.slow
def test_a_log_of_ten_million_rows(tmp_path: Path) -> None:
    log = _log(tmp_path / "log.csv", 10_000_000)
    expected = ("log.csv", "10,000,000 rows", f"at most {MAX_LOG_ROWS:,}")
    assert_refused(identify_argv(log), expected, tmp_path)


def test_logs_of_more_rows_than_allowed_together(tmp_path: Path) -> None:
    half = _log(tmp_path / "half.csv", MAX_LOG_ROWS // 2 + 1)
    argv = identify_argv(half)
    argv.insert(2, str(half))
    expected = ("half.csv", f"{MAX_LOG_ROWS + 2:,} rows together", f"at most {MAX_LOG_ROWS:,}")
    assert_refused(argv, expected, tmp_path)


def test_an_empty_log(tmp_path: Path) -> None:
    log = tmp_path / "empty.csv"
    log.write_bytes(b"")
    assert_refused(identify_argv(log), ("empty.csv", "empty file"), tmp_path)


def test_a_trajectory_of_more_samples_than_allowed(tmp_path: Path) -> None:
    trajectory = tmp_path / "plan.csv"
    rows = "".join(f"{i},0,0,0,0,0,0\n" for i in range(MAX_TRAJECTORY_ROWS + 1))
    trajectory.write_text("t,q1,q2,qd1,qd2,qdd1,qdd2\n" + rows)
    expected = ("plan.csv", f"at most {MAX_TRAJECTORY_ROWS:,} samples")
    assert_refused(["evaluate", str(HARDWARE_PROBLEM), str(trajectory)], expected, tmp_path)


def test_a_trajectory_of_one_long_line(tmp_path: Path) -> None:
    trajectory = tmp_path / "plan.csv"
    trajectory.write_text("t" * 10_000_000)
    expected = ("plan.csv", "line 1: not CSV (field larger than field limit")
    assert_refused(["evaluate", str(HARDWARE_PROBLEM), str(trajectory)], expected, tmp_path)


def test_a_plan_too_dense_for_its_csv(tmp_path: Path) -> None:
    """The plan command refuses to write what reading would refuse: 40 s at 100 kHz."""
    argv = [*plan_argv(write_problem(tmp_path)), "--rate", "100000"]
    expected = ("4,000,006 samples", f"at most {MAX_TRAJECTORY_ROWS:,}", "lower the rate")
    assert_refused(argv, expected, tmp_path)
    assert not (tmp_path / "out").exists()


def test_a_sidecar_nested_100000_deep(tmp_path: Path) -> None:
    trajectory = tmp_path / "plan.csv"
    trajectory.write_text("t,q1,q2,qd1,qd2,qdd1,qdd2\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0\n")
    (tmp_path / "plan.json").write_text('{"a": ' + "[" * 100_000 + "]" * 100_000 + "}")
    expected = ("plan.json", "not valid JSON")
    assert_refused(["evaluate", str(HARDWARE_PROBLEM), str(trajectory)], expected, tmp_path)


# --- the limits in the library ----------------------------------------------------------


def test_a_problem_built_in_code_has_at_most_the_largest_landmark_count() -> None:
    problem = so.load_problem(HARDWARE_PROBLEM)
    many = np.tile(problem.landmarks[:1], (1_000_000, 1))
    with pytest.raises(InputError, match=f"1,000,000 of them; expected at most {MAX_LANDMARKS}"):
        dataclasses.replace(problem, landmarks=many)


def test_the_caller_sets_the_largest_sweep() -> None:
    """The shipped friction sweep has 36 tasks: refused under 35, taken under 36, and its
    tasks refused once the limit falls (before any is made)."""
    path = ROOT / "problems" / "sweeps" / "friction_payload.toml"
    with pytest.raises(InputError, match=r"36 tasks \(12 grid points x 3 planners\)"):
        load_sweep_spec(path, max_tasks=35)
    spec = load_sweep_spec(path, max_tasks=36)
    assert spec.task_count == 36
    with pytest.raises(InputError, match="at most 10 "):
        dataclasses.replace(spec, max_tasks=10).tasks()
    with pytest.raises(InputError, match="max_tasks = 0"):
        load_sweep_spec(path, max_tasks=0)


def test_brackets_and_dots_in_strings_and_comments_do_not_count() -> None:
    deep, dotted = "[" * 40 + "]" * 40, ".".join(["a"] * 40)
    text = (
        f"basic = \"{deep} {dotted}\"\nliteral = '{deep}'\n# {deep} {dotted}\n"
        f'multiline = """\n{deep}\n{dotted}""""\nquoted."{dotted}" = 1\n'
        f"floats = [{', '.join(['1.5e-3'] * 100)}]\n"
    )
    data = parse_toml(text, "strings.toml")
    assert data["multiline"] == f'{deep}\n{dotted}"' and data["quoted"] == {dotted: 1}
