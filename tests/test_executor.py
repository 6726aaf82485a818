"""The executor on the simulated robot: a full run, refusals, safe stops and the log."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest
from conftest import HARDWARE_PROBLEM
from test_execution_faults import assert_the_commanded_stop_kept_its_limits, stop_bound

import spm_opt as so
from spm_opt.base.errors import PreflightError
from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot, execute, read_log
from spm_opt.execution.log import COLUMNS
from spm_opt.execution.results import LoopStatistics

pytestmark = pytest.mark.real_time

DEG = np.pi / 180.0


@pytest.fixture(scope="module")
def completed_run(hardware_problem, hardware_plan, tmp_path_factory):
    log = tmp_path_factory.mktemp("run") / "run.csv"
    backend = SimulatedRobot(hardware_problem.robot, start_rad=hardware_plan.position(0.0))
    result = execute(hardware_plan, backend, hardware_problem, log)
    return result, *read_log(log)


def test_the_faster_craniotomy_runs_to_completion_and_tracks_the_plan(completed_run, hardware_plan):
    result, table, header = completed_run
    assert result.completed and result.at_rest and header["completed"]
    plan = table[table["phase"] == "plan"]
    assert len(plan) == pytest.approx(hardware_plan.duration * 100, abs=2)
    t = plan["time_s"].to_numpy() - plan["time_s"].iloc[0]
    measured = plan[["position_theta1_rad", "position_theta2_rad"]].to_numpy()
    error = np.abs(measured - hardware_plan.position(t))
    # a P position loop lags by rate / gain: at most 0.17 rad/s / 32 1/s = 5.2 mrad, plus
    # the one period between goal and reading; well inside the 1 deg following tolerance
    assert np.max(error) < 0.4 * DEG
    assert result.statistics.achieved_rate_hz == pytest.approx(100.0)


def test_the_log_holds_every_sample_with_torque_from_the_current_map(
    completed_run, hardware_problem
):
    result, table, header = completed_run
    assert list(table.columns) == list(COLUMNS)
    assert len(table) == result.samples == header["samples"]
    assert np.all(np.diff(table["time_s"]) > 0)
    current = table[["current_theta1_a", "current_theta2_a"]].to_numpy()
    torque = table[["torque_theta1_nm", "torque_theta2_nm"]].to_numpy()
    np.testing.assert_allclose(torque, current * 14.0 / 1.9, rtol=1e-6)
    assert header["problem"] == hardware_problem.record()
    assert header["backend"]["backend"] == "simulated"
    assert header["settings"]["rate_hz"] == 100.0
    assert header["plan"]["planner"] == "cubic"


def test_a_plan_that_breaks_a_limit_is_refused_before_anything_is_written(
    paper_problem, baseline, tmp_path
):
    backend = SimulatedRobot(paper_problem.robot, start_rad=baseline.position(0.0))
    with pytest.raises(PreflightError, match="plan refused: theta. acceleration step"):
        execute(baseline, backend, paper_problem, tmp_path / "run.csv")
    assert list(tmp_path.iterdir()) == []


def test_a_robot_away_from_the_start_is_refused_or_approached(
    hardware_problem, hardware_plan, tmp_path
):
    start = hardware_plan.position(0.0) + np.array([3.0, -2.0]) * DEG
    robot = SimulatedRobot(hardware_problem.robot, start_rad=start)
    refusal = r"3\.000 deg away .* ask for an approach move \(spm-opt execute --approach"
    with pytest.raises(PreflightError, match=refusal):
        execute(hardware_plan, robot, hardware_problem, tmp_path / "refused.csv")
    assert not (tmp_path / "refused.csv").exists()

    robot = SimulatedRobot(hardware_problem.robot, start_rad=start)
    settings = ExecutionSettings(approach=True)
    result = execute(hardware_plan, robot, hardware_problem, tmp_path / "run.csv", settings)
    assert result.completed
    table, _ = read_log(tmp_path / "run.csv")
    approach = table[table["phase"] == "approach"]
    goals = approach[["reference_theta1_rad", "reference_theta2_rad"]].to_numpy()
    np.testing.assert_allclose(goals[0], start, atol=1e-5)
    np.testing.assert_allclose(goals[-1], hardware_plan.position(0.0), atol=1e-9)
    speed = np.abs(np.diff(goals, axis=0)) * 100.0
    assert np.max(speed) <= 0.1 + 1e-6  # the approach's speed limit, rad/s


def _stop_is_jerk_limited(table: pd.DataFrame, problem: so.Problem, plan: so.Trajectory) -> None:
    """The stop's goals keep its speed, acceleration and jerk limits (see
    tests/test_execution_faults.py for the bound and the tolerance)."""
    assert_the_commanded_stop_kept_its_limits(table, problem, stop_bound(problem, plan))
    first = int(np.argmax(table["phase"].to_numpy() == "stop"))
    assert np.all(table["phase"].iloc[first:].isin(["stop", "hold"]))


def test_a_following_error_ends_in_a_jerk_limited_stop_at_rest(
    hardware_problem, hardware_plan, tmp_path
):
    robot = SimulatedRobot(hardware_problem.robot, start_rad=hardware_plan.position(0.0))
    tolerance = 0.05 * DEG  # under the unled goals' lag at speed
    settings = ExecutionSettings(
        tracking="none", min_following_error_rad=tolerance, max_following_error_rad=tolerance
    )
    result = execute(hardware_plan, robot, hardware_problem, tmp_path / "run.csv", settings)
    assert not result.completed and result.at_rest
    assert result.reason.startswith("following error of theta")
    table, header = read_log(tmp_path / "run.csv")
    assert header["reason"] == result.reason and header["at_rest"]
    _stop_is_jerk_limited(table, hardware_problem, hardware_plan)
    last = table.iloc[-1]
    assert abs(last["velocity_theta1_rad_s"]) < 0.005 and abs(last["velocity_theta2_rad_s"]) < 0.005


class _SignalledAlongThePlan(SimulatedRobot):
    """The simulated robot on the machine's clock; it sends this process SIGINT once the
    executor's status shows the plan ``at_plan_s`` along (an event, not a timer: a busy
    machine only makes it come later)."""

    executor: Executor
    at_plan_s: float
    sent = False

    def read(self):  # noqa: ANN201 - the backend's
        status = self.executor.status
        if not self.sent and status is not None and status.plan_time_s >= self.at_plan_s:
            self.sent = True
            os.kill(os.getpid(), signal.SIGINT)
        return super().read()


def test_sigint_ends_in_a_safe_stop(hardware_problem, hardware_plan, tmp_path):
    robot = _SignalledAlongThePlan(
        hardware_problem.robot, start_rad=hardware_plan.position(0.0), realtime=True
    )
    robot.executor, robot.at_plan_s = Executor(hardware_problem, robot), 1.5
    result = robot.executor.run(hardware_plan, tmp_path / "run.csv")
    assert result.reason == "interrupted (SIGINT)" and result.at_rest
    table, _ = read_log(tmp_path / "run.csv")
    plan_times = table.loc[table["phase"] == "plan", "plan_time_s"]
    assert 1.5 <= plan_times.max() < 0.5 * hardware_plan.duration
    _stop_is_jerk_limited(table, hardware_problem, hardware_plan)


def test_kill_9_leaves_a_valid_log_of_every_flushed_sample(hardware_plan, tmp_path):
    plan = tmp_path / "plan.csv"
    hardware_plan.to_csv(plan)
    log = tmp_path / "run.csv"
    command = [sys.executable, "-m", "spm_opt.cli", "execute", str(plan)]
    command += ["--problem", str(HARDWARE_PROBLEM), "--backend", "sim", "--realtime"]
    command += ["--rate", "250", "--log", str(log)]
    process = subprocess.Popen(command, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not log.exists() or log.stat().st_size < 20_000):
        time.sleep(0.05)
    flushed = log.read_bytes().count(b"\n") - 1  # samples on the disk, whenever that is
    process.send_signal(signal.SIGKILL)
    process.wait()
    text = log.read_text()
    assert text.endswith("\n")
    table = pd.read_csv(log)
    assert list(table.columns) == list(COLUMNS)
    # every line whole, every cell there (the pace's only in the plan phase)
    pace = ["plan_time_s", "feed", "feed_target"]
    assert table.drop(columns=pace).notna().all().all()
    assert table.loc[table["phase"] == "plan"].notna().all().all()
    assert len(table) >= flushed > 50
    assert np.all(np.diff(table["time_s"]) > 0)
    header = json.loads(log.with_suffix(".json").read_text())
    assert "completed" not in header  # the run never ended: the header is the start one


def test_loop_statistics_from_tick_times():
    ticks = [0.0, 0.01, 0.021, 0.03, 0.05, 0.06]
    stats = LoopStatistics.from_ticks(ticks, 0.01)
    assert stats.cycles == 6 and stats.overruns == 1
    assert stats.achieved_rate_hz == pytest.approx(5 / 0.06)
    assert stats.period_error_max_ms == pytest.approx(10.0)


def test_bad_settings_are_one_line_errors():
    with pytest.raises(so.InputError, match=r"rate_hz = 0: expected a number in \[1.0, 2000.0\]"):
        ExecutionSettings(rate_hz=0)
    with pytest.raises(so.InputError, match="min_following_error_rad = nan"):
        ExecutionSettings(min_following_error_rad=float("nan"))
    with pytest.raises(so.InputError, match="tracking = 'ahead': expected one of lead, none"):
        ExecutionSettings(tracking="ahead")
