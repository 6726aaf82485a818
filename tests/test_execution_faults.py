"""Every injected fault ends in a safe stop at rest, with the log up to the fault: the
executor, the Dynamixel backend on the real SDK, and the emulator on a pseudo-terminal."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import HARDWARE_PROBLEM

import spm_opt as so
from spm_opt.execution import ExecutionSettings, execute, read_log
from spm_opt.execution.dynamixel import DynamixelRobot
from spm_opt.execution.emulator import (
    CorruptReplies,
    DropReplies,
    Faults,
    Overload,
    StuckEncoder,
    spawn_emulator,
)

DEG = np.pi / 180.0
FAULT_AT_S = 1.0


@pytest.fixture(scope="module")
def short_move() -> so.Trajectory:
    """A 3 s quintic move from rest at (0, 0) to rest at (6, −4) deg."""
    t = np.linspace(0.0, 3.0, 301)
    tau = t / 3.0
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    ds = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / 3.0
    dds = (60 * tau - 180 * tau**2 + 120 * tau**3) / 9.0
    span = np.array([6.0, -4.0]) * DEG
    return so.Trajectory.from_samples(
        t, s[:, None] * span, ds[:, None] * span, dds[:, None] * span, {"planner": "test"}
    )


def _run(problem, trajectory, faults, tmp_path):
    with spawn_emulator(problem_file=HARDWARE_PROBLEM, faults=faults) as emulator:
        backend = DynamixelRobot(problem.robot.actuator, emulator.device)
        result = execute(trajectory, backend, problem, tmp_path / "run.csv", ExecutionSettings())
    table, header = read_log(tmp_path / "run.csv")
    return result, table, header


def _ended_in_a_safe_stop(result, table, header) -> None:
    assert not result.completed and result.at_rest, result.reason
    assert header["reason"] == result.reason and header["at_rest"]
    phases = table["phase"].tolist()
    stop = phases.index("stop")
    assert set(phases[stop:]) <= {"stop", "hold"} and phases[-1] == "hold"
    plan = table.iloc[:stop]
    # every sample up to the fault is in the log, one per control period
    assert plan["time_s"].iloc[-1] - plan["time_s"].iloc[0] >= FAULT_AT_S - 0.05
    assert len(plan) >= 0.8 * 100 * FAULT_AT_S
    last = table.iloc[-1]
    assert abs(last["velocity_theta1_rad_s"]) < 0.005
    assert abs(last["velocity_theta2_rad_s"]) < 0.005


def test_the_move_completes_through_the_sdk_and_the_emulator(
    hardware_problem, short_move, tmp_path
):
    result, table, header = _run(hardware_problem, short_move, Faults(), tmp_path)
    assert result.completed and result.at_rest
    assert header["backend"]["backend"] == "dynamixel"
    plan = table[table["phase"] == "plan"]
    t = plan["time_s"].to_numpy() - plan["time_s"].iloc[0]
    measured = plan[["position_theta1_rad", "position_theta2_rad"]].to_numpy()
    assert np.max(np.abs(measured - short_move.position(t))) < 0.5 * DEG
    assert result.statistics.achieved_rate_hz == pytest.approx(100.0, rel=0.02)


@pytest.mark.parametrize(
    ("faults", "reason"),
    [
        (Faults(drop=DropReplies(at=FAULT_AT_S, count=40)), "communication lost"),
        (Faults(crc=CorruptReplies(at=FAULT_AT_S, count=40)), "communication lost"),
        (
            Faults(overload=(Overload(id=1, at=FAULT_AT_S),)),
            "hardware error on actuator 1: overload",
        ),
        (Faults(stuck=(StuckEncoder(id=2, at=FAULT_AT_S),)), "following error of theta2"),
    ],
    ids=["dropped replies", "bad crc", "overload", "stuck encoder"],
)
def test_each_fault_ends_in_a_safe_stop_at_rest(
    hardware_problem, short_move, tmp_path, faults, reason
):
    result, table, header = _run(hardware_problem, short_move, faults, tmp_path)
    assert result.reason.startswith(reason), result.reason
    _ended_in_a_safe_stop(result, table, header)
