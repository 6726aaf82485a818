"""Shared fixtures: the paper's problem and its cubic baseline, and the faster run of the
hardware verification (Section 6) with its cubic plan."""

from pathlib import Path

import pytest

import spm_opt as so

ROOT = Path(__file__).resolve().parents[1]
PAPER_PROBLEM = ROOT / "problems" / "craniotomy_bone_flap.toml"
HARDWARE_PROBLEM = ROOT / "problems" / "craniotomy_hardware.toml"


@pytest.fixture(scope="session")
def paper_problem() -> so.Problem:
    return so.load_problem(PAPER_PROBLEM)


@pytest.fixture(scope="session")
def baseline(paper_problem: so.Problem) -> so.Trajectory:
    return so.plan(paper_problem, "cubic")


@pytest.fixture(scope="session")
def hardware_problem() -> so.Problem:
    return so.load_problem(HARDWARE_PROBLEM)


@pytest.fixture(scope="session")
def hardware_plan(hardware_problem: so.Problem) -> so.Trajectory:
    return so.plan(hardware_problem, "cubic")
