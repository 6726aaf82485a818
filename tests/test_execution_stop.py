"""The stop, on the simulated robot in simulated time: failed writes stop the run and never
advance the goal; rest is proven over a window, not assumed; the hold goes on through
failed reads, hardware errors and signals, and says plainly when rest is not proven."""

from __future__ import annotations

import re
import signal

import numpy as np
import pandas as pd
import pytest
from test_execution_faults import (
    FAULT_AT_S,
    GOALS,
    PERIOD_S,
    SETTINGS,
    ScriptedRobot,
    assert_the_commanded_stop_kept_its_limits,
    short_move,
    stop_bound,
)

import spm_opt as so
from spm_opt.execution import ExecutionSettings, execute, read_log

DEG = np.pi / 180.0


@pytest.fixture(scope="module")
def move(hardware_problem: so.Problem) -> so.Trajectory:
    return short_move(hardware_problem)


def _between(start: float, end: float):  # noqa: ANN202
    return lambda t: start <= t < end


def _run(problem, move, tmp_path, settings=SETTINGS, **script):
    robot = ScriptedRobot(problem.robot, move.position(0.0), **script)
    result = execute(move, robot, problem, tmp_path / "run.csv", settings)
    table, header = read_log(tmp_path / "run.csv")
    return result, table, header, robot


# ------------------------------------------------------------------ failed writes
def test_failed_writes_stop_the_run_and_the_stop_starts_from_the_last_goal_received(
    hardware_problem, move, tmp_path
):
    """Writes fail for 0.1 s from 1 s on (reads succeed): the fourth failed cycle in a row
    is past the retry budget of 3; no failed goal ever becomes the commanded state, so the
    plant's goal is the log's at every cycle, and the stop continues the goals received."""
    result, table, header, robot = _run(
        hardware_problem, move, tmp_path, write_fails=_between(FAULT_AT_S, FAULT_AT_S + 0.1)
    )
    assert result.reason.startswith("communication lost: 4 cycles in a row"), result.reason
    assert "write failed: scripted write failure" in result.reason
    failed = table["status"].str.contains("write failed").to_numpy()
    seen = header["stop"]["fault_seen_s"]
    fault = int(np.argmin(np.abs(table["time_s"].to_numpy() - seen)))
    assert table["time_s"].iloc[fault] == pytest.approx(FAULT_AT_S + 3 * PERIOD_S)
    assert failed[fault - 3 : fault + 1].all() and not failed[: fault - 3].any()
    # the plant's goal, read after each cycle's write, is the goal logged for the cycle
    # (the trace's first two rows are the executor's readings before the loop: on
    # connecting, and the one the loop starts from)
    trace = robot.trace.arrays()
    np.testing.assert_allclose(trace["time_s"][2:], table["time_s"], atol=1e-9)
    pulse = 2 * np.pi / hardware_problem.robot.actuator.pulses_per_rev
    logged = table[GOALS].to_numpy()
    np.testing.assert_allclose(trace["goal_rad"][2:], logged, atol=pulse / 2)
    np.testing.assert_array_equal(logged[fault], logged[fault - 4])  # nothing got through
    # the stop waited for the line: 6 more failed writes, then its whole profile
    assert header["stop"]["failed_writes"] == 6 and header["stop"]["stop_delivered"]
    assert_the_commanded_stop_kept_its_limits(
        table, hardware_problem, stop_bound(hardware_problem, move)
    )
    assert header["stop"]["at_rest"]


class _WriteRecorder(ScriptedRobot):
    """The scripted robot, noting each goal written and when (the simulated clock, s)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)
        self.writes: list[tuple[float, np.ndarray]] = []

    def write_goal(self, position_rad: np.ndarray) -> None:
        super().write_goal(position_rad)
        self.writes.append((self.clock.now(), np.array(position_rad, dtype=float)))


def test_a_fault_a_reading_shows_replaces_its_cycles_goal_with_the_stops_first(
    hardware_problem, move, tmp_path
):
    """The goal goes out before the read: when the reading shows a hardware error, the
    cycle writes the stop's first goal at once in its place, and the stop begins from the
    goal before, one period along, as if the plan's goal had never gone out."""
    robot = _WriteRecorder(
        hardware_problem.robot, move.position(0.0), hardware_error=(FAULT_AT_S, 1 << 2)
    )
    result = execute(move, robot, hardware_problem, tmp_path / "run.csv", SETTINGS)
    assert result.reason == "hardware error on actuator 2: overheating", result.reason
    table, header = read_log(tmp_path / "run.csv")
    seen = header["stop"]["fault_seen_s"]
    fault = int(np.argmin(np.abs(table["time_s"].to_numpy() - seen)))
    assert table["phase"].iloc[fault] == "stop" and table["phase"].iloc[fault - 1] == "plan"
    # two writes at the fault cycle's instant: the plan's goal, then the stop's first
    origin = header["clock_origin_s"]
    at_fault = [goal for time, goal in robot.writes if abs(time - origin - seen) < 1e-9]
    assert len(at_fault) == 2
    plan_goal, stop_goal = at_fault
    np.testing.assert_allclose(stop_goal, table[GOALS].iloc[fault].to_numpy(), atol=1e-9)
    assert np.max(np.abs(plan_goal - stop_goal)) > 0.0
    # the stop's first reference is one period along from the row before's, not two: it
    # begins from the goal before the replaced one (its rate and acceleration carried)
    references = table[["reference_theta1_rad", "reference_theta2_rad"]].to_numpy()
    rates = np.gradient(references[:fault], table["time_s"].to_numpy()[:fault], axis=0)
    step = references[fault] - references[fault - 1]
    np.testing.assert_allclose(step, rates[fault - 1] * PERIOD_S, atol=0.05 * np.max(np.abs(step)))
    assert_the_commanded_stop_kept_its_limits(
        table, hardware_problem, stop_bound(hardware_problem, move)
    )


def test_alternating_read_and_write_failures_are_one_run_of_failures(
    hardware_problem, move, tmp_path
):
    """From 1 s on, every cycle loses either its read or its write: each cycle fails, so
    the run stops after the retry budget, as if every read had failed."""

    def cycle(t: float) -> int:
        return round(t / PERIOD_S)

    result, table, header, _ = _run(
        hardware_problem,
        move,
        tmp_path,
        read_fails=lambda t: t >= FAULT_AT_S and cycle(t) % 2 == 0,
        write_fails=lambda t: t >= FAULT_AT_S and cycle(t) % 2 == 1,
    )
    assert result.reason.startswith("communication lost: 4 cycles in a row"), result.reason
    assert header["stop"]["fault_seen_s"] == pytest.approx(FAULT_AT_S + 3 * PERIOD_S)


# ------------------------------------------------------------------ rest, proven
def test_a_joint_creeping_below_the_rest_speed_is_not_taken_for_at_rest(
    hardware_problem, move, tmp_path
):
    """After a SIGINT, θ2's reading creeps at 4 mrad/s, under the 5 mrad/s rest speed but
    46 pulses per 0.2 s: rest is not confirmed, and the outcome says so and why."""
    result, table, header, _ = _run(
        hardware_problem,
        move,
        tmp_path,
        signals=[(FAULT_AT_S, signal.SIGINT)],
        creep_rad_s=(FAULT_AT_S, 0.004),
    )
    assert result.reason == "interrupted (SIGINT)"
    assert not result.at_rest and not header["at_rest"]
    stop = header["stop"]
    assert not stop["at_rest"] and stop["duration_s"] is None
    assert re.match(
        rf"not confirmed within the {SETTINGS.hold_s:g} s hold: theta2 moved \d+ pulses in 0\.",
        stop["rest"],
    ), stop["rest"]
    hold = table[table["phase"] == "hold"]
    assert hold["time_s"].iloc[-1] - hold["time_s"].iloc[0] == pytest.approx(SETTINGS.hold_s)


def test_rest_needs_the_whole_window(hardware_problem, move, tmp_path):
    """Without creep the same stop confirms rest, but only once samples covering the rest
    window (0.2 s: 21 samples at 100 Hz) are all still; the first still sample is not
    enough."""
    result, table, header, robot = _run(
        hardware_problem, move, tmp_path, signals=[(FAULT_AT_S, signal.SIGINT)]
    )
    assert result.at_rest and header["stop"]["rest"] == "confirmed"
    window = round(SETTINGS.rest_window_s / PERIOD_S) + 1
    last = table.iloc[-window:]
    assert set(last["phase"]) == {"hold"}
    speeds = last[["velocity_theta1_rad_s", "velocity_theta2_rad_s"]].abs().to_numpy()
    assert np.all(speeds < SETTINGS.rest_speed_rad_s)
    still = np.all(
        table[["velocity_theta1_rad_s", "velocity_theta2_rad_s"]].abs().to_numpy()
        < SETTINGS.rest_speed_rad_s,
        axis=1,
    )
    first_still = int(np.flatnonzero(~still)[-1]) + 1
    assert len(table) - first_still >= window
    assert header["stop"]["duration_s"] == pytest.approx(
        table["time_s"].iloc[-1] - header["stop"]["fault_seen_s"]
    )


def test_the_plan_starts_once_at_rest_on_its_start_not_only_still(hardware_problem, move, tmp_path):
    """θ1 reads still but 10 pulses off the start (over the 5 allowed) for the first
    0.5 s, as a joint stuck on its friction beside its goal: the hold at the start goes on
    until the window (0.2 s) has been still on the start, so the plan's first row is 0.7 s
    in; without the offset it is 0.2 s in."""
    window = SETTINGS.rest_window_s

    def plan_begins(tmp, **script) -> float:
        tmp.mkdir()
        _, table, _, _ = _run(hardware_problem, move, tmp, **script)
        ready = table[table["phase"] == "ready"]
        assert table["phase"].iloc[len(ready)] == "plan"
        return float(table["time_s"].iloc[len(ready)] - table["time_s"].iloc[0])

    assert plan_begins(tmp_path / "on") == pytest.approx(window + PERIOD_S, abs=1e-9)
    off = plan_begins(tmp_path / "off", theta1_off_pulses=(_between(-1.0, 0.5), 10))
    assert off == pytest.approx(0.5 + window + PERIOD_S, abs=PERIOD_S + 1e-9)


def test_a_start_never_reached_is_said_and_the_plan_starts_after_the_settle_time(
    hardware_problem, move, tmp_path, caplog
):
    """θ1 reads 10 pulses off the start throughout: the hold lasts ``settle_s``, the log
    says why rest was not proven, and the plan starts (its following error checked)."""
    caplog.set_level("INFO", logger="spm_opt.execution")
    result, table, _, _ = _run(
        hardware_problem, move, tmp_path, theta1_off_pulses=(lambda t: True, 10)
    )
    ready = table.loc[table["phase"] == "ready", "time_s"]
    assert ready.iloc[-1] - ready.iloc[0] == pytest.approx(SETTINGS.settle_s, abs=1e-9)
    assert "rest at the start not proven: theta1 10 pulses from its goal" in caplog.text
    assert result.completed


def test_a_signal_during_the_hold_is_recorded_and_the_hold_goes_on(
    hardware_problem, move, tmp_path
):
    """A SIGTERM 50 ms into the hold (after the SIGINT that stopped the run) neither ends
    the hold nor is lost: the run is the same, and the outcome lists both signals."""
    first = _run(hardware_problem, move, tmp_path, signals=[(FAULT_AT_S, signal.SIGINT)])
    table = first[1]
    hold_start = table.loc[table["phase"] == "hold", "time_s"].iloc[0]
    (tmp_path / "again").mkdir()
    result, again, header, _ = _run(
        hardware_problem,
        move,
        tmp_path / "again",
        signals=[(FAULT_AT_S, signal.SIGINT), (hold_start + 0.05, signal.SIGTERM)],
    )
    assert result.reason == "interrupted (SIGINT)" and result.at_rest
    assert result.signals == header["signals"] == ["SIGINT during plan", "SIGTERM during hold"]
    pd.testing.assert_frame_equal(again, table)  # NaN (no plan time outside the plan) equal


def test_the_hold_watches_reads_and_hardware_errors(hardware_problem, move, tmp_path):
    """Reads fail for 0.1 s in the hold and θ2 reports overheating: the failures restart
    the rest window, both are in the outcome, and rest is confirmed after the window."""
    first = _run(hardware_problem, move, tmp_path, signals=[(FAULT_AT_S, signal.SIGINT)])
    hold_start = first[1].loc[first[1]["phase"] == "hold", "time_s"].iloc[0]
    (tmp_path / "again").mkdir()
    outage = (hold_start + 0.05, hold_start + 0.15)
    result, table, header, _ = _run(
        hardware_problem,
        move,
        tmp_path / "again",
        signals=[(FAULT_AT_S, signal.SIGINT)],
        read_fails=_between(*outage),
        hardware_error=(hold_start + 0.02, 1 << 2),
    )
    stop = header["stop"]
    assert result.at_rest and stop["rest"] == "confirmed"
    assert stop["failed_reads"] == 10
    assert stop["hardware_errors"] == ["actuator 2: overheating"]
    confirmed = stop["fault_seen_s"] + stop["duration_s"]
    assert confirmed >= outage[1] + SETTINGS.rest_window_s - 1e-9


def test_rest_cannot_be_proven_without_readings(hardware_problem, move, tmp_path):
    """Every read fails from 1 s on: the run stops, the stop's goals go out blind, and the
    outcome says plainly that rest was not confirmed."""
    result, table, header, _ = _run(
        hardware_problem, move, tmp_path, read_fails=lambda t: t >= FAULT_AT_S
    )
    assert result.reason.startswith("communication lost")
    stop = header["stop"]
    assert not result.at_rest and not stop["at_rest"] and stop["duration_s"] is None
    assert stop["stop_delivered"]
    assert stop["rest"] == (
        f"not confirmed within the {SETTINGS.hold_s:g} s hold: a read failed; "
        f"at rest for the last 0.000 s of {SETTINGS.rest_window_s:g} s"
    )


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"hold_s": 0.1}, r"hold_s = 0.1: expected at least rest_window_s \(0.2 s\)"),
        ({"settle_s": 0.0}, r"settle_s = 0.0: expected at least rest_window_s"),
        ({"rest_position_pulses": 2.5}, r"rest_position_pulses = 2.5: expected an integer"),
        ({"rest_window_s": -1.0}, r"rest_window_s = -1.0: expected a number in"),
    ],
)
def test_rest_settings_are_checked(changes, match):
    with pytest.raises(so.InputError, match=match):
        ExecutionSettings(**changes)
