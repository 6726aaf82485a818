"""The command line's conventions a script relies on: exit statuses, output folders
checked before any work, --version and help texts that state defaults."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest
from test_bad_inputs import assert_one_error, run_cli

from spm_opt.base.errors import PlanningError
from spm_opt.base.version import package_version
from spm_opt.cli.parser import EXIT_STATUSES, build_parser
from spm_opt.planners import PLANNERS

ROOT = Path(__file__).resolve().parents[1]
PAPER = str(ROOT / "problems" / "craniotomy_bone_flap.toml")


class _Refusing:
    """A planner that always fails, and counts its calls."""

    name = "refuses"
    calls = 0

    def plan(self, problem):
        type(self).calls += 1
        raise PlanningError("refuses: never plans")


@pytest.fixture
def refusing(monkeypatch: pytest.MonkeyPatch) -> type[_Refusing]:
    _Refusing.calls = 0
    monkeypatch.setitem(PLANNERS, _Refusing.name, _Refusing())
    return _Refusing


def _options(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.Action]]:
    """Every option of every sub-command, by command name."""
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    found = [("spm-opt", action) for action in parser._actions]
    for name, sub in commands.choices.items():
        found += [(name, action) for action in sub._actions]
    return found


def test_version_names_the_installed_package(capsys: pytest.CaptureFixture[str]) -> None:
    status, _ = run_cli(["--version"])
    assert status == 0
    assert capsys.readouterr().out.strip() == f"spm-opt {package_version()}"


def test_every_optional_value_states_its_default_and_help_is_plain_text() -> None:
    parser = build_parser()
    for command, action in _options(parser):
        help_text = action.help or ""
        assert "``" not in help_text, f"{command} {action.option_strings}: RST in help"
        if not action.option_strings or action.required:
            continue
        if isinstance(action, argparse._HelpAction | argparse._VersionAction):
            continue
        assert help_text, f"{command} {action.option_strings}: no help"
        if isinstance(action, argparse._CountAction):
            continue
        stated = "default" in help_text or "required" in help_text
        assert stated, f"{command} {action.option_strings}: neither a default nor required"
    top = parser.format_help()
    assert "``" not in top
    for status in EXIT_STATUSES:
        assert re.search(rf"^\s+{status}\s", top, re.MULTILINE), f"exit status {status} missing"


def _plan(tmp_path: Path, planner: str) -> Path:
    out = tmp_path / f"{planner}.csv"
    assert run_cli(["plan", PAPER, "--planner", planner, "--out", str(out)])[0] == 0
    return out


def test_evaluate_exits_1_when_the_plan_breaks_a_limit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cubic = _plan(tmp_path, "cubic")  # the paper's plan: too fast, off the contour
    capsys.readouterr()
    status, _ = run_cli(["evaluate", PAPER, str(cubic)])
    captured = capsys.readouterr()
    assert status == 1
    assert "tool speed" in captured.out  # the report is printed all the same
    (line,) = captured.err.strip().splitlines()
    assert re.match(r"spm-opt: the planned cut: \d+ violations \(.*tool speed.*\)$", line), line


def test_evaluate_exits_0_on_a_clean_plan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    toppra = _plan(tmp_path, "toppra")
    capsys.readouterr()
    status, _ = run_cli(["evaluate", PAPER, str(toppra), "--json"])
    assert status == 0
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize(
    "out",
    [
        pytest.param("afile/sub", id="under-a-file"),
        pytest.param("afile", id="a-file"),
        pytest.param("/proc/spm-opt/sub", id="read-only"),  # read-only even for root
    ],
)
def test_compare_checks_its_folder_before_planning(
    out: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    refusing: type[_Refusing],
) -> None:
    (tmp_path / "afile").write_text("not a folder", encoding="utf-8")
    folder = out if out.startswith("/") else str(tmp_path / out)
    status, shown = run_cli(["compare", PAPER, "--planners", "refuses", "--out", folder])
    assert_one_error(status, capsys.readouterr().err, ("--out",), tmp_path, shown)
    assert refusing.calls == 0
    assert not list(tmp_path.glob("afile*/**/*"))


@pytest.mark.parametrize(
    ("command", "option"),
    [
        (["plan", PAPER, "--out", "{folder}/plan.csv"], "--out"),
        (["reproduce", "--problem", PAPER, "--out", "{folder}"], "--out"),
        (["identify", "x.csv", "--problem", PAPER, "--out", "{folder}/robot.toml"], "--out"),
        (
            ["execute", "x.csv", "--problem", PAPER, "--backend", "sim", "--log", "{folder}/r.csv"],
            "--log",
        ),
        (["sweep", "x.toml", "--out", "{folder}"], "--out"),
    ],
)
def test_every_output_is_checked_first(
    command: list[str], option: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "afile").write_text("not a folder", encoding="utf-8")
    folder = str(tmp_path / "afile" / "sub")
    status, shown = run_cli([part.replace("{folder}", folder) for part in command])
    assert_one_error(status, capsys.readouterr().err, (option, "afile"), tmp_path, shown)


def test_plan_exits_1_when_the_planner_fails(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], refusing: type[_Refusing]
) -> None:
    out = tmp_path / "plan.csv"
    status, _ = run_cli(["plan", PAPER, "--planner", "refuses", "--out", str(out)])
    assert status == 1
    assert capsys.readouterr().err == "spm-opt: failed: refuses: never plans\n"
    assert list(tmp_path.iterdir()) == []
