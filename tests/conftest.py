"""Shared fixtures: the paper's problem and its cubic baseline."""

from pathlib import Path

import pytest

import spm_opt as so

ROOT = Path(__file__).resolve().parents[1]
PAPER_PROBLEM = ROOT / "problems" / "craniotomy_bone_flap.toml"


@pytest.fixture(scope="session")
def paper_problem() -> so.Problem:
    return so.load_problem(PAPER_PROBLEM)


@pytest.fixture(scope="session")
def baseline(paper_problem: so.Problem) -> so.Trajectory:
    return so.plan(paper_problem, "cubic")
