"""The library's log reaches the user of ``spm-opt``: warnings on stderr as
``spm-opt: warning: ...``, info lines with ``-v``, debug lines with ``-vv``; the library
itself, used from Python, prints nothing."""

from __future__ import annotations

import importlib
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

import spm_opt as so
from spm_opt.cli import main

EVALUATOR = importlib.import_module(
    "spm_opt.judge.evaluate"
)  # spm_opt.judge.evaluate is the function

ROOT = Path(__file__).resolve().parents[1]
PAPER_PROBLEM = ROOT / "problems" / "craniotomy_bone_flap.toml"


@pytest.fixture(scope="module")
def plan_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    plan = tmp_path_factory.mktemp("plan") / "toppra.csv"  # a clean plan: evaluate exits 0
    so.plan(so.load_problem(PAPER_PROBLEM), "toppra").to_csv(plan)
    return plan


def _run_without_compiler(command: list[str], tmp_path: Path) -> subprocess.CompletedProcess:
    """``command`` in ``tmp_path`` with no C compiler to be found (an empty PATH, no CC)."""
    empty = tmp_path / "bin"
    empty.mkdir()
    env = {key: value for key, value in os.environ.items() if key != "CC"}
    return subprocess.run(
        command,
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
        env={**env, "PATH": str(empty)},
        check=False,
    )


def test_no_c_compiler_is_a_warning_on_stderr(tmp_path: Path, plan_csv: Path) -> None:
    command = [sys.executable, "-m", "spm_opt.cli", "evaluate", str(PAPER_PROBLEM), str(plan_csv)]
    result = _run_without_compiler(command, tmp_path)
    assert result.returncode == 0, result.stderr
    warnings = result.stderr.splitlines()
    assert warnings, "the missing compiler was not reported"
    assert all(
        line.startswith("spm-opt: warning: no C compiler: ") and "interpreter" in line
        for line in warnings
    ), result.stderr
    assert result.stdout  # the report


def test_the_library_itself_prints_nothing(tmp_path: Path, plan_csv: Path) -> None:
    """The same warning from Python, with no logging configured: silence (NullHandler)."""
    script = (
        f"import spm_opt as so; p = so.load_problem({str(PAPER_PROBLEM)!r}); "
        f"so.evaluate(p, so.Trajectory.from_csv({str(plan_csv)!r}))"
    )
    result = _run_without_compiler([sys.executable, "-c", script], tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""


@pytest.fixture
def chatty_evaluator(monkeypatch: pytest.MonkeyPatch) -> None:
    """The evaluator, logging one line at each level before it measures."""
    evaluate = EVALUATOR.evaluate

    def chatty(problem, trajectory, **options):  # noqa: ANN001, ANN003, ANN202
        log = logging.getLogger("spm_opt.judge.evaluate")
        log.debug("debug line")
        log.info("info line")
        log.warning("warning line")
        return evaluate(problem, trajectory, **options)

    monkeypatch.setattr(EVALUATOR, "evaluate", chatty)


@pytest.mark.parametrize(
    ("before", "after", "shown"),
    [
        ([], [], ["warning"]),
        (["-v"], [], ["info", "warning"]),
        ([], ["-v"], ["info", "warning"]),
        (["-vv"], [], ["debug", "info", "warning"]),
    ],
    ids=["default", "-v before", "-v after", "-vv"],
)
def test_verbosity_chooses_the_levels_shown(
    before: list[str],
    after: list[str],
    shown: list[str],
    plan_csv: Path,
    chatty_evaluator: None,
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = [*before, "evaluate", str(PAPER_PROBLEM), str(plan_csv), *after]
    assert main(argv) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if line.endswith(" line")]
    assert lines == [f"spm-opt: {level}: {level} line" for level in shown]


def test_main_leaves_the_library_silent_again(plan_csv: Path, chatty_evaluator: None) -> None:
    logger = logging.getLogger("spm_opt")
    handlers, level = list(logger.handlers), logger.level
    assert main(["-v", "evaluate", str(PAPER_PROBLEM), str(plan_csv)]) == 0
    assert logger.handlers == handlers and logger.level == level
