"""The one executor: every plan reaches a device through here.

Pre-flight (:mod:`spm_opt.execution.preflight`), the plan must have been made for this
problem, start and end at rest, and keep every limit that judges the robot. The robot must
be where the plan starts, or, on request, is first brought there by a jerk-limited ruckig
approach. A stop asked for before or during :meth:`Executor.run` is honoured (and forgotten
when the run ends): before connecting, the run ends with nothing moved or written
(:class:`~spm_opt.errors.RunInterrupted`); after, in the first control cycle, before any
goal of the plan goes out. Then a fixed-rate loop on the backend's clock reads both
actuators, checks them, writes the next goal positions and logs the sample (queued in
memory: a thread of the log's own writes it, :mod:`spm_opt.execution.log`, so the loop and
the stop never wait on the disk). The goals follow the plan at the operator's feed
(:mod:`spm_opt.execution.feed`): held, resumed and overridden from any thread, always on
the planned path; a hold where the plan leaves no room for a stop on the path
(:mod:`spm_opt.hold_room`) is the safe stop below, at once (the log's feed events say "no
room: safe stop"). On a hardware error, a following error beyond the tolerance, a run of
cycles with a failed read or write longer than the retry budget, a log write that failed or
stalls (in the approach, the plan and the settle; during the stop and the hold the samples
wait in memory), SIGINT or SIGTERM, any other exception raised by the backend or in the
loop, the robot is brought to rest by a jerk-limited ruckig stop that starts, in the cycle
that saw the fault, from the last goal the actuators received (so the goal stream stays
continuous: starting from the measured position would make the goal jump back by the
following error, and a goal whose write failed never reached them). It then holds there
until rest is proven: every sample over a window below the rest speed and each joint's
position within a few encoder pulses. The log's header reports how long the stop took and
how far each joint moved. A run is a success only when it completed and rest was proven at
its end (:attr:`ExecutionResult.succeeded`). The log's times start at 0 at the loop's
start; the header's ``clock_origin_s`` is that moment on the backend's clock.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import signal
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import ruckig

from spm_opt.errors import CommunicationError, InputError, PreflightError, RunInterrupted
from spm_opt.execution import preflight
from spm_opt.execution.backend import (
    CLOCK_EPSILON_S,
    Backend,
    Clock,
    Measurement,
    hardware_error_names,
)
from spm_opt.execution.feed import FeedProfile, FeedRequests, NoRoom, Pace, feed_ceiling
from spm_opt.execution.log import LogWriter, Write
from spm_opt.execution.preflight import degrees
from spm_opt.execution.realtime import frozen_heap, raised_priority
from spm_opt.execution.rest import FeedHoldWatch, RestWindow
from spm_opt.execution.results import ExecutionResult, LoopStatistics, RunStatus, StopReport
from spm_opt.execution.settings import ExecutionSettings
from spm_opt.execution.tracking import Lead, following_error_limit
from spm_opt.model.params import DEG
from spm_opt.problem import Problem
from spm_opt.ruckig_local import calculate_locally
from spm_opt.trajectory import Trajectory
from spm_opt.version import package_version

_LOG = logging.getLogger(__name__)


class _Ticker:
    """The loop's schedule: deadlines every period on the backend's clock, from ``origin``
    (its time now, s); a late cycle skips the deadlines it missed rather than running them
    in a burst. Times it gives are since ``origin`` (the log's clock)."""

    def __init__(self, clock: Clock, period: float) -> None:
        self.clock, self.period = clock, period
        self.origin = clock.now()
        self.ticks: list[float] = []
        self._next = self.origin

    def wait(self) -> float:
        """Sleep until the next deadline; returns the time the cycle starts, s."""
        self.clock.sleep_until(self._next)
        now = self.clock.now()
        self.ticks.append(now - self.origin)
        missed = math.floor((now - self._next) / self.period)
        self._next += (max(missed, 0) + 1) * self.period
        return now - self.origin

    def now(self) -> float:
        """The time since ``origin``, s."""
        return self.clock.now() - self.origin


@dataclass
class _Cycle:
    """One control cycle: when it began (s, the time its goal is sampled at), what it
    read and what went wrong (``notes``; ``unexpected``: the backend raised something
    other than :class:`CommunicationError`, a fault at once)."""

    time_s: float
    measurement: Measurement | None = None
    following_error: np.ndarray | None = None
    read_failed: bool = False
    write_failed: bool = False
    unexpected: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def status(self) -> str:
        """The log's status: "ok", or the notes."""
        return "; ".join(self.notes) or "ok"


class _Stop(Exception):
    """Raised inside the loop to end the run in a safe stop. ``cycle`` saw the fault;
    ``logged``: it is finished (its goal sent, its sample logged), else the stop's first
    goal goes out in it."""

    def __init__(self, reason: str, cycle: _Cycle | None = None, logged: bool = False) -> None:
        super().__init__(reason)
        self.cycle, self.logged = cycle, logged


@dataclass
class _Commanded:
    """The reference of the last goal the actuators received: position, rate, acceleration
    (the stop starts from here), and that goal (the reference led by the loop's lag)."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    goal: np.ndarray


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
    log_write : callable, optional
        The system call that writes the log's lines (``os.write``; a test's failing disk).
    """

    def __init__(
        self,
        problem: Problem,
        backend: Backend,
        settings: ExecutionSettings | None = None,
        log_write: Write = os.write,
    ) -> None:
        self.problem = problem
        self.backend = backend
        self.settings = settings or ExecutionSettings()
        self._log_write = log_write
        self._torque_map = problem.robot.actuator.current_map
        self._stop_requested: str | None = None
        self._signals_seen: list[str] = []
        self._phase = "connect"
        self._requests = FeedRequests(self.settings.feed, self.settings.max_feed)
        self._lead = Lead.for_actuator(
            problem.robot.actuator, 1.0 / self.settings.rate_hz, self.settings.tracking
        )
        self._feed_events: list[dict[str, Any]] = []
        self._pace: Pace | None = None
        self._plan_duration = 0.0
        self.status: RunStatus | None = None
        """The run as it stands after the last cycle (None before the first)."""

    # ------------------------------------------------------------ the operator
    # Each may be called from any thread, before or during a run.
    def set_feed(self, fraction: float) -> float:
        """Follow the plan at ``fraction`` of its planned pace (≥ 0; above 1 only as far
        as the plan's limits allow); returns the feed that applies."""
        return self._requests.set_feed(fraction)

    def step_feed(self, step: float) -> float:
        """Change the override by ``step`` (within 10 % and the ceiling); returns it."""
        return self._requests.step_feed(step)

    def hold(self) -> None:
        """Bring the tool to rest on the planned path (a feed hold)."""
        self._requests.hold()

    def resume(self) -> None:
        """End a feed hold: go on from the same point at the override."""
        self._requests.resume()

    def toggle_hold(self) -> bool:
        """Hold if running, resume if held; returns True if now held."""
        return self._requests.toggle_hold()

    def stop(self, why: str = "stop requested") -> None:
        """End the run in the safe stop, as SIGINT does; during pre-flight, end it before
        anything moves (see :meth:`run`)."""
        self._stop_requested = self._stop_requested or why

    # ---------------------------------------------------------------- pre-flight
    def check_plan(self, trajectory: Trajectory) -> None:
        """Refuse a plan this executor must not run (one-line :class:`PreflightError`;
        see :mod:`spm_opt.execution.preflight`)."""
        settings = self.settings
        preflight.check_plan(
            self.problem,
            trajectory,
            settings.joint_limits(self.problem),
            1.0 / settings.rate_hz,
            self._lead,
            settings.other_problem,
        )

    def _approach(self, measured: np.ndarray, start: np.ndarray) -> _Segment | None:
        distance = float(np.max(np.abs(measured - start)))
        if distance <= self.settings.start_tolerance_rad:
            return None
        if not self.settings.approach:
            raise PreflightError(
                f"robot at {degrees(measured)}, the plan starts at {degrees(start)}: "
                f"{distance / DEG:.3f} deg away (tolerance "
                f"{self.settings.start_tolerance_rad / DEG:.3f} deg); ask for an approach move "
                "(spm-opt execute --approach; ExecutionSettings(approach=True))"
            )
        return self._ruckig_segment(
            "approach",
            _Commanded(measured, np.zeros(2), np.zeros(2), measured),
            target=start,
            speed=self.settings.approach_speed_rad_s,
        )

    # ----------------------------------------------------------------------- run
    def run(
        self, trajectory: Trajectory, log_path: str | Path, header: dict[str, Any] | None = None
    ) -> ExecutionResult:
        """Check the plan, connect, run it and log every sample to ``log_path`` (CSV).

        Raises :class:`PreflightError` before anything moves or is written when the plan
        or the robot's position is refused, and :class:`RunInterrupted` when a stop was
        asked for (:meth:`stop`, SIGINT, SIGTERM) before connecting (a :meth:`stop` made
        before ``run`` counts: an operator's console starts first); returns how the run
        ended otherwise. A stop asked for later is honoured by the loop's first cycle.
        """
        self._signals_seen, self._phase = [], "pre-flight"
        try:
            with self._signals():
                return self._preflight_and_run(trajectory, Path(log_path), header or {})
        finally:
            self._stop_requested = None  # a stop belongs to the run it ended

    def _preflight_and_run(
        self, trajectory: Trajectory, log_path: Path, header: dict[str, Any]
    ) -> ExecutionResult:
        self.check_plan(trajectory)
        self._requests.ceiling = feed_ceiling(
            self.problem, trajectory, self.settings.max_feed, self._lead
        )
        if self.settings.feed > self._requests.ceiling:
            _LOG.warning(
                "feed %.0f%% is above this plan's ceiling, %.0f%% (the highest at which "
                "it keeps its limits): it starts at %.0f%%",
                100 * self.settings.feed,
                100 * self._requests.ceiling,
                100 * self._requests.ceiling,
            )
        if log_path.suffix != ".csv":
            raise InputError(f"log {log_path}: expected a file name ending in .csv")
        if self._stop_requested:
            raise RunInterrupted(
                f"stopped during pre-flight ({self._stop_requested}): nothing moved, "
                "nothing was written"
            )
        backend = self.backend
        self._phase = "connect"
        backend.connect()
        try:
            measured = backend.read()
            start = trajectory.position(trajectory.start_time)
            approach = self._approach(measured.position_rad, start)
            with frozen_heap(), raised_priority() as nice:
                header = {**header, "control_thread_nice": nice}
                return self._run_connected(trajectory, approach, measured, log_path, header)
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
        header = {
            **header,
            "plan": trajectory.metadata,
            "plan_duration_s": trajectory.duration,
            "problem": self.problem.record(),
            "backend": self.backend.describe(),
            "settings": dataclasses.asdict(settings),
            "feed_ceiling": self._requests.ceiling,
            "tracking": {
                "mode": settings.tracking,
                "lead_rate_s": self._lead.rate_s.tolist(),
                "lead_acceleration_s2": self._lead.acceleration_s2.tolist(),
            },
            "software_version": package_version(),
            "started_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        preflight.check_log_room(log_path, self._longest_run_s(trajectory, approach), header)
        self._writer = LogWriter(
            log_path, header, settings.flush_interval_s, settings.log_stall_s, self._log_write
        )
        # the loop starts now, with its log's files written (the header's origin follows)
        self._ticker = _Ticker(self.backend.clock, 1.0 / settings.rate_hz)
        self._writer.note({"clock_origin_s": self._ticker.origin})
        self._feed_events, self._pace = [], None
        self._plan_duration = trajectory.duration
        at = first.position_rad.copy()
        self._commanded = _Commanded(at, np.zeros(2), np.zeros(2), at)
        self._last_measurement = first
        self._failed_cycles = self._reads_failed = self._writes_failed = 0
        self._previous = (-self._ticker.period, True)
        reason, completed, at_rest, report, exception = "", False, False, None, None
        try:
            if approach is not None:
                self._follow("approach", approach)
            self._follow_plan(trajectory)
            end = trajectory.position(trajectory.end_time)
            at_rest, why = self._settle(end)
            completed = True
            reason = "completed" if at_rest else f"completed, but rest {why}"
        except _Stop as stop:
            reason = str(stop)
            report = self._safe_stop(stop)
        except Exception as error:  # a bug in the loop: a fault like any other
            reason = f"internal error: {type(error).__name__}: {error}"
            exception = traceback.format_exception(error)
            _LOG.debug("safe stop after an internal error", exc_info=True)
            report = self._safe_stop(_Stop(reason))
        finally:
            at_rest = report.at_rest if report is not None else at_rest
            statistics = LoopStatistics.from_ticks(self._ticker.ticks, self._ticker.period)
            backend_state = self.backend.describe()
            log = self._writer.close(
                {
                    "completed": completed,
                    "reason": reason,
                    "at_rest": at_rest,
                    "stop": None if report is None else dataclasses.asdict(report),
                    "signals": list(self._signals_seen),
                    "feed_events": list(self._feed_events),
                    "samples": self._writer.samples,
                    "loop": dataclasses.asdict(statistics),
                    "backend": backend_state,
                    "exception": exception,
                }
            )
        return ExecutionResult(
            completed,
            reason,
            log_path,
            self._writer.samples,
            statistics,
            at_rest,
            backend_state,
            report,
            list(self._signals_seen),
            list(self._feed_events),
            log,
        )

    def _longest_run_s(self, trajectory: Trajectory, approach: _Segment | None) -> float:
        """How long the run may log for, s, if nobody holds the feed: the approach, the
        plan at its starting feed, the settle, a stop from the speed limit and the hold."""
        limits = self.settings.joint_limits(self.problem)
        feed = min(self.settings.feed, self._requests.ceiling)
        stop = limits.speed / limits.acceleration + limits.acceleration / limits.jerk
        return (
            (approach.duration if approach is not None else 0.0)
            + trajectory.duration / feed
            + self.settings.settle_s
            + stop
            + self.settings.hold_s
        )

    # ------------------------------------------------------------------ phases
    def _follow(self, phase: str, segment: _Segment) -> None:
        """Stream a segment's goals, each sampled at its cycle's start, to its end; every
        cycle is checked and a fault raises :class:`_Stop`."""
        self._phase = phase
        begin = None
        while True:
            cycle = self._begin_cycle()
            begin = cycle.time_s if begin is None else begin
            elapsed = min(cycle.time_s - begin, segment.duration)
            if segment.duration - elapsed < CLOCK_EPSILON_S:  # rounding must not add a cycle
                elapsed = segment.duration
            reference = segment.at(elapsed)
            self._check(cycle, reference)
            self._send(cycle, *reference)
            self._end_cycle(phase, cycle, checked=True)
            if elapsed >= segment.duration:
                return

    def _follow_plan(self, trajectory: Trajectory) -> None:
        """Stream the plan's goals at the pace the operator asks for, to the plan's end;
        each cycle is checked, and a fault, a hold for which no path-keeping stop fits
        (at once, in the cycle that saw it asked) or a hold longer than ``max_hold_s``
        raises :class:`_Stop`."""
        self._phase = "plan"
        settings, requests = self.settings, self._requests
        limits = settings.joint_limits(self.problem)
        override, held = asked = requests.requested()
        profile = FeedProfile(
            trajectory,
            limits,
            0.0 if held else override,
            0.5 / settings.rate_hz,
            self.problem.limits.hold_within_s,
        )
        begin, hold = None, FeedHoldWatch(settings, self.problem.robot.actuator)
        try:
            while True:
                cycle = self._begin_cycle()
                begin = cycle.time_s if begin is None else begin
                override, held = requested = requests.requested()
                try:
                    pace = profile.advance(cycle.time_s - begin, 0.0 if held else override)
                except NoRoom as no_room:
                    self._no_room(cycle, asked, requested, no_room)
                for event in _request_events(asked, requested):
                    self._feed_event(cycle, pace, event)
                asked = requested
                self._pace = pace
                reference = profile.goal(pace)
                self._check(cycle, reference)
                self._send(cycle, *reference)
                self._end_cycle("plan", cycle, checked=True)
                for event in hold.watch(cycle.time_s, cycle.measurement, pace):
                    self._feed_event(cycle, pace, event)
                if hold.too_long(cycle.time_s):
                    reason = f"feed held longer than max_hold_s ({settings.max_hold_s:g} s)"
                    raise _Stop(reason, cycle, logged=True)
                if profile.finished(pace):
                    return
        finally:
            self._pace = None

    def _no_room(
        self,
        cycle: _Cycle,
        asked: tuple[float, bool],
        requested: tuple[float, bool],
        no_room: NoRoom,
    ) -> NoReturn:
        """A hold for which no path-keeping stop fits: record it and raise :class:`_Stop`,
        whose first goal goes out in this cycle."""
        pace = self._pace or Pace(0.0, 0.0, 0.0, 0.0)
        for event in _request_events(asked, requested):
            self._feed_event(cycle, pace, event)
        self._feed_event(cycle, pace, "no room: safe stop")
        raise _Stop(f"feed hold: {no_room}; the safe stop instead", cycle)

    def _feed_event(self, cycle: _Cycle, pace: Pace, event: str) -> None:
        """Record a hold, a resume, an override or a hold's progress, with its time."""
        _LOG.info("%s at %.3f s (plan time %.3f s)", event, cycle.time_s, pace.plan_time_s)
        self._feed_events.append(
            {
                "time_s": cycle.time_s,
                "event": event,
                "plan_time_s": pace.plan_time_s,
                "feed": pace.feed,
                "feed_target": pace.target,
            }
        )

    def _settle(self, target: np.ndarray) -> tuple[bool, str]:
        """Hold the plan's end, checked, until rest is confirmed or ``settle_s`` passes;
        (True, "confirmed") if confirmed, else (False, "not proven within …: why")."""
        settle_s = self.settings.settle_s
        at_rest = (target, np.zeros(2), np.zeros(2))
        confirmed, window = self._rest(
            "settle", target, settle_s, lambda c: self._check(c, at_rest), True
        )
        if confirmed is not None:
            return True, "confirmed"
        why = f"not proven within the {settle_s:g} s settle: {window.why()}"
        _LOG.info("rest %s", why)
        return False, why

    def _safe_stop(self, stop: _Stop) -> StopReport:
        """The jerk-limited stop from the last goal delivered, then the hold."""
        _LOG.info("safe stop: %s", stop)
        self._phase = "stop"
        seen = stop.cycle.time_s if stop.cycle is not None else self._ticker.now()
        before = self._last_measurement
        reads, writes = self._reads_failed, self._writes_failed
        errors: list[str] = []
        segment = self._ruckig_segment("stop", self._commanded, target=None)
        first = None if stop.logged else stop.cycle
        delivered = self._stop_stream(segment, first, errors, seen)
        at_rest, rest, confirmed = self._hold(errors)
        travel = _travel(before, self._last_measurement)
        return StopReport(
            fault_seen_s=seen,
            stop_delivered=delivered,
            at_rest=at_rest,
            rest=rest,
            duration_s=None if confirmed is None else confirmed - seen,
            travel_rad=travel,
            travel_deg=None if travel is None else [t / DEG for t in travel],
            failed_reads=self._reads_failed - reads,
            failed_writes=self._writes_failed - writes,
            hardware_errors=errors,
        )

    def _stop_stream(
        self, segment: _Segment, first: _Cycle | None, errors: list[str], seen: float
    ) -> bool:
        """Stream the stop to its end; gives up ``hold_s`` after its planned end. True if
        its last goal was delivered.

        The stop's clock runs with the loop's while its goals get through; a failed write
        pauses it (the goal after an outage is one period further along the profile than
        the last one delivered), so the goals the actuators receive stay one jerk-limited
        stream.
        """
        elapsed, cycle = 0.0, first
        give_up = seen + segment.duration + self.settings.hold_s
        while True:
            cycle = cycle or self._begin_cycle()
            self._observe(cycle, errors)
            previous_s, delivered = self._previous
            step = cycle.time_s - previous_s if delivered else self._ticker.period
            t = min(elapsed + step, segment.duration)
            if segment.duration - t < CLOCK_EPSILON_S:
                t = segment.duration
            if self._send(cycle, *segment.at(t)):
                elapsed = t
            self._end_cycle("stop", cycle, checked=False)
            if elapsed >= segment.duration:
                return True
            if cycle.time_s >= give_up:
                _LOG.warning("stop given up at %.3f s of its %.3f s", elapsed, segment.duration)
                return False
            cycle = None

    def _hold(self, errors: list[str]) -> tuple[bool, str, float | None]:
        """Hold the last goal delivered until rest is confirmed or ``hold_s`` passes.

        Returns (at rest, "confirmed" or why not, the time rest was confirmed or None).
        Reads, hardware errors and signals are still watched: they are recorded, and a
        failed read or a motion restarts the rest window.
        """
        hold_s = self.settings.hold_s
        confirmed, window = self._rest(
            "hold", self._commanded.position, hold_s, lambda c: self._observe(c, errors), False
        )
        if confirmed is not None:
            return True, "confirmed", confirmed
        why = f"not confirmed within the {hold_s:g} s hold: {window.why()}"
        _LOG.info("rest %s", why)
        return False, why, None

    def _rest(
        self,
        phase: str,
        target: np.ndarray,
        limit_s: float,
        inspect: Callable[[_Cycle], None],
        checked: bool,
    ) -> tuple[float | None, RestWindow]:
        """Hold ``target`` (rad), each cycle inspected (``checked``: a run of failed cycles
        is a fault), until rest is confirmed or ``limit_s`` (s) passes; the time rest was
        confirmed (None if not), and the window."""
        self._phase = phase
        window = RestWindow(self.settings, self.problem.robot.actuator)
        begin = None
        while True:
            cycle = self._begin_cycle()
            begin = cycle.time_s if begin is None else begin
            inspect(cycle)
            self._send(cycle, target, np.zeros(2), np.zeros(2))
            self._end_cycle(phase, cycle, checked=checked)
            if window.add(cycle.time_s, cycle.measurement):
                return cycle.time_s, window
            if cycle.time_s - begin >= limit_s - CLOCK_EPSILON_S:
                return None, window

    # ------------------------------------------------------------------ cycles
    def _begin_cycle(self) -> _Cycle:
        """Wait for the next deadline and read both actuators."""
        cycle = _Cycle(self._ticker.wait())
        try:
            cycle.measurement = self.backend.read()
            self._last_measurement = cycle.measurement
        except Exception as error:  # noqa: BLE001 - any failure of the device is a fault
            cycle.read_failed = True
            self._reads_failed += 1
            cycle.notes.append(self._failure("read", error, cycle))
        return cycle

    def _failure(self, what: str, error: Exception, cycle: _Cycle) -> str:
        """The note of a read or write that raised: a :class:`CommunicationError` is a
        failed transaction (counted against the retry budget); anything else is
        unexpected, a fault at once."""
        if isinstance(error, CommunicationError):
            _LOG.info("%s failed: %s", what, error)
            return f"{what} failed: {error}"
        cycle.unexpected = f"the backend's {what} raised {type(error).__name__}: {error}"
        _LOG.debug("%s raised", what, exc_info=True)
        return cycle.unexpected

    def _send(
        self, cycle: _Cycle, position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray
    ) -> bool:
        """Write the goal of a reference state (led by the loop's lag); only a write that
        succeeded becomes the commanded state. A write reported failed counts as not
        delivered, though a port can fail a packet that left (see
        :mod:`spm_opt.execution.dynamixel`); the stop's first goal, one period along from
        the last goal known, is then the one that arrived to within q̈ T²."""
        goal = self._lead.goal(position, velocity, acceleration)
        try:
            self.backend.write_goal(goal)
        except Exception as error:  # noqa: BLE001 - any failure of the device is a fault
            cycle.write_failed = True
            self._writes_failed += 1
            cycle.notes.append(self._failure("write", error, cycle))
            return False
        commanded = self._commanded
        commanded.position, commanded.velocity = position, velocity
        commanded.acceleration, commanded.goal = acceleration, goal
        return True

    def _end_cycle(self, phase: str, cycle: _Cycle, checked: bool) -> None:
        """Count the cycle (failed if its read or its write did) and log it; when
        ``checked``, a run of failures past the retry budget, or a write that raised the
        unexpected, is a fault seen here."""
        failed = cycle.read_failed or cycle.write_failed
        self._failed_cycles = self._failed_cycles + 1 if failed else 0
        self._previous = (cycle.time_s, not cycle.write_failed)
        reason = ""
        if checked and cycle.unexpected:
            reason = cycle.unexpected
        elif checked and self._failed_cycles > self.settings.communication_retries:
            reason = self._communication_lost(self._failed_cycles, cycle)
            cycle.notes.append(reason)
        self._log(phase, cycle)
        if checked and not reason and self._writer.fault:
            reason = f"log failed: {self._writer.fault}"
        if reason:
            raise _Stop(reason, cycle, logged=True)

    def _check(self, cycle: _Cycle, reference: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """Raise :class:`_Stop` on an interrupt, too many failed cycles (this one's read
        included), a hardware error or a following error (the measured position against
        the reference ``(position, rate, acceleration)`` at the cycle's time); the reason
        joins the notes."""
        reason = self._fault(cycle, reference[0], reference[1])
        if reason:
            if reason not in cycle.notes:
                cycle.notes.append(reason)
            raise _Stop(reason, cycle)

    def _fault(self, cycle: _Cycle, expected: np.ndarray, rate: np.ndarray) -> str:
        if self._stop_requested:
            return f"interrupted ({self._stop_requested})"
        if cycle.unexpected:
            return cycle.unexpected
        failures = self._failed_cycles + 1 if cycle.read_failed else 0
        if failures > self.settings.communication_retries:
            return self._communication_lost(failures, cycle)
        measurement = cycle.measurement
        if measurement is None:
            return ""
        for joint, status_bits in enumerate(measurement.hardware_error):
            if status_bits:
                names = ", ".join(hardware_error_names(status_bits))
                return f"hardware error on actuator {joint + 1}: {names}"
        error = np.abs(measurement.position_rad - expected)
        cycle.following_error = error
        speed = np.maximum(np.abs(rate), np.abs(measurement.velocity_rad_s))
        allowed = following_error_limit(
            speed, self.problem.limits.max_joint_speed, *self.settings.following_error_bounds
        )
        worst = int(np.argmax(error / allowed))
        if error[worst] > allowed[worst]:
            return (
                f"following error of theta{worst + 1}: {error[worst] / DEG:.3f} deg "
                f"(tolerance {allowed[worst] / DEG:.3f} deg at {speed[worst]:.3f} rad/s)"
            )
        return ""

    def _communication_lost(self, failures: int, cycle: _Cycle) -> str:
        return (
            f"communication lost: {failures} cycles in a row with a failed read or write "
            f"(retry budget {self.settings.communication_retries}); last: {cycle.status}"
        )

    def _observe(self, cycle: _Cycle, errors: list[str]) -> None:
        """During the stop and the hold: record the hardware errors reported."""
        if cycle.measurement is None:
            return
        for joint, status_bits in enumerate(cycle.measurement.hardware_error):
            if status_bits:
                entry = f"actuator {joint + 1}: {', '.join(hardware_error_names(status_bits))}"
                if entry not in errors:
                    _LOG.warning("hardware error while stopping: %s", entry)
                    errors.append(entry)

    def _log(self, phase: str, cycle: _Cycle) -> None:
        """One sample: the pace along the plan (in its phase), the goal the actuators hold
        (the last delivered) and the reading; the same as :attr:`status`."""
        commanded, measurement, pace = self._commanded, cycle.measurement, self._pace
        reference, goal = commanded.position, commanded.goal
        along = None if pace is None else (pace.plan_time_s, pace.feed, pace.target)
        torque = None
        if measurement is None:
            self._writer.append(
                cycle.time_s, phase, along, reference, goal, None, None, cycle.status
            )
        else:
            torque = self._torque_map.torque(measurement.current_a)
            values = (
                measurement.position_rad,
                measurement.velocity_rad_s,
                measurement.current_a,
                torque,
            )
            self._writer.append(
                cycle.time_s,
                phase,
                along,
                reference,
                goal,
                values,
                measurement.hardware_error,
                cycle.status,
            )
        self._update_status(phase, cycle, torque)

    def _update_status(self, phase: str, cycle: _Cycle, torque: np.ndarray | None) -> None:
        """Replace :attr:`status` (one assignment: a reader in another thread sees the old
        status or the new one, whole)."""
        pace, (_, held) = self._pace, self._requests.requested()
        if pace is None:  # outside the plan phase the goal is not on the plan's clock
            pace = Pace(self.status.plan_time_s if self.status else 0.0, 0.0, 0.0, 0.0)
        error = cycle.following_error
        self.status = RunStatus(
            time_s=cycle.time_s,
            phase=phase,
            plan_time_s=pace.plan_time_s,
            plan_duration_s=self._plan_duration,
            feed=pace.feed,
            feed_target=pace.target,
            held=held,
            following_error_rad=None if error is None else float(np.max(error)),
            torque_nm=None if torque is None else (float(torque[0]), float(torque[1])),
            status=cycle.status,
        )

    def _ruckig_segment(
        self, name: str, commanded: _Commanded, target: np.ndarray | None, speed: float = 0.0
    ) -> _Segment:
        """A jerk-limited move from the commanded state: to rest at ``target``, or (None)
        to rest as soon as the limits allow."""
        limits = self.settings.joint_limits(self.problem)
        acceleration, jerk = limits.acceleration, limits.jerk
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
            inp.max_velocity = [max(limits.speed, *np.abs(commanded.velocity))] * 2
        else:
            inp.target_position = list(target)
            inp.max_velocity = [min(speed, limits.speed)] * 2
        motion = calculate_locally(inp, name)

        def goal(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            position, velocity, acceleration = motion.at_time(t)
            return np.array(position), np.array(velocity), np.array(acceleration)

        return _Segment(motion.duration, goal)

    @contextmanager
    def _signals(self) -> Iterator[None]:
        """SIGINT and SIGTERM ask for a stop (in the main thread only); each one is
        recorded with the phase it arrived in, also during the stop and the hold, which
        go on."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return

        def request(signum: int, _frame: Any) -> None:
            name = signal.Signals(signum).name
            self._signals_seen.append(f"{name} during {self._phase}")
            self._stop_requested = self._stop_requested or name

        previous = {s: signal.signal(s, request) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)


def _request_events(before: tuple[float, bool], after: tuple[float, bool]) -> list[str]:
    """What the operator asked for since ``before`` (override, held): "feed 60%", "hold",
    "resume"."""
    events = [] if after[0] == before[0] else [f"feed {after[0]:.0%}"]
    if after[1] != before[1]:
        events.append("hold" if after[1] else "resume")
    return events


def _travel(before: Measurement | None, after: Measurement | None) -> list[float] | None:
    """How far each joint moved between two readings, rad (None without both)."""
    if before is None or after is None:
        return None
    return [float(d) for d in np.abs(after.position_rad - before.position_rad)]


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
