"""Every injected fault ends in a safe stop that the plant's TRUE state confirms.

Eight faults: five on the wire, through the real ``dynamixel-sdk`` against the emulator in
a child process (dropped replies, bad CRC, refused writes, overload, stuck encoder), and
three in simulated time on the simulated robot (following error, SIGINT, SIGTERM), whose
faults do not need the SDK. Each run is checked from its log, its header and the plant's
true state (:class:`~spm_opt.execution.plant.StateTrace`: no encoder quantisation, no
noise), on one clock (the emulator records on the machine's monotonic clock, which is the
executor's).

1. The log holds every sample up to the fault: one row per control cycle (the header's
   sample count is the loop's cycle count), from the plan's start; the row of the cycle
   that saw the fault names it, and only the stop and the hold follow (the stop's first
   goal goes out in that very cycle unless the fault was its failed write).
2. The commanded stop kept its limits. The goals the actuators received are the plan's,
   each sampled at its cycle's start (the log's time, to the ns), then the ruckig stop,
   joined C² to them (it starts from the last delivered goal's position, rate and
   acceleration) and sampled on its own clock, which runs with the loop's while its goals
   get through and moves one period over an outage. The k-th finite difference of samples
   of a function divided by T^k is a weighted mean of its k-th derivative (the Peano
   kernel of the difference is a B-spline: non-negative, of unit integral; on an uneven
   grid, k! times the divided difference is such a mean too), so it keeps the same bound
   with no error of the method. What remains is the log's rounding of goals to 9
   significant digits, ε ≤ 5e-10 |q|, amplified by at most 2^k ε / h^k (h the smallest
   spacing), and the evaluator's 0.5 % (:mod:`spm_opt.judge.limits`) allowed as for a plan.
3. The stop is bounded. Let v be a joint's goal speed when the stop starts and a₀ its
   acceleration (at most the plan's peaks V and A over its whole duration, so the bound
   holds whenever the fault comes), a and j the stop's limits. The time-optimal jerk-limited
   stop first brings the acceleration to zero (≤ a₀/j, the speed growing by at most
   a₀²/(2j), to v⁺ = v + a₀²/(2j)), then ramps the deceleration up to a (a/j), holds it and
   ramps it down (a/j), shedding v⁺: v⁺/a + a/j in all, or 2√(v⁺/j) ≤ v⁺/a + a/j
   (AM–GM) when v⁺ < a²/j never lets it reach a. So T ≤ a₀/j + v⁺/a + a/j for the joint
   that sets the time; ruckig gives the other joint the same T, decelerating it more
   gently, and its speed (checked from the log) stays under its own v⁺. Each joint's goal
   moves at most D = v⁺ T after the stop starts.
4. The plant came to rest within that bound plus the following error allowance. When the
   fault is seen, the true position lags the goal by at most the following tolerance plus
   the goal's advance over the cycles not checked (the retry budget and the cycle itself:
   (retries + 1) V T_loop); at rest it sits on its final goal within the rest tolerance
   (rest_position_pulses). The true travel after the fault is at most
   D + tolerance + (retries + 1) V T_loop + rest pulses.
5. Rest was proven, not assumed: over the window the executor took as proof, the true
   speeds stayed below the rest speed and the true positions within the rest pulses, and
   the plant stayed at rest after it.
"""

from __future__ import annotations

import dataclasses
import os
import signal
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pytest
from conftest import HARDWARE_PROBLEM

import spm_opt as so
from spm_opt.base.errors import CommunicationError
from spm_opt.execution import (
    ExecutionSettings,
    Measurement,
    SimulatedRobot,
    execute,
    read_log,
)
from spm_opt.execution.dynamixel import DynamixelRobot
from spm_opt.execution.emulator import (
    CorruptReplies,
    DropReplies,
    Faults,
    Overload,
    RefusedWrites,
    StuckEncoder,
    spawn_emulator,
)
from spm_opt.execution.plant import StateTrace
from spm_opt.execution.realtime import CONTROL_FIFO_PRIORITY
from spm_opt.execution.tracking import Lead
from spm_opt.judge.limits import RULES

pytestmark = pytest.mark.real_time

DEG = np.pi / 180.0
FAULT_AT_S = 1.0
"""When each fault is injected, s after the plan's first goal."""
SETTINGS = ExecutionSettings()
PERIOD_S = 1.0 / SETTINGS.rate_hz
GOALS = ["goal_theta1_rad", "goal_theta2_rad"]
REFERENCES = ["reference_theta1_rad", "reference_theta2_rad"]
"""The logged references: the commanded motion, of which the goals are the lead."""
LOG_DIGITS_ERROR = 5e-10
"""Relative rounding of a goal written to the log with 9 significant digits."""


def short_move(problem: so.Problem) -> so.Trajectory:
    """A 3 s quintic move from rest at (0, 0) to rest at (6, −4) deg, made for ``problem``."""
    t = np.linspace(0.0, 3.0, 301)
    tau = t / 3.0
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    ds = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / 3.0
    dds = (60 * tau - 180 * tau**2 + 120 * tau**3) / 9.0
    span = np.array([6.0, -4.0]) * DEG
    return so.Trajectory.from_samples(
        t,
        s[:, None] * span,
        ds[:, None] * span,
        dds[:, None] * span,
        {"planner": "test", "problem": problem.record()},
    )


@pytest.fixture(scope="module")
def move(hardware_problem: so.Problem) -> so.Trajectory:
    return short_move(hardware_problem)


@dataclass(frozen=True)
class StopBound:
    """Item 3 of the module's docstring: the stop's duration T, s, and per joint the
    largest goal speed v⁺, rad/s, and goal travel D = v⁺ T, rad."""

    duration_s: float
    speed_rad_s: np.ndarray
    travel_rad: np.ndarray
    plan_speed_rad_s: np.ndarray


def stop_bound(problem: so.Problem, trajectory: so.Trajectory) -> StopBound:
    """The bound of a jerk-limited stop from anywhere on ``trajectory``."""
    a = problem.limits.max_joint_acceleration or SETTINGS.stop_acceleration_rad_s2
    j = problem.limits.max_joint_jerk or SETTINGS.stop_jerk_rad_s3
    t = np.linspace(trajectory.start_time, trajectory.end_time, 3001)
    v = np.max(np.abs(trajectory.velocity(t)), axis=0)
    a0 = np.max(np.abs(trajectory.acceleration(t)), axis=0)
    peak = v + a0**2 / (2 * j)
    duration = float(np.max(a0 / j + peak / a + a / j))
    return StopBound(duration, peak, peak * duration, v)


def received_goals(table: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """The references of the goals the actuators received, from three before the stop to
    its end, and their times on the goal stream's own clock (item 2 of the module's
    docstring): each was sampled at its cycle's start, except that an outage (rows whose
    write failed) pauses the stop's clock, the next one period along from the last
    delivered."""
    delivered = ~table["status"].str.contains("write failed").to_numpy()
    phases = table["phase"].to_numpy()
    first_stop = int(np.argmax(phases == "stop"))
    rows = np.concatenate(
        [
            np.flatnonzero(delivered[:first_stop])[-3:],
            np.flatnonzero(delivered & (phases == "stop")),
        ]
    )
    time = table["time_s"].to_numpy()
    steps = np.where(np.diff(rows) == 1, np.diff(time[rows]), PERIOD_S)
    return np.concatenate([[0.0], np.cumsum(steps)]), table[REFERENCES].to_numpy()[rows]


def derivative_estimates(t: np.ndarray, q: np.ndarray, order: int) -> np.ndarray:
    """order! times the divided differences of q (rows) over t: means of the derivative."""
    d = q
    for k in range(1, order + 1):
        d = (d[1:] - d[:-1]) / (t[k:] - t[:-k])[:, None] * k
    return d


def assert_the_commanded_stop_kept_its_limits(
    table: pd.DataFrame, problem: so.Problem, bound: StopBound
) -> None:
    """Item 2 and the goal's part of item 3 of the module's docstring."""
    a = problem.limits.max_joint_acceleration or SETTINGS.stop_acceleration_rad_s2
    j = problem.limits.max_joint_jerk or SETTINGS.stop_jerk_rad_s3
    t, q = received_goals(table)
    rounding = LOG_DIGITS_ERROR * np.max(np.abs(q))
    for order, limit, rule in (
        (1, bound.speed_rad_s, "joint speed"),
        (2, np.array([a, a]), "joint acceleration"),
        (3, np.array([j, j]), "joint jerk"),
    ):
        spacing = np.min(t[order:] - t[:-order]) / order
        allowed = RULES[rule].allowed(limit) + 2**order * rounding / spacing**order
        worst = np.max(np.abs(derivative_estimates(t, q, order)), axis=0)
        assert np.all(worst <= allowed), (rule, worst, allowed)
    # the last goal short of the end was sampled inside the profile (the last one may come
    # a cycle late: its clock is clamped to the end, where the goal rests)
    moving = np.flatnonzero(np.any(q != q[-1], axis=1))[-1]
    assert t[moving] - t[2] < bound.duration_s
    assert np.all(np.abs(q[-1] - q[2]) <= bound.travel_rad)


def assert_every_sample_up_to_the_fault(
    table: pd.DataFrame, header: dict, result: so.ExecutionResult, injected_at: float | None
) -> None:
    """Item 1 of the module's docstring; ``injected_at``, s after the plan's first goal."""
    assert len(table) == header["samples"] == header["loop"]["cycles"] == result.samples
    assert np.all(np.diff(table["time_s"]) > 0)
    seen = header["stop"]["fault_seen_s"]
    fault = int(np.argmin(np.abs(table["time_s"].to_numpy() - seen)))
    assert table["time_s"].iloc[fault] == pytest.approx(seen, abs=1e-6)
    assert result.reason.replace(",", ";") in table["status"].iloc[fault]
    phases = table["phase"].tolist()
    assert set(phases[:fault]) == {"ready", "plan"} and phases[fault - 1] == "plan"
    assert phases.index("plan") == phases.count("ready") and phases[-1] == "hold"
    assert set(phases[fault + 1 :]) <= {"stop", "hold"}
    if injected_at is not None:
        assert seen - table["time_s"].iloc[0] >= injected_at - PERIOD_S
    # the header's figures are the log's: from the last reading at or before the fault to
    # the reading that confirmed rest, the last one
    measured = table[["position_theta1_rad", "position_theta2_rad"]].to_numpy()
    before = np.flatnonzero(~np.isnan(measured[: fault + 1, 0]))[-1]
    travel = np.abs(measured[-1] - measured[before])
    np.testing.assert_allclose(header["stop"]["travel_rad"], travel, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(header["stop"]["travel_deg"], np.degrees(travel), rtol=1e-6)
    duration = table["time_s"].iloc[-1] - seen
    assert header["stop"]["duration_s"] == pytest.approx(duration, abs=1e-6)


def _row_at(trace: dict[str, np.ndarray], t: float) -> int:
    """The last true state sampled at or before ``t``."""
    return int(np.searchsorted(trace["time_s"], t, side="right")) - 1


def assert_the_plant_came_to_rest(
    trace: dict[str, np.ndarray],
    header: dict,
    problem: so.Problem,
    bound: StopBound,
    tolerance_rad: float,
) -> None:
    """Items 4 and 5 of the module's docstring, from the plant's true state."""
    stop = header["stop"]
    assert stop["at_rest"] and stop["rest"] == "confirmed", stop["rest"]
    pulse = 2 * np.pi / problem.robot.actuator.pulses_per_rev
    rest_span = SETTINGS.rest_position_pulses * pulse
    seen, confirmed = stop["fault_seen_s"], stop["fault_seen_s"] + stop["duration_s"]
    q, v = trace["position_rad"], trace["velocity_rad_s"]
    allowance = (
        tolerance_rad
        + (SETTINGS.communication_retries + 1) * bound.plan_speed_rad_s * PERIOD_S
        + rest_span
    )
    travel = np.abs(q[_row_at(trace, confirmed)] - q[_row_at(trace, seen)])
    assert np.all(travel <= bound.travel_rad + allowance), (travel, bound.travel_rad + allowance)
    window = slice(_row_at(trace, confirmed - SETTINGS.rest_window_s) + 1, None)
    assert np.all(np.abs(v[window]) < SETTINGS.rest_speed_rad_s)
    assert np.all(np.ptp(q[window], axis=0) < rest_span)


# ------------------------------------------------------------------- on the wire
def run_on_the_wire(problem, trajectory, faults, tmp_path, backend_class=DynamixelRobot):
    """Run ``trajectory`` through the SDK against the emulator with ``faults``: the result,
    the log, its header and the plant's true trace on the log's clock."""
    trace_path = tmp_path / "plant.npz"
    with spawn_emulator(
        problem_file=HARDWARE_PROBLEM, faults=faults, trace_path=trace_path
    ) as emulator:
        backend = backend_class(problem.robot.actuator, emulator.device)
        result = execute(trajectory, backend, problem, tmp_path / "run.csv", SETTINGS)
    table, header = read_log(tmp_path / "run.csv")
    return result, table, header, StateTrace.load(trace_path, header["clock_origin_s"])


def test_the_move_completes_through_the_sdk_and_the_emulator(hardware_problem, move, tmp_path):
    result, table, header, trace = run_on_the_wire(hardware_problem, move, Faults(), tmp_path)
    assert result.completed and result.at_rest and header["stop"] is None
    assert header["backend"]["backend"] == "dynamixel"
    # a loop on the wall clock runs under the real-time policy where it may (root in CI)
    if os.geteuid() == 0:
        assert header["control_thread_fifo"] == CONTROL_FIFO_PRIORITY
    # the log starts at 0 (its first cycle late by no more than the loop's worst period
    # error: a late cycle shortens the next period); its origin on the monotonic clock is in
    # the header
    worst_s = header["loop"]["period_error_max_ms"] / 1e3
    assert 0.0 <= table["time_s"].iloc[0] < PERIOD_S + worst_s
    assert header["clock_origin_s"] > 0.0
    plan = table[table["phase"] == "plan"]
    t = plan["time_s"].to_numpy() - plan["time_s"].iloc[0]
    measured = plan[["position_theta1_rad", "position_theta2_rad"]].to_numpy()
    # a read the loaded machine's pseudo-terminal misses is logged as NaN: rare, not wrong
    read = np.all(np.isfinite(measured), axis=1)
    assert np.mean(read) > 0.95
    assert np.max(np.abs(measured - move.position(t))[read]) < 0.5 * DEG
    assert result.statistics.achieved_rate_hz == pytest.approx(100.0, rel=0.02)
    # the true state and the measured one agree to the encoder's resolution and the sag
    rows = [_row_at(trace, t) for t in table["time_s"]]
    true = trace["position_rad"][rows]
    measured = table[["position_theta1_rad", "position_theta2_rad"]].to_numpy()
    read = np.all(np.isfinite(measured), axis=1)
    assert np.max(np.abs(true - measured)[read]) < 0.05 * DEG


WIRE_FAULTS = [
    pytest.param(
        Faults(drop=DropReplies(at=FAULT_AT_S, count=40)), "communication lost", id="drop"
    ),
    pytest.param(
        Faults(crc=CorruptReplies(at=FAULT_AT_S, count=40)), "communication lost", id="crc"
    ),
    pytest.param(
        Faults(overload=(Overload(id=1, at=FAULT_AT_S),)),
        "hardware error on actuator 1: overload",
        id="overload",
    ),
    pytest.param(
        Faults(stuck=(StuckEncoder(id=2, at=FAULT_AT_S),)),
        "following error of theta2",
        id="stuck",
    ),
]


@pytest.mark.parametrize(("faults", "reason"), WIRE_FAULTS)
def test_a_wire_fault_ends_in_a_stop_the_true_state_confirms(
    hardware_problem, move, tmp_path, faults, reason
):
    result, table, header, trace = run_on_the_wire(hardware_problem, move, faults, tmp_path)
    assert result.reason.startswith(reason), result.reason
    bound = stop_bound(hardware_problem, move)
    assert_every_sample_up_to_the_fault(table, header, result, FAULT_AT_S)
    assert_the_commanded_stop_kept_its_limits(table, hardware_problem, bound)
    assert_the_plant_came_to_rest(
        trace, header, hardware_problem, bound, SETTINGS.following_error_bounds[1]
    )


def test_refused_writes_stop_from_the_last_goal_the_actuators_received(
    hardware_problem, move, tmp_path
):
    """The line refuses every packet for 0.3 s: the SDK's writes fail at the port, count
    against the retry budget, and the stop starts from the goal the plant really holds."""
    faults = Faults(write=RefusedWrites(at=FAULT_AT_S, seconds=0.3))
    result, table, header, trace = run_on_the_wire(hardware_problem, move, faults, tmp_path)
    assert result.reason.startswith("communication lost"), result.reason
    bound = stop_bound(hardware_problem, move)
    assert_every_sample_up_to_the_fault(table, header, result, FAULT_AT_S)
    assert_the_commanded_stop_kept_its_limits(table, hardware_problem, bound)
    assert_the_plant_came_to_rest(
        trace, header, hardware_problem, bound, SETTINGS.following_error_bounds[1]
    )
    failed = table["status"].str.contains("write failed").to_numpy()
    seen = header["stop"]["fault_seen_s"]
    fault = int(np.argmin(np.abs(table["time_s"].to_numpy() - seen)))
    first = int(np.argmax(failed))
    assert fault - first == SETTINGS.communication_retries and np.all(failed[first : fault + 1])
    assert "Write timeout" in table["status"].iloc[first]
    # the cycle that saw the fault (its read failed too) wrote twice: its own goal, then the
    # stop's first in its place
    assert header["backend"]["communication_failures"]["write"] == failed.sum() + 1
    # no failed goal became the commanded state: the log holds the last one delivered
    np.testing.assert_array_equal(table[GOALS].iloc[fault], table[GOALS].iloc[first - 1])
    # which is what the plant held when the stop began, unless the line stalled just after
    # the first failed write's bytes left (pyserial fails a write that finds no room after
    # it): then the plant holds that goal, the plan's at that cycle
    held = trace["goal_rad"][_row_at(trace, seen)]
    pulse = 2 * np.pi / hardware_problem.robot.actuator.pulses_per_rev
    at = table["plan_time_s"].iloc[first]  # the plan's time of the goal that failed
    lead = Lead.for_actuator(hardware_problem.robot.actuator, PERIOD_S, SETTINGS.tracking)
    attempted = lead.goal(move.position(at), move.velocity(at), move.acceleration(at))
    candidates = np.array([table[GOALS].iloc[first - 1], attempted])
    assert np.any(np.all(np.abs(candidates - held) <= pulse, axis=1)), (held, candidates)
    # while the line was down, the stop's goals waited for it
    assert header["stop"]["failed_writes"] > 0 and header["stop"]["stop_delivered"]


# --------------------------------------------------------------- simulated time
Window = Callable[[float], bool]
"""Whether a scripted fault is on at a time of the simulated robot's clock, s."""


class ScriptedRobot(SimulatedRobot):
    """The simulated robot with faults scripted on its clock (simulated time: a run takes
    a fraction of a second): real signals sent to this process, reads and writes that
    fail (a failed write never reaches the plant), a reading of θ2 that creeps, a reading
    of θ1 off by a few pulses while a window lasts, and Hardware Error Status bits
    reported."""

    def __init__(
        self,
        robot: so.Robot,
        start_rad: np.ndarray,
        *,
        signals: Sequence[tuple[float, int]] = (),
        read_fails: Window | None = None,
        write_fails: Window | None = None,
        creep_rad_s: tuple[float, float] = (float("inf"), 0.0),
        theta1_off_pulses: tuple[Window, int] | None = None,
        hardware_error: tuple[float, int] = (float("inf"), 0),
    ) -> None:
        super().__init__(robot, start_rad=start_rad)
        self.signals = sorted(signals)
        self.read_fails, self.write_fails = read_fails, write_fails
        self.creep_from, self.creep_rad_s = creep_rad_s
        self.theta1_off_pulses = theta1_off_pulses
        self.error_from, self.error_bits = hardware_error

    def read(self) -> Measurement:
        now = self.clock.now()
        while self.signals and now >= self.signals[0][0]:
            os.kill(os.getpid(), self.signals.pop(0)[1])
        measurement = super().read()
        if self.read_fails is not None and self.read_fails(now):
            raise CommunicationError(f"scripted read failure at {now:.3f} s")
        creep = self.creep_rad_s * max(now - self.creep_from, 0.0)
        off = 0.0
        if self.theta1_off_pulses is not None and self.theta1_off_pulses[0](now):
            off = self._actuator.angle(self.theta1_off_pulses[1])
        error = self.error_bits if now >= self.error_from else 0
        return dataclasses.replace(
            measurement,
            position_rad=measurement.position_rad + np.array([off, creep]),
            hardware_error=(measurement.hardware_error[0], measurement.hardware_error[1] | error),
        )

    def write_goal(self, position_rad: np.ndarray) -> None:
        now = self.clock.now()
        if self.write_fails is not None and self.write_fails(now):
            raise CommunicationError(f"scripted write failure at {now:.3f} s")
        super().write_goal(position_rad)


@pytest.mark.parametrize(
    ("kind", "reason"),
    [
        ("following error", "following error of theta1"),
        ("SIGINT", "interrupted (SIGINT)"),
        ("SIGTERM", "interrupted (SIGTERM)"),
    ],
)
def test_a_simulated_fault_ends_in_a_stop_the_true_state_confirms(
    hardware_problem, move, tmp_path, kind, reason
):
    start = move.position(0.0)
    settings, tolerance = SETTINGS, SETTINGS.following_error_bounds[1]
    if kind == "following error":  # unled goals, a tolerance under the loop's lag at speed
        tolerance = 0.05 * DEG
        settings = ExecutionSettings(
            tracking="none", min_following_error_rad=tolerance, max_following_error_rad=tolerance
        )
        robot = SimulatedRobot(hardware_problem.robot, start_rad=start)
    else:
        signals = [(FAULT_AT_S, getattr(signal, kind))]
        robot = ScriptedRobot(hardware_problem.robot, start, signals=signals)
    result = execute(move, robot, hardware_problem, tmp_path / "run.csv", settings)
    assert result.reason.startswith(reason), result.reason
    table, header = read_log(tmp_path / "run.csv")
    bound = stop_bound(hardware_problem, move)
    injected_at = None if kind == "following error" else FAULT_AT_S
    if injected_at is not None:
        assert header["signals"] == [f"{kind} during plan"]
        assert header["stop"]["fault_seen_s"] == pytest.approx(FAULT_AT_S)
    assert_every_sample_up_to_the_fault(table, header, result, injected_at)
    assert_the_commanded_stop_kept_its_limits(table, hardware_problem, bound)
    assert_the_plant_came_to_rest(robot.trace.arrays(), header, hardware_problem, bound, tolerance)
    assert np.all(np.abs(robot.true_state.velocity_rad_s) < SETTINGS.rest_speed_rad_s)
