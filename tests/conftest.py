"""Shared fixtures: the paper's problem and its cubic baseline, the faster run of the
hardware verification (Section 6) with its cubic plan, and the check of every figure a
test saves; experiments/ scripts as modules."""

import importlib.util
import signal
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

import spm_opt as so

ROOT = Path(__file__).resolve().parents[1]
PAPER_PROBLEM = ROOT / "problems" / "craniotomy_bone_flap.toml"
HARDWARE_PROBLEM = ROOT / "problems" / "craniotomy_hardware.toml"


def experiment_module(name: str) -> ModuleType:
    """experiments/<name>.py as a module."""
    spec = importlib.util.spec_from_file_location(
        f"experiment_{name}", ROOT / "experiments" / f"{name}.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def pytest_configure(config: pytest.Config) -> None:
    """The tests of Ctrl-C need SIGINT to reach this process and those it starts: a run
    started in the background by a shell, which ignores SIGINT there (and so would every
    process it starts), gets Python's own handler back."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Tests marked ``real_time`` share one xdist group: they run one at a time (each still
    beside other tests, as on a busy machine, which they must bear)."""
    for item in items:
        if item.get_closest_marker("real_time") is not None:
            item.add_marker(pytest.mark.xdist_group("real time"))


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


@pytest.fixture(scope="session", autouse=True)
def saved_figures_keep_the_rules() -> Iterator[None]:
    """Every figure a test saves is first checked by :func:`spm_opt.report.figure_rules.
    figure_faults` (units, titles, legends clear of the data, the anterior on top views):
    a figure that breaks a rule fails the test, its faults listed."""
    from matplotlib.figure import Figure

    from spm_opt.report.figure_rules import figure_faults

    save = Figure.savefig

    def checked(figure: Figure, *args: Any, **kwargs: Any) -> Any:
        faults = figure_faults(figure)
        if faults:
            pytest.fail("a saved figure breaks the figure rules:\n" + "\n".join(faults))
        return save(figure, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Figure, "savefig", checked)
        yield
