"""The experiment scripts under faults: a signal that stops one of a study's runs ends the
study (the next run never starts), a connection that fails before anything moves is made
again, and a bad input is one line with status 2 and nothing written."""

import contextlib
import dataclasses
import os
import signal
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest
from conftest import experiment_module

import spm_opt as so
from spm_opt.base.errors import CommunicationError
from spm_opt.cli.run import run_script

ROOT = Path(__file__).resolve().parents[1]
STUDY = ["--backend", "sim", "--problems", "craniotomy_hardware", "--planners", "toppra"]


class _Plant(so.SimulatedRobot):
    """The study's simulated robot, but for a SIGTERM to this process at its 200th read,
    2 s into the run, in the plan (``signal_in_plan``), or a connection that fails
    (``refuse``)."""

    def __init__(self, *args, signal_in_plan=False, refuse=False, **kwargs):
        super().__init__(*args, **kwargs)
        self.signal_in_plan, self.refuse, self.reads = signal_in_plan, refuse, 0

    def connect(self) -> None:
        if self.refuse:
            raise CommunicationError("read: no status packet (scripted)")
        super().connect()

    def read(self):
        self.reads += 1
        if self.signal_in_plan and self.reads == 200:
            os.kill(os.getpid(), signal.SIGTERM)
        return super().read()


@dataclasses.dataclass
class _Study:
    """experiments/executed_cut.py (``module``) with its backends replaced by the
    :class:`_Plant` s :meth:`plants` makes, each kept in ``made``."""

    module: ModuleType
    monkeypatch: pytest.MonkeyPatch
    made: list = dataclasses.field(default_factory=list)

    def plants(self, options) -> None:
        """Give the n-th run made a :class:`_Plant` with ``options(n)`` (keywords)."""

        @contextlib.contextmanager
        def scripted(kind, problem, plan, plant, trace):
            start = plan.position(plan.start_time)
            robot = _Plant(
                problem.robot, start_rad=start, plant_robot=plant, **options(len(self.made))
            )
            self.made.append(robot)
            yield robot
            robot.trace.save(trace)

        self.monkeypatch.setattr(self.module, "_backend", scripted)


@pytest.fixture
def study(monkeypatch, tmp_path):
    monkeypatch.setattr(sys, "argv", ["executed_cut.py", "--out", str(tmp_path / "out"), *STUDY])
    return _Study(experiment_module("executed_cut"), monkeypatch)


def test_a_sigterm_that_stops_a_run_of_the_study_ends_the_study(study, tmp_path, capfd):
    study.plants(lambda index: {"signal_in_plan": index == 0})
    status = run_script(study.module.main)
    assert status == 128 + signal.SIGTERM
    assert len(study.made) == 1  # the next run never started
    line = capfd.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("executed_cut.py: stopped: SIGTERM during plan: the run ended in")
    assert not (tmp_path / "out" / "executed_cut.md").exists()


def test_a_connection_that_fails_before_anything_moves_is_made_again(study, tmp_path):
    study.plants(lambda index: {"refuse": index in (0, 2, 3)})
    assert run_script(study.module.main) == 0
    refused = [robot.refuse for robot in study.made]
    assert refused[:5] == [True, False, True, True, False]  # the second run: three tries
    assert (tmp_path / "out" / "executed_cut.md").exists()


def test_a_connection_that_keeps_failing_ends_the_study_in_one_line(study, capfd):
    study.plants(lambda index: {"refuse": True})
    assert run_script(study.module.main) == 2
    assert len(study.made) == study.module.CONNECT_TRIES
    line = capfd.readouterr().err.strip().splitlines()[-1]
    assert line == "executed_cut.py: error: read: no status packet (scripted)"


@pytest.mark.parametrize(
    ("script", "arguments", "message"),
    [
        ("executed_cut", ["--lab-robot", "missing.toml"], "error: missing.toml: no such file"),
        ("executed_cut", ["--planners", "toppra,nosuch"], "--planners toppra,nosuch: unknown"),
        ("compensated_cut", ["--part", "2/2"], "--part 2/2: expected k/n, whole numbers"),
        ("compensated_cut", ["--speed-mm-s", "4,fast"], "--speed-mm-s 4,fast: expected"),
        ("compensated_cut", ["--merge"], "--merge: no compensated_cut.part*.json in"),
    ],
)
def test_a_bad_input_to_a_study_is_one_line_and_writes_nothing(
    tmp_path, script, arguments, message
):
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / f"{script}.py"), "--out", str(out)] + arguments,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        cwd=tmp_path,
    )
    assert result.returncode == 2, result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith(f"{script}.py: ") and message in last, last
    assert "Traceback" not in result.stderr
    assert not out.exists()
