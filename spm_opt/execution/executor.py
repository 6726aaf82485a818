"""The one executor: every plan reaches a device through here.

Pre-flight (:mod:`spm_opt.execution.preflight`), the plan must have been made for this
problem, start and end at rest, and keep every limit that judges the robot. The robot must
be where the plan starts, or, on request, is first brought there by a jerk-limited ruckig
approach; either way it then holds the start until rest is proven on it (or ``settle_s``
passes), so that the plan starts with the load taken up by the loop. A stop asked for
before or during :meth:`Executor.run` is honoured (and forgotten when the run ends):
before connecting, the run ends with nothing moved or written
(:class:`~spm_opt.base.errors.RunInterrupted`); after, in the first control cycle, before any
goal of the plan goes out. Then a fixed-rate loop on the backend's clock writes the next
goal positions, reads both actuators, checks them and logs the sample (queued in
memory: a thread of the log's own writes it, :mod:`spm_opt.execution.log`, so the loop and
the stop never wait on the disk). The goals follow the plan at the operator's feed
(:mod:`spm_opt.execution.feed`): held, resumed and overridden from any thread, always on
the planned path; a hold where the plan leaves no room for a stop on the path
(:mod:`spm_opt.judge.hold_room`) is the safe stop below, at once (the log's feed events say "no
room: safe stop"). On a hardware error, a following error beyond the tolerance, a run of
cycles with a failed read or write longer than the retry budget, a log write that failed or
stalls (in the approach, the hold at the start, the plan and the settle; during the stop
and the hold the samples wait in memory), SIGINT or SIGTERM, any other exception raised by
the backend or in the loop, the robot is brought to rest by a jerk-limited ruckig stop that
starts, in the cycle that saw the fault, from the last goal the actuators received before
it (a goal that cycle wrote before its reading showed the fault is replaced; so the goal
stream stays continuous: starting from the measured position would make the goal jump
back by the following error, and a goal whose write failed never reached them). It then
holds there until rest is proven: every sample over a window below the rest speed and each
joint's position within a few encoder pulses. The log's header reports how long the stop
took and how far each joint moved. A run is a success only when it completed and rest was
proven at its end (:attr:`ExecutionResult.succeeded`). The log's times count from the
reading the loop starts from; the header's ``clock_origin_s`` is that moment on the
backend's clock.

This module holds the run's lifecycle and its phases along the plan; a cycle's I/O and
checks are :mod:`spm_opt.execution.cycle`'s, the approach and the stop's ruckig moves
:mod:`spm_opt.execution.moves`', the safe stop :mod:`spm_opt.execution.stop`'s, the proof of
rest :mod:`spm_opt.execution.rest`'s and the feed ceiling :mod:`spm_opt.execution.ceiling`'s.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import signal
import threading
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from spm_opt.base.errors import InputError, RunInterrupted
from spm_opt.base.version import package_version
from spm_opt.execution import preflight
from spm_opt.execution.backend import CLOCK_EPSILON_S, Backend, Measurement, VirtualClock
from spm_opt.execution.ceiling import feed_ceiling
from spm_opt.execution.cycle import LATE_GOAL_S, ControlLoop, Cycle, CycleTiming, Fault
from spm_opt.execution.encoders import calibrated
from spm_opt.execution.feed import FeedProfile, FeedRequests, NoRoom, Pace
from spm_opt.execution.log import LogWriter, Write
from spm_opt.execution.moves import Segment, approach_move
from spm_opt.execution.realtime import CONTROL_FIFO_PRIORITY, frozen_heap, raised_priority
from spm_opt.execution.rest import FeedHoldWatch, RestWindow, hold_until_rest
from spm_opt.execution.results import ExecutionResult, LoopStatistics, RunStatus
from spm_opt.execution.settings import ExecutionSettings
from spm_opt.execution.stop import safe_stop
from spm_opt.execution.tracking import Lead
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

_LOG = logging.getLogger(__name__)


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
        self.backend = calibrated(backend, problem.robot.calibration)
        self.settings = settings or ExecutionSettings()
        self._log_write = log_write
        self._stop_requested: str | None = None
        self._signals_seen: list[str] = []
        self._phase = "connect"
        self._requests = FeedRequests(self.settings.feed, self.settings.max_feed)
        self._lead = Lead.for_actuator(
            problem.robot.actuator, 1.0 / self.settings.rate_hz, self.settings.tracking
        )
        self._feed_events: list[dict[str, Any]] = []
        self._loop: ControlLoop | None = None
        self._last_status: RunStatus | None = None
        self._status_changed = threading.Condition()

    @property
    def status(self) -> RunStatus | None:
        """The run as it stands after the last cycle (None before the first)."""
        return self._loop.status if self._loop is not None else self._last_status

    def next_status(self, after_s: float | None, timeout_s: float) -> RunStatus | None:
        """The status of the first cycle after log time ``after_s`` (s; None: any), as
        soon as the loop has made it, so that a reader (a live view, the navigation link)
        works between cycles rather than across one; after ``timeout_s`` (s) the status as
        it stands, newer or not (None before the first cycle)."""

        def newer() -> bool:
            status = self.status
            return status is not None and (after_s is None or status.time_s > after_s)

        with self._status_changed:
            self._status_changed.wait_for(newer, timeout_s)
        return self.status

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
        self._last_status, self._loop = self.status, None
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
        _warn_if_learned_otherwise(trajectory, self.settings)
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
            limits = self.settings.joint_limits(self.problem)
            approach = approach_move(self.settings, limits, measured.position_rad, start)
            on_the_wall_clock = not isinstance(backend.clock, VirtualClock)
            fifo = CONTROL_FIFO_PRIORITY if on_the_wall_clock else None
            with frozen_heap(), raised_priority(fifo=fifo) as priority:
                header = {
                    **header,
                    "control_thread_nice": priority.nice,
                    "control_thread_fifo": priority.fifo,
                }
                return self._run_connected(trajectory, approach, measured, log_path, header)
        finally:
            backend.close()

    def _run_connected(
        self,
        trajectory: Trajectory,
        approach: Segment | None,
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
        # the loop starts from a reading taken now, not at connecting: the simulated robot
        # integrates the time since (the heap's collection) here, where the loop's first
        # cycle did on the wall clock (its next came 61-143 ms later on a loaded machine,
        # and the reference ran on: a following error stopped runs). The header holds
        # the loop's origin from the start: rewritten 0.1 s into the run, it made a goal
        # 5-10 ms late in every simulated run on the wall clock
        first, origin = self.backend.read(), self.backend.clock.now()
        self._writer = LogWriter(
            log_path,
            {**header, "clock_origin_s": origin},
            settings.flush_interval_s,
            settings.log_stall_s,
            self._log_write,
        )
        loop = self._loop = ControlLoop(
            self.problem,
            settings,
            self.backend,
            self._lead,
            self._writer,
            self._requests,
            first,
            origin,
            trajectory.duration,
            self._last_status,
            self._status_changed,
        )
        loop.phase = self._phase
        self._feed_events = []
        reason, completed, at_rest, report, exception = "", False, False, None, None
        try:
            if approach is not None:
                self._follow("approach", approach)
            self._ready(trajectory.position(trajectory.start_time))
            self._follow_plan(trajectory)
            end = trajectory.position(trajectory.end_time)
            at_rest, why = self._settle(end)
            completed = True
            reason = "completed" if at_rest else f"completed, but rest {why}"
        except Fault as fault:
            reason = str(fault)
            report = safe_stop(loop, fault, self.problem, settings)
        except Exception as error:  # a bug in the loop: a fault like any other
            reason = f"internal error: {type(error).__name__}: {error}"
            exception = traceback.format_exception(error)
            _LOG.debug("safe stop after an internal error", exc_info=True)
            report = safe_stop(loop, Fault(reason), self.problem, settings)
        finally:
            at_rest = report.at_rest if report is not None else at_rest
            statistics = LoopStatistics.from_ticks(loop.ticker.ticks, loop.ticker.period)
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
                    "current_reads": {
                        "per_cycle": settings.current_reads_per_cycle,
                        "missed": loop.current_reads_missed,
                        "read_s": loop.current_read_s,
                    },
                    "cycle_timing": loop.timing.record(),
                    "backend": backend_state,
                    "exception": exception,
                }
            )
        if completed:  # a safe stop's one line says how the run ended
            _warn_if_goals_were_late(loop.timing)
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

    def _longest_run_s(self, trajectory: Trajectory, approach: Segment | None) -> float:
        """How long the run may log for, s, if nobody holds the feed: the approach, the
        ready hold, the plan at its starting feed, the settle, a stop from the speed limit
        and the hold."""
        limits = self.settings.joint_limits(self.problem)
        feed = min(self.settings.feed, self._requests.ceiling)
        stop = limits.speed / limits.acceleration + limits.acceleration / limits.jerk
        return (
            (approach.duration if approach is not None else 0.0)
            + trajectory.duration / feed
            + 2 * self.settings.settle_s
            + stop
            + self.settings.hold_s
        )

    # ------------------------------------------------------------------ phases
    def _follow(self, phase: str, segment: Segment) -> None:
        """Stream a segment's goals, each sampled at its cycle's start, to its end; every
        cycle is checked and a fault raises :class:`Fault`."""
        loop = self._loop
        loop.phase = phase
        begin = None
        while True:
            cycle = loop.begin()
            begin = cycle.time_s if begin is None else begin
            elapsed = min(cycle.time_s - begin, segment.duration)
            if segment.duration - elapsed < CLOCK_EPSILON_S:  # rounding must not add a cycle
                elapsed = segment.duration
            reference = segment.at(elapsed)
            loop.send(cycle, *reference)
            loop.read(cycle)
            loop.check(cycle, reference, self._stop_requested)
            loop.end(phase, cycle, checked=True)
            if elapsed >= segment.duration:
                return

    def _follow_plan(self, trajectory: Trajectory) -> None:
        """Stream the plan's goals at the pace the operator asks for, to the plan's end;
        each cycle is checked, and a fault, a hold for which no path-keeping stop fits
        (at once, in the cycle that saw it asked) or a hold longer than ``max_hold_s``
        raises :class:`Fault`."""
        loop = self._loop
        loop.phase = "plan"
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
                cycle = loop.begin()
                begin = cycle.time_s if begin is None else begin
                override, held = requested = requests.requested()
                try:
                    pace = profile.advance(cycle.time_s - begin, 0.0 if held else override)
                except NoRoom as no_room:
                    self._no_room(cycle, asked, requested, no_room)
                for event in _request_events(asked, requested):
                    self._feed_event(cycle, pace, event)
                asked = requested
                loop.pace = pace
                reference = profile.goal(pace)
                loop.send(cycle, *reference)
                loop.read(cycle)
                loop.check(cycle, reference, self._stop_requested)
                loop.end("plan", cycle, checked=True)
                for event in hold.watch(cycle.time_s, cycle.measurement, pace):
                    self._feed_event(cycle, pace, event)
                if hold.too_long(cycle.time_s):
                    reason = f"feed held longer than max_hold_s ({settings.max_hold_s:g} s)"
                    raise Fault(reason, cycle, logged=True)
                if profile.finished(pace):
                    return
        finally:
            loop.pace = None

    def _no_room(
        self,
        cycle: Cycle,
        asked: tuple[float, bool],
        requested: tuple[float, bool],
        no_room: NoRoom,
    ) -> NoReturn:
        """A hold for which no path-keeping stop fits: record it and raise :class:`Fault`,
        whose first goal goes out in this cycle."""
        pace = self._loop.pace or Pace(0.0, 0.0, 0.0, 0.0)
        for event in _request_events(asked, requested):
            self._feed_event(cycle, pace, event)
        self._feed_event(cycle, pace, "no room: safe stop")
        raise Fault(f"feed hold: {no_room}; the safe stop instead", cycle)

    def _feed_event(self, cycle: Cycle, pace: Pace, event: str) -> None:
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

    def _ready(self, start: np.ndarray) -> None:
        """Hold the plan's start until rest is confirmed or ``settle_s`` passes, so that the
        plan begins with the load taken up by the loop (a robot whose torque was just
        enabled, or that just arrived, sags under gravity first: on the family's plants
        that start broke θ1's jerk limit in the plan's first 0.1 s, whatever the plan). Rest
        counts only on the start, each joint within ``rest_position_pulses`` of it (a joint
        can stick on its friction off it while the loop's integral builds). Not proven at
        rest there, the plan starts anyway, its following error checked."""
        confirmed, window = self._hold_checked("ready", start, on_target=True)
        if confirmed is None:
            _LOG.info("rest at the start not proven: %s; the plan starts", window.why())

    def _settle(self, target: np.ndarray) -> tuple[bool, str]:
        """Hold the plan's end until rest is confirmed or ``settle_s`` passes; (True,
        "confirmed") if confirmed, else (False, "not proven within …: why")."""
        confirmed, window = self._hold_checked("settle", target)
        if confirmed is not None:
            return True, "confirmed"
        why = f"not proven within the {self.settings.settle_s:g} s settle: {window.why()}"
        _LOG.info("rest %s", why)
        return False, why

    def _hold_checked(
        self, phase: str, target: np.ndarray, on_target: bool = False
    ) -> tuple[float | None, RestWindow]:
        """Hold ``target`` (rad) in ``phase``, every cycle checked against rest there,
        until rest is confirmed (``on_target``: on ``target``) or ``settle_s`` passes
        (:func:`hold_until_rest`)."""
        loop = self._loop
        at_rest = (target, np.zeros(2), np.zeros(2))
        return hold_until_rest(
            loop,
            phase,
            target,
            self.settings.settle_s,
            self.settings,
            self.problem.robot.actuator,
            lambda cycle: loop.check(cycle, at_rest, self._stop_requested),
            checked=True,
            on_target=on_target,
        )

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
            phase = self._loop.phase if self._loop is not None else self._phase
            self._signals_seen.append(f"{name} during {phase}")
            self._stop_requested = self._stop_requested or name

        previous = {s: signal.signal(s, request) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)


def _warn_if_goals_were_late(timing: CycleTiming) -> None:
    """Warn once after a completed run whose goals reached the actuators late
    (:data:`LATE_GOAL_S`): each makes an uneven step the plan does not have, and the joints'
    jerk may break its limit there (``spm-opt evaluate`` names the limits broken near
    one)."""
    if timing.late_count:
        _LOG.warning(
            "%d goal(s) reached the actuators more than %.0f ms late (the latest %.1f ms, "
            "the first at %.3f s): the control computer's loop lost time; keep its cores free "
            "during a run",
            timing.late_count,
            1000 * LATE_GOAL_S,
            1000 * timing.latest_s,
            timing.late[0][0],
        )


def _request_events(before: tuple[float, bool], after: tuple[float, bool]) -> list[str]:
    """What the operator asked for since ``before`` (override, held): "feed 60%", "hold",
    "resume"."""
    events = [] if after[0] == before[0] else [f"feed {after[0]:.0%}"]
    if after[1] != before[1]:
        events.append("hold" if after[1] else "resume")
    return events


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


def _warn_if_learned_otherwise(trajectory: Trajectory, settings: ExecutionSettings) -> None:
    """Warn when a compensated plan (:mod:`spm_opt.verify.compensation`) runs at a starting
    feed, a rate or a tracking other than those its correction was learned at."""
    learned = trajectory.metadata.get("compensation")
    if not isinstance(learned, dict):
        return
    now = {"feed": settings.feed, "rate_hz": settings.rate_hz, "tracking": settings.tracking}
    other = [
        f"{key} {learned.get(key)} (now {value})"
        for key, value in now.items()
        if learned.get(key) != value
    ]
    if other:
        _LOG.warning(
            "this plan's correction was learned at %s: it repeats what it learned only as "
            "it was learned",
            ", ".join(other),
        )
