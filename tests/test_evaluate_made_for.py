"""`evaluate` of a plan file checks what the plan was made for, as `execute` and `review` do."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import HARDWARE_PROBLEM
from test_bad_inputs import run_cli

import spm_opt as so
from spm_opt.base.errors import InputError

PAPER = Path(__file__).parents[1] / "problems" / "craniotomy_bone_flap.toml"


@pytest.fixture(scope="module")
def paper_plan(tmp_path_factory) -> Path:
    """The paper's cubic plan of its own flap, as `spm-opt plan` writes it."""
    out = tmp_path_factory.mktemp("plan") / "cubic.csv"
    assert run_cli(["plan", str(PAPER), "--planner", "cubic", "--out", str(out)])[0] == 0
    return out


def test_a_plan_judged_under_another_problem_is_refused_in_one_line(paper_plan, capsys):
    status, _ = run_cli(["evaluate", str(HARDWARE_PROBLEM), str(paper_plan)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1
    assert f"plan {paper_plan} refused: the plan was made for craniotomy_bone_flap" in err
    assert "not for craniotomy_hardware" in err and "--other-problem" in err


def test_other_problem_judges_it_with_a_warning_and_the_verdict_of_that_problems_limits(
    paper_plan, capsys
):
    status, _ = run_cli(
        ["evaluate", str(HARDWARE_PROBLEM), str(paper_plan), "--other-problem", "--json"]
    )
    captured = capsys.readouterr()
    warning = captured.err.splitlines()[0]
    assert warning.startswith("spm-opt: warning: plan ")
    assert "judged under craniotomy_hardware's limits as asked" in warning
    shown = json.loads(captured.out)
    # the same plan object judged under the other problem, in code (no check there)
    expected = so.evaluate(so.load_problem(HARDWARE_PROBLEM), so.Trajectory.from_csv(paper_plan))
    assert shown["violations"] == expected.to_dict()["violations"]
    assert status == (1 if expected.violations else 0)


def test_its_own_problem_judges_it_without_a_word(paper_plan, capsys):
    run_cli(["evaluate", str(PAPER), str(paper_plan)])
    assert "warning" not in capsys.readouterr().err


def test_the_library_checks_a_plan_file_but_judges_a_trajectory_object_as_given(paper_plan):
    hardware = so.load_problem(HARDWARE_PROBLEM)
    with pytest.raises(InputError, match="made for craniotomy_bone_flap"):
        so.evaluate(hardware, paper_plan)
    so.evaluate(hardware, paper_plan, other_problem=True)
    so.evaluate(hardware, so.Trajectory.from_csv(paper_plan))
