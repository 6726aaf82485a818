"""The one executor: every plan reaches a device through here.

Pre-flight, the evaluator measures the plan against the problem's limits and the robot's
(joint range, speed, acceleration, jerk, torque, singularity; the cut's own figures, tool
speed and distance from the contour, are the planner's business, not the robot's
safety), and the robot must be where the plan starts, or, on request, is first brought
there by a jerk-limited ruckig approach. Then a fixed-rate loop on the backend's clock
reads both actuators, checks them, writes the next goal positions and logs the sample.
On a hardware error, a following error beyond the tolerance, a run of failed reads longer
than the retry budget, SIGINT or SIGTERM, the robot is brought to rest by a jerk-limited
ruckig stop that starts from the last commanded state (so the goal stream stays
continuous: starting from the measured position would make the goal jump back by the
following error) and holds there.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import ruckig

from spm_opt.errors import CommunicationError, InputError, PreflightError
from spm_opt.evaluate import evaluate
from spm_opt.execution.backend import (
    Backend,
    Clock,
    Measurement,
    hardware_error_names,
)
from spm_opt.execution.log import LogWriter
from spm_opt.model.params import DEG
from spm_opt.planners.ruckig import calculate_locally
from spm_opt.problem import Problem
from spm_opt.trajectory import Trajectory, package_version

_LOG = logging.getLogger(__name__)

CUT_QUALITY_LIMITS = ("tool speed", "contour deviation")
"""Evaluator limits that judge the cut, not the robot's safety: not checked pre-flight."""


@dataclass(frozen=True)
class ExecutionSettings:
    """How the executor runs a plan (SI).

    Attributes
    ----------
    rate_hz : float, Hz
        Control loop rate.
    start_tolerance_rad : float, rad
        Largest distance of the robot from the plan's start at which the plan may begin.
    approach : bool
        Move to the plan's start first (a ruckig move from rest to rest) when farther.
    approach_speed_rad_s : float, rad/s
        Speed limit of the approach move.
    following_error_rad : float, rad
        Largest distance between the planned and the measured position of a joint.
    communication_retries : int
        Consecutive failed reads tolerated before the run stops.
    stop_acceleration_rad_s2, stop_jerk_rad_s3 : float
        Limits of the stop and of the approach (defaults when the problem has none).
    settle_s : float, s
        After the plan's end, time allowed for the joints to come to rest.
    rest_speed_rad_s : float, rad/s
        Measured joint speed below which a joint counts as at rest.
    hold_s : float, s
        After a stop, time spent holding and confirming rest.
    flush_interval_s : float, s
        Longest time a sample waits before it is written to the log.
    """

    rate_hz: float = 100.0
    start_tolerance_rad: float = 0.25 * DEG
    approach: bool = False
    approach_speed_rad_s: float = 0.1
    following_error_rad: float = 1.0 * DEG
    communication_retries: int = 3
    stop_acceleration_rad_s2: float = 1.0
    stop_jerk_rad_s3: float = 10.0
    settle_s: float = 1.0
    rest_speed_rad_s: float = 0.005
    hold_s: float = 0.5
    flush_interval_s: float = 0.1

    def __post_init__(self) -> None:
        checks = {
            "rate_hz": (1.0, 2000.0),
            "start_tolerance_rad": (1e-6, 0.5),
            "approach_speed_rad_s": (1e-3, 2.0),
            "following_error_rad": (1e-5, 1.0),
            "communication_retries": (0, 1000),
            "stop_acceleration_rad_s2": (1e-3, 100.0),
            "stop_jerk_rad_s3": (1e-3, 10000.0),
            "settle_s": (0.0, 60.0),
            "rest_speed_rad_s": (1e-6, 1.0),
            "hold_s": (0.0, 60.0),
            "flush_interval_s": (1e-3, 0.1),
        }
        for name, (low, high) in checks.items():
            value = getattr(self, name)
            if not (isinstance(value, int | float) and low <= value <= high):
                raise InputError(f"{name} = {value!r}: expected a number in [{low}, {high}]")


@dataclass(frozen=True)
class LoopStatistics:
    """Timing of the control loop: achieved rate and the error of each period."""

    cycles: int
    achieved_rate_hz: float
    period_error_p50_ms: float
    period_error_p99_ms: float
    period_error_max_ms: float
    overruns: int

    @classmethod
    def from_ticks(cls, ticks: list[float], period: float) -> LoopStatistics:
        """From the start times of the cycles, s; an overrun is a period over 1.5 nominal."""
        if len(ticks) < 2:
            return cls(len(ticks), float("nan"), float("nan"), float("nan"), float("nan"), 0)
        periods = np.diff(ticks)
        error = np.abs(periods - period) * 1e3
        return cls(
            cycles=len(ticks),
            achieved_rate_hz=float((len(ticks) - 1) / (ticks[-1] - ticks[0])),
            period_error_p50_ms=float(np.percentile(error, 50)),
            period_error_p99_ms=float(np.percentile(error, 99)),
            period_error_max_ms=float(np.max(error)),
            overruns=int(np.sum(periods > 1.5 * period)),
        )


@dataclass
class ExecutionResult:
    """How a run ended. ``completed`` is False when it ended in a safe stop; ``reason``
    says why, in one line."""

    completed: bool
    reason: str
    log_path: Path
    samples: int
    statistics: LoopStatistics
    at_rest: bool
    backend: dict[str, Any] = field(default_factory=dict)


class _Ticker:
    """The loop's schedule: deadlines every period on the backend's clock; a late cycle
    skips the deadlines it missed rather than running them in a burst."""

    def __init__(self, clock: Clock, period: float) -> None:
        self.clock, self.period = clock, period
        self.ticks: list[float] = []
        self._next = clock.now()

    def wait(self) -> float:
        """Sleep until the next deadline; returns the time the cycle starts, s."""
        self.clock.sleep_until(self._next)
        now = self.clock.now()
        self.ticks.append(now)
        missed = math.floor((now - self._next) / self.period)
        self._next += (max(missed, 0) + 1) * self.period
        return now


class _Stop(Exception):
    """Raised inside the loop to end the run in a safe stop."""


@dataclass
class _Commanded:
    """The last goal sent: position, rate, acceleration (the stop starts from here)."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


@dataclass(frozen=True)
class _Segment:
    """A goal stream: ``at(t)`` gives position, rate and acceleration (each (2,), SI) at
    time t since its start, for t in [0, duration]."""

    duration: float
    at: Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]


class Executor:
    """Runs trajectories on one backend under one problem's limits.

    Parameters
    ----------
    problem : Problem
        The robot and the limits the plan is checked against.
    backend : Backend
    settings : ExecutionSettings, optional
    """

    def __init__(
        self, problem: Problem, backend: Backend, settings: ExecutionSettings | None = None
    ) -> None:
        self.problem = problem
        self.backend = backend
        self.settings = settings or ExecutionSettings()
        self._torque_map = problem.robot.actuator.current_map
        self._stop_requested: str | None = None

    # ---------------------------------------------------------------- pre-flight
    def check_plan(self, trajectory: Trajectory) -> None:
        """Refuse a plan that breaks a robot limit (one-line :class:`PreflightError`)."""
        report = evaluate(self.problem, trajectory)
        broken = [v for v in report.violations if v.limit not in CUT_QUALITY_LIMITS]
        if broken:
            raise PreflightError(
                f"plan refused: {broken[0]}"
                + (f" and {len(broken) - 1} more limit(s) broken" if len(broken) > 1 else "")
            )
        start = trajectory.position(trajectory.start_time)
        low, high = self.problem.robot.joint_range[:, 0], self.problem.robot.joint_range[:, 1]
        if np.any(start < low) or np.any(start > high):
            raise PreflightError(f"plan refused: its start {_degrees(start)} is out of range")

    def _approach(self, measured: np.ndarray, start: np.ndarray) -> _Segment | None:
        distance = float(np.max(np.abs(measured - start)))
        if distance <= self.settings.start_tolerance_rad:
            return None
        if not self.settings.approach:
            raise PreflightError(
                f"robot at {_degrees(measured)}, the plan starts at {_degrees(start)}: "
                f"{distance / DEG:.3f} deg away (tolerance "
                f"{self.settings.start_tolerance_rad / DEG:.3f} deg); ask for an approach move"
            )
        return self._ruckig_segment(
            "approach",
            _Commanded(measured, np.zeros(2), np.zeros(2)),
            target=start,
            speed=self.settings.approach_speed_rad_s,
        )

    # ----------------------------------------------------------------------- run
    def run(
        self, trajectory: Trajectory, log_path: str | Path, header: dict[str, Any] | None = None
    ) -> ExecutionResult:
        """Check the plan, connect, run it and log every sample to ``log_path`` (CSV).

        Raises :class:`PreflightError` before anything moves or is written when the plan
        or the robot's position is refused; returns how the run ended otherwise.
        """
        self.check_plan(trajectory)
        log_path = Path(log_path)
        if log_path.suffix != ".csv":
            raise InputError(f"log {log_path}: expected a file name ending in .csv")
        backend = self.backend
        backend.connect()
        try:
            measured = backend.read()
            start = trajectory.position(trajectory.start_time)
            approach = self._approach(measured.position_rad, start)
            return self._run_connected(trajectory, approach, measured, log_path, header or {})
        finally:
            backend.close()

    def _run_connected(
        self,
        trajectory: Trajectory,
        approach: _Segment | None,
        first: Measurement,
        log_path: Path,
        header: dict[str, Any],
    ) -> ExecutionResult:
        settings = self.settings
        writer = LogWriter(
            log_path,
            {
                **header,
                "plan": trajectory.metadata,
                "plan_duration_s": trajectory.duration,
                "problem": self.problem.name,
                "backend": self.backend.describe(),
                "settings": dataclasses.asdict(settings),
                "software_version": package_version(),
                "started_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            },
            settings.flush_interval_s,
        )
        ticker = _Ticker(self.backend.clock, 1.0 / settings.rate_hz)
        commanded = _Commanded(first.position_rad.copy(), np.zeros(2), np.zeros(2))
        reason, completed, at_rest = "", False, False
        with self._signals():
            try:
                if approach is not None:
                    self._stream("approach", approach, commanded, writer, ticker)
                plan = _plan_segment(trajectory)
                self._stream("plan", plan, commanded, writer, ticker)
                at_rest = self._settle("settle", commanded, writer, ticker, settings.settle_s)
                reason, completed = "completed", True
            except _Stop as stop:
                reason = str(stop)
                at_rest = self._safe_stop(reason, commanded, writer, ticker)
            except Exception as error:  # a bug or a backend's surprise: stop, then raise
                reason = f"{type(error).__name__}: {error}"
                at_rest = self._safe_stop(reason, commanded, writer, ticker)
                raise
            finally:
                statistics = LoopStatistics.from_ticks(ticker.ticks, ticker.period)
                backend_state = self.backend.describe()
                writer.close(
                    {
                        "completed": completed,
                        "reason": reason,
                        "at_rest": at_rest,
                        "samples": writer.samples,
                        "loop": dataclasses.asdict(statistics),
                        "backend": backend_state,
                    }
                )
        return ExecutionResult(
            completed, reason, log_path, writer.samples, statistics, at_rest, backend_state
        )

    def _safe_stop(
        self, reason: str, commanded: _Commanded, writer: LogWriter, ticker: _Ticker
    ) -> bool:
        """The jerk-limited stop from the commanded state, then the hold; True at rest."""
        _LOG.warning("safe stop: %s", reason)
        stop = self._ruckig_segment("stop", commanded, target=None)
        self._stream("stop", stop, commanded, writer, ticker, stopping=True)
        return self._settle("hold", commanded, writer, ticker, self.settings.hold_s)

    def _stream(
        self,
        phase: str,
        segment: _Segment,
        commanded: _Commanded,
        writer: LogWriter,
        ticker: _Ticker,
        stopping: bool = False,
    ) -> None:
        """Stream a segment's goals at the loop rate until its end; checks every reading
        unless ``stopping``."""
        length = segment.duration
        failures = 0
        begin = None
        while True:
            now = ticker.wait()
            if begin is None:  # a stop continues from the goal sent one period ago
                begin = now - ticker.period if stopping else now
            elapsed = min(now - begin, length)
            if length - elapsed < 1e-9:  # the clock's rounding must not add a cycle
                elapsed = length
            expected = commanded.position
            measurement, status = self._read(stopping)
            failures = 0 if measurement is not None else failures + 1
            if not stopping:
                self._check(measurement, expected, failures, status)
            position, velocity, acceleration = segment.at(elapsed)
            try:
                self.backend.write_goal(position)
            except CommunicationError as error:
                status = f"write failed: {error}"
                if not stopping and failures + 1 > self.settings.communication_retries:
                    raise _Stop(f"communication lost: {error}") from None
            commanded.position, commanded.velocity = position, velocity
            commanded.acceleration = acceleration
            self._log(writer, now, phase, position, measurement, status)
            if elapsed >= length:
                return

    def _settle(
        self,
        phase: str,
        commanded: _Commanded,
        writer: LogWriter,
        ticker: _Ticker,
        duration: float,
    ) -> bool:
        """Hold the last goal for up to ``duration``; True once every joint is at rest."""
        hold = _Commanded(commanded.position, np.zeros(2), np.zeros(2))
        begin = None
        while True:
            now = ticker.wait()
            begin = now if begin is None else begin
            measurement, status = self._read(phase == "hold")
            try:
                self.backend.write_goal(hold.position)
            except CommunicationError as error:
                status = f"write failed: {error}"
            self._log(writer, now, phase, hold.position, measurement, status)
            at_rest = measurement is not None and bool(
                np.all(np.abs(measurement.velocity_rad_s) < self.settings.rest_speed_rad_s)
            )
            if phase != "hold" and measurement is not None:
                self._check(measurement, hold.position, 0, status)
            if at_rest or now - begin >= duration:
                return at_rest

    def _read(self, quiet: bool) -> tuple[Measurement | None, str]:
        try:
            return self.backend.read(), "ok"
        except CommunicationError as error:
            if not quiet:
                _LOG.info("read failed: %s", error)
            return None, f"read failed: {error}"

    def _check(
        self, measurement: Measurement | None, expected: np.ndarray, failures: int, status: str
    ) -> None:
        """Raise :class:`_Stop` on a fault, an interrupt or too many failed reads."""
        if self._stop_requested:
            raise _Stop(f"interrupted ({self._stop_requested})")
        if failures > self.settings.communication_retries:
            raise _Stop(
                f"communication lost: {failures} reads failed in a row "
                f"(retry budget {self.settings.communication_retries}); last: {status}"
            )
        if measurement is None:
            return
        for joint, status_bits in enumerate(measurement.hardware_error):
            if status_bits:
                names = ", ".join(hardware_error_names(status_bits))
                raise _Stop(f"hardware error on actuator {joint + 1}: {names}")
        error = np.abs(measurement.position_rad - expected)
        worst = int(np.argmax(error))
        if error[worst] > self.settings.following_error_rad:
            raise _Stop(
                f"following error of theta{worst + 1}: {error[worst] / DEG:.3f} deg "
                f"(tolerance {self.settings.following_error_rad / DEG:.3f} deg)"
            )

    def _log(
        self,
        writer: LogWriter,
        now: float,
        phase: str,
        goal: np.ndarray,
        measurement: Measurement | None,
        status: str,
    ) -> None:
        if measurement is None:
            writer.append(now, phase, goal, None, None, status)
            return
        torque = self._torque_map.torque(measurement.current_a)
        values = (
            measurement.position_rad,
            measurement.velocity_rad_s,
            measurement.current_a,
            torque,
        )
        writer.append(now, phase, goal, values, measurement.hardware_error, status)

    def _ruckig_segment(
        self, name: str, commanded: _Commanded, target: np.ndarray | None, speed: float = 0.0
    ) -> _Segment:
        """A jerk-limited move from the commanded state: to rest at ``target``, or (None)
        to rest as soon as the limits allow."""
        limits = self.problem.limits
        acceleration = limits.max_joint_acceleration or self.settings.stop_acceleration_rad_s2
        jerk = limits.max_joint_jerk or self.settings.stop_jerk_rad_s3
        inp = ruckig.InputParameter(2)
        inp.current_position = list(commanded.position)
        inp.current_velocity = list(commanded.velocity)
        inp.current_acceleration = list(
            np.clip(commanded.acceleration, -acceleration, acceleration)
        )
        inp.max_acceleration = [acceleration] * 2
        inp.max_jerk = [jerk] * 2
        if target is None:
            inp.control_interface = ruckig.ControlInterface.Velocity
            inp.target_velocity = [0.0, 0.0]
            inp.max_velocity = [
                max(self.problem.limits.max_joint_speed, *np.abs(commanded.velocity))
            ] * 2
        else:
            inp.target_position = list(target)
            inp.max_velocity = [min(speed, self.problem.limits.max_joint_speed)] * 2
        motion = calculate_locally(inp, name)

        def goal(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            position, velocity, acceleration = motion.at_time(t)
            return np.array(position), np.array(velocity), np.array(acceleration)

        return _Segment(motion.duration, goal)

    @contextmanager
    def _signals(self) -> Iterator[None]:
        """SIGINT and SIGTERM ask for a safe stop (in the main thread only)."""
        self._stop_requested = None
        if threading.current_thread() is not threading.main_thread():
            yield
            return

        def request(signum: int, _frame: Any) -> None:
            self._stop_requested = signal.Signals(signum).name

        previous = {s: signal.signal(s, request) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)


def _plan_segment(trajectory: Trajectory) -> _Segment:
    start = trajectory.start_time

    def goal(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        at = start + t
        return trajectory.position(at), trajectory.velocity(at), trajectory.acceleration(at)

    return _Segment(trajectory.duration, goal)


def _degrees(q: np.ndarray) -> str:
    return "(" + ", ".join(f"{v / DEG:.3f}" for v in q) + ") deg"


def execute(
    trajectory: Trajectory,
    backend: Backend,
    problem: Problem,
    log: str | Path = "run.csv",
    settings: ExecutionSettings | None = None,
) -> ExecutionResult:
    """Run ``trajectory`` on ``backend`` under ``problem``'s limits, logging to ``log``
    (CSV, with its JSON header beside it). See :class:`Executor`."""
    return Executor(problem, backend, settings).run(trajectory, log)
