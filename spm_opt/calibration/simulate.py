"""A calibration run on the simulated robot, watched by the simulated tracker: what
``spm-opt calibrate`` does without a lab, and what the tests calibrate robots the model
does not know with."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from spm_opt.base.errors import InputError
from spm_opt.calibration.run import uncalibrated
from spm_opt.calibration.simulated_tracker import SimulatedTracker
from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot
from spm_opt.execution.log import read_execution_log
from spm_opt.model.params import Robot
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory


def simulated_run(
    problem: Problem,
    plan: Trajectory,
    plant: Robot,
    tracker: SimulatedTracker,
    log_path: Path,
) -> tuple[pd.DataFrame, dict, str]:
    """Run ``plan`` through the one executor on the simulated ``plant`` (from rest at
    θ = 0, with an approach move), under ``problem``'s robot as its encoders read; the
    log's rows and header, and the tracker's CSV text of the run.

    Raises
    ------
    InputError
        If the executor refuses the plan (a PreflightError), or the run ends in a safe stop
        (naming why).
    """
    backend = SimulatedRobot(problem.robot, plant_robot=plant)
    executor = Executor(uncalibrated(problem), backend, ExecutionSettings(approach=True))
    result = executor.run(plan, log_path)
    table, header = read_execution_log(log_path)
    if not result.succeeded:
        raise InputError(f"calibration run {log_path}: ended in a safe stop ({result.reason})")
    trace = backend.trace.arrays(header["clock_origin_s"])
    return table, header, tracker.csv_text(trace)
