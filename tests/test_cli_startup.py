"""The command line starts fast and explains itself: its help and version import none of
the heavy modules, the names its parser offers are the library's, every command says what
it does, and an unknown planner's name gets a suggestion."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_bad_inputs import assert_one_error, run_cli

from spm_opt.base import choices
from spm_opt.cli.parser import build_parser
from spm_opt.execution import ExecutionSettings
from spm_opt.execution.tracking import TRACKING_MODES
from spm_opt.planners import PLANNERS, contour_planners

ROOT = Path(__file__).resolve().parents[1]
PAPER = str(ROOT / "problems" / "craniotomy_bone_flap.toml")
HEAVY = (
    "numpy",
    "scipy",
    "casadi",
    "pandas",
    "matplotlib",
    "trimesh",
    "toppra",
    "ruckig",
    "dask",
    "distributed",
    "plotly",
    "mujoco",
)
"""Packages only the commands that need them may import (numpy too: the parser needs none)."""
_IMPORTED = """\
import contextlib, io, json, sys
from spm_opt.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        status = main(sys.argv[1:])
    except SystemExit as exit_:
        status = exit_.code
print(json.dumps({"status": status, "modules": sorted(sys.modules)}))
"""


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def command_summaries() -> dict[str, str]:
    """Each command's line in ``spm-opt --help``, by name."""
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {choice.dest: choice.help for choice in action._choices_actions}


@pytest.mark.parametrize(
    "argv",
    [["--help"], ["--version"], *([name, "--help"] for name in _commands())],
    ids="_".join,
)
def test_help_and_version_import_no_heavy_module(argv: list[str]) -> None:
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", _IMPORTED, *argv],
        cwd=ROOT,
        env=environment,
        capture_output=True,
        text=True,
        check=True,
    )
    imported = json.loads(done.stdout)
    assert imported["status"] == 0, done.stderr
    heavy = sorted({m.split(".")[0] for m in imported["modules"]} & set(HEAVY))
    assert not heavy, f"spm-opt {' '.join(argv)} imports {heavy}"


def test_the_parsers_names_are_the_librarys() -> None:
    assert choices.PLANNER_NAMES == tuple(sorted(PLANNERS))
    assert choices.CONTOUR_PLANNER_NAMES == tuple(contour_planners())
    assert TRACKING_MODES is choices.TRACKING_MODES


@pytest.mark.parametrize("name", sorted(_commands()))
def test_each_command_says_what_it_does(name: str) -> None:
    """Its line in ``spm-opt --help`` is a phrase, and ``spm-opt NAME --help`` opens with it
    as a sentence and goes on."""
    summary, description = command_summaries()[name], _commands()[name].description
    assert summary and summary[0].islower() and not summary.endswith("."), summary
    opening = f"{summary[0].upper()}{summary[1:]}. "
    assert description.startswith(opening) and len(description) > len(opening), description


def test_compare_names_the_planners_it_leaves_out() -> None:
    left_out = sorted(set(PLANNERS) - set(contour_planners()))
    assert left_out, "every planner cuts: the help's 'every planner but' is wrong"
    texts = [command_summaries()["compare"], _commands()["compare"].description]
    planners = next(a for a in _commands()["compare"]._actions if a.dest == "planners")
    for text in [*texts, planners.help]:
        assert all(name in text for name in left_out), text


def test_execute_rate_range_in_its_help_is_the_settings() -> None:
    action = next(a for a in _commands()["execute"]._actions if a.dest == "rate")
    low, high = (float(v) for v in re.search(r"(\S+) <= HZ <= (\S+) ", action.help).groups())
    for rate in (low, high):
        assert ExecutionSettings(rate_hz=rate).rate_hz == rate
    for rate in (low * 0.999, high * 1.001):
        with pytest.raises(ValueError, match="rate_hz"):
            ExecutionSettings(rate_hz=rate)
    assert "plan --rate" in action.help
    plan_rate = next(a for a in _commands()["plan"]._actions if a.dest == "rate")
    assert "execute" in plan_rate.help


@pytest.mark.parametrize(
    ("argv", "suggested"),
    [
        (["plan", PAPER, "--planner", "toppr"], "toppra"),
        (["plan", PAPER, "--planner", "ocp-min-tme"], "ocp-min-time"),
        (["compare", PAPER, "--planners", "cubic,rukig"], "ruckig"),
    ],
)
def test_an_unknown_planner_gets_the_closest_name(
    argv: list[str],
    suggested: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / ("plan.csv" if argv[0] == "plan" else "compared")
    status, shown = run_cli([*argv, "--out", str(out)])
    stderr = capsys.readouterr().err
    expected = (f"did you mean '{suggested}'?", "expected one of")
    assert_one_error(status, stderr, expected, tmp_path, shown)
    assert not out.exists()


def test_a_name_like_no_planner_gets_no_suggestion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    status, _ = run_cli(["plan", PAPER, "--planner", "zzz", "--out", str(tmp_path / "p.csv")])
    stderr = capsys.readouterr().err
    assert_one_error(status, stderr, ("planner = 'zzz': unknown; expected one of",), tmp_path)
