"""One control cycle's I/O and checks: wait for the deadline, write the goal, read both
actuators, judge the reading, count the failures and log the sample.

The goal goes out before the read (but where current reads are asked for, below). A goal
depends only on the plan, the feed and the stop, never on the cycle's own reading, and
the read is a bus transaction whose replies take as long as the actuators and the
machine let them: through the SDK and the emulated actuators with two busy loops holding
both cores, 40 of the hardware problem's 48 runs had goals late, up to 10.8 ms, while
the reads came before the write, and 7 of the 32 led and unled runs broke a joint limit
their predictions kept (up to 1.709 times the predicted jerk); with the write first, 10
of 48 had late goals and 1 broke a limit, beside a goal 12.1 ms late
(``docs/guide/executed-cut.md``). A reading that asks for the safe stop is seen just
after the write, and the stop's first goal replaces that cycle's goal at once, from the
goal before it (:attr:`Cycle.before`): the stream is the one a check before the write
gives, with the plan's goal held for the read's duration in between.

The current a cycle logs is the cycle's own Present Current read, or, with
:attr:`~spm_opt.execution.settings.ExecutionSettings.current_reads_per_cycle` N > 0, the
mean over the last goal's hold: N reads, one at a random instant in each of N equal parts
of the span from that goal's write to two average reads before the deadline, and the
cycle's own read for the rest, up to this cycle's write (weighted by their spans). So with
N > 0 (identification's excitation logs) the cycle reads before it writes: its own read
made just after the write, which on the emulated actuators may sample the new goal's hold,
put viscous friction of +0.020 N·m·s/rad where there is none into
``tests/test_identify_pipeline.py``'s identification (+0.012 in a fresh-clone run).

Why. A goal is a step, and the actuator's velocity loop answers each step with a current
that surges and then reverses within the period; one read, made at the same instant of
every period, samples that ripple at one phase and turns it into a steady error. Measured
on the simulated robot equal to its model (``problems/identification.toml``'s excitation
at 100 Hz, the plant's current at every 1 ms step): the read just before the goal write
lay below the period's mean current by 0.0140 and 0.0119 A per rad/s of the joint's rate
(0.103 and 0.088 N·m·s/rad), what identification took for viscous friction of −0.112 and
−0.095. Reads at fixed instants fail the same way, less, wherever the actuator applies a
goal later than the write returns: through the SDK and the emulated actuators (which
apply it some 0.5 ms later, more on a loaded machine), 2 and 4 reads at the parts'
middles gave viscous friction of +0.010 to +0.035 N·m·s/rad where there is none, and 2
placed from the deadline rather than the write +0.053. One read at a random instant in
each part (stratified sampling) makes the mean's expectation the current's mean over the
span wherever the goal took effect in it: 4 such reads gave −0.0015 ± 0.0015 and
−0.0027 ± 0.0014 there (``tests/test_identify_pipeline.py``). On the simulated robot,
whose current is constant over each 1 ms step, 10 reads at 100 Hz read every step once.
The mean refers to about the middle of the period, half a period before the cycle's time
(:mod:`spm_opt.identify.samples`).

The same reads' torques are also logged in two sides, positive and negative, each read on
the side its neighbours' sign gives (:mod:`spm_opt.execution.torque_sides`; the cycle's own
read last among them). Where a gear train loses (η < 1), the load gets η τ from a
motor that drives it and τ / η from one it drives back, and the velocity loop's answer to
each goal step swings the motor's torque across zero within the period: on the simulated
robot with η 0.75 and a velocity loop of 227 1/s (``problems/identification.toml``'s
excitation, 30 s), the torque swung by 0.33 and 0.23 N·m within the median period, against
loads of 0.19 and 0.08 N·m, and the side changed within half the periods. The period's mean
torque then is no model's torque at the period's mean motion; its two sides are: the
load's mean torque is η times the driving side plus the driven side over η
(:mod:`spm_opt.identify.estimate`). A read that fails or whose part has passed is left out
and counted; the stop makes none. Each read is a bus transaction: the loop's timing pays
for them (``docs/guide/run.md``).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import random
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spm_opt.base.errors import CommunicationError
from spm_opt.execution import torque_sides
from spm_opt.execution.backend import Backend, Clock, Measurement, hardware_error_names
from spm_opt.execution.feed import FeedRequests, Pace
from spm_opt.execution.log import LogWriter
from spm_opt.execution.results import RunStatus
from spm_opt.execution.settings import ExecutionSettings
from spm_opt.execution.tracking import Lead, following_error_limit
from spm_opt.model.params import DEG
from spm_opt.problem.problem import Problem

_LOG = logging.getLogger(__name__)

CURRENT_READ_SMOOTHING = 0.1
"""Weight of each current read's duration in their moving average."""
CURRENT_READ_MARGIN = 2.0
"""Current reads are spread over the span that ends this many average reads before the
cycle's deadline, so that the cycle's own read seldom waits for one."""
INTERRUPTED = "interrupted"
"""How the reason of a run ended by a stop asked for (SIGINT, SIGTERM, a key, STOP) begins."""


class Ticker:
    """The loop's schedule: deadlines every period on the backend's clock, from ``origin``
    (a time on it, s: the first deadline); a late cycle skips the deadlines it missed
    rather than running them in a burst. Times it gives are since ``origin`` (the log's
    clock)."""

    def __init__(self, clock: Clock, period: float, origin: float) -> None:
        self.clock, self.period = clock, period
        self.origin = origin
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

    @property
    def deadline(self) -> float:
        """The next deadline, on the clock, s."""
        return self._next


LATE_GOAL_S = 0.002
"""A goal is late when it reached the actuators more than this (s) after an even stream
would have brought it (:meth:`CycleTiming.wrote`). Through the SDK and the emulated
actuators under the real-time policy, each goal written before its cycle's read, 17 of 48
runs of the hardware problem had a late goal on an idle machine, up to 13.4 ms, and 10 of
48 with two busy loops holding both cores, up to 12.1 ms (``docs/guide/executed-cut.md``)."""

LATE_GOALS_KEPT = 100
"""How many late goals the header lists (the first; all are counted)."""


@dataclass
class CycleTiming:
    """When, after a cycle's time, its read sampled the actuators (the read call's
    middle) and its goal write returned: the means over the run, s, each offset within one
    period. Identification's replay (:mod:`spm_opt.identify.velocity_replay`) reads and
    writes its model at these instants; on the simulated robot both are 0. And the goals
    that were late (:data:`LATE_GOAL_S`): the judge names the robot limits a run broke
    just after one (:mod:`spm_opt.verify.executed_cut`)."""

    period_s: float
    read_sum_s: float = 0.0
    reads: int = 0
    write_sum_s: float = 0.0
    writes: int = 0
    late: list[tuple[float, float]] = field(default_factory=list)
    late_count: int = 0
    latest_s: float = 0.0
    _arrived_s: float = 0.0
    _delay_s: float = 0.0

    def read(self, offset_s: float) -> None:
        """Count one read made ``offset_s`` after its cycle's time."""
        self.read_sum_s += min(max(offset_s, 0.0), self.period_s)
        self.reads += 1

    def wrote(self, time_s: float, offset_s: float, sampled_s: float) -> None:
        """Count one goal write of the cycle at ``time_s`` (s) that returned ``offset_s``
        after it, its reference sampled ``sampled_s`` after it (at the write's start, where
        the lead carries it). A steady delay between a reference's instant
        and its goal's arrival shifts the stream and does no harm; the goal is late by the
        longer of how much longer its delay was than the goal before's and how much longer
        than a period after that goal it arrived (the goal before held longer)."""
        self.write_sum_s += min(max(offset_s, 0.0), self.period_s)
        self.writes += 1
        arrived, delay = time_s + offset_s, offset_s - sampled_s
        late = max(delay - self._delay_s, arrived - self._arrived_s - self.period_s)
        self._arrived_s, self._delay_s = arrived, delay
        if self.writes > 1 and late > LATE_GOAL_S:  # the first has no goal before it
            self.late_count += 1
            self.latest_s = max(self.latest_s, late)
            if len(self.late) < LATE_GOALS_KEPT:
                self.late.append((time_s, late))

    def record(self) -> dict[str, Any]:
        """The header's ``cycle_timing``: ``read_s`` and ``goal_written_s``, the means;
        ``late_goals``: how many were late, the latest (s) and the first
        :data:`LATE_GOALS_KEPT` as [cycle's time, late by] (s)."""
        return {
            "read_s": self.read_sum_s / max(self.reads, 1),
            "goal_written_s": self.write_sum_s / max(self.writes, 1),
            "late_goals": {
                "threshold_s": LATE_GOAL_S,
                "count": self.late_count,
                "latest_s": self.latest_s,
                "first": [list(entry) for entry in self.late],
            },
        }


@dataclass
class Commanded:
    """The reference of the last goal the actuators received: position, rate, acceleration
    (the stop starts from here), and that goal (the reference led by the loop's lag)."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    goal: np.ndarray


@dataclass
class Cycle:
    """One control cycle: when it began (s, the time its goal is sampled at), what it
    read and what went wrong (``notes``; ``unexpected``: the backend raised something
    other than :class:`CommunicationError`, a fault at once)."""

    time_s: float
    measurement: Measurement | None = None
    held_current: tuple[np.ndarray, float, float] | None = None
    """The mean Present Current (A) of the reads while the last goal was held, and the
    span they covered, from that goal's write to its end (s, on the clock)."""
    held_reads: np.ndarray | None = None
    """The same reads (k, 2), A, in the order they were made."""
    written_at: float | None = None
    """When this cycle's goal write returned, on the clock (s)."""
    before: Commanded | None = None
    """The commanded state before this cycle's first goal write (None until one was
    tried): a fault its reading shows stops from here, the stop's first goal replacing
    this cycle's (:func:`~spm_opt.execution.stop.safe_stop`)."""
    read_made: bool = False
    """Whether its actuators were read (:meth:`ControlLoop.read`), successfully or not."""
    following_error: np.ndarray | None = None
    read_failed: bool = False
    write_failed: bool = False
    unexpected: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def status(self) -> str:
        """The log's status: "ok", or the notes."""
        return "; ".join(self.notes) or "ok"


class Fault(Exception):
    """Raised to end the run in a safe stop. ``cycle`` saw the fault; ``logged``: it is
    finished (its goal sent, its sample logged), else the stop's first goal goes out in
    it."""

    def __init__(self, reason: str, cycle: Cycle | None = None, logged: bool = False) -> None:
        super().__init__(reason)
        self.cycle, self.logged = cycle, logged


class ControlLoop:
    """The cycles of one connected run, on ``backend``'s clock at the settings' rate.

    Keeps what the cycles share: the commanded state, the last reading, the failed reads
    and writes (in a row, and in all), the current reads between goals that were missed
    (``current_reads_missed``) and the time one takes (``current_read_s``, s, a moving
    average), the pace along the plan (``pace``, None outside the
    plan phase), the phase (``phase``, for the signals' record) and :attr:`status`.

    Parameters
    ----------
    problem, settings : the run's limits and settings.
    backend : Backend
    lead : Lead
        How a goal leads its reference.
    writer : LogWriter
        The log every cycle's sample goes to.
    requests : FeedRequests
        The operator's requests (the status says whether the feed is held).
    first : Measurement
        The reading taken just before the log was written: the commanded state starts at
        rest there.
    origin_s : float, s
        The loop's start on the backend's clock (its first deadline; the log's time 0),
        taken with ``first`` (the log's header holds it).
    plan_duration_s : float, s
    previous : RunStatus or None
        The status before this run (its plan time shows until the plan phase begins).
    status_changed : threading.Condition, optional
        Notified after each new :attr:`status`, for a reader that works between cycles.
    """

    def __init__(
        self,
        problem: Problem,
        settings: ExecutionSettings,
        backend: Backend,
        lead: Lead,
        writer: LogWriter,
        requests: FeedRequests,
        first: Measurement,
        origin_s: float,
        plan_duration_s: float,
        previous: RunStatus | None,
        status_changed: threading.Condition | None = None,
    ) -> None:
        self._status_changed = status_changed
        self._problem, self._settings = problem, settings
        self._backend, self._lead, self._writer = backend, lead, writer
        self._requests = requests
        self._torque_map = problem.robot.actuator.current_map
        self._current_unit_a = problem.robot.actuator.current_unit_a
        self._plan_duration = plan_duration_s
        self.ticker = Ticker(backend.clock, 1.0 / settings.rate_hz, origin_s)
        at = first.position_rad.copy()
        self.commanded = Commanded(at, np.zeros(2), np.zeros(2), at)
        self.last_measurement = first
        self.failed_cycles = self.reads_failed = self.writes_failed = 0
        self.current_reads_missed = 0
        self.current_read_s = 0.0
        self.timing = CycleTiming(self.ticker.period)
        self._goal_written_at = -math.inf
        self._phases = random.Random(0)  # where in its part each current read falls
        self.previous = (-self.ticker.period, True)
        """(the last cycle's time, s; whether its goal was delivered)."""
        self.pace: Pace | None = None
        self.phase = "connect"
        self.status = previous

    # ------------------------------------------------------------------ I/O
    def begin(self) -> Cycle:
        """Read the current while the last goal is held and wait for the next deadline:
        the cycle, its goal yet to be sent (:meth:`send`) and its actuators read
        (:meth:`read`), unless current reads are asked for (outside the stop): then it reads
        them now, before the write, for the hold's last part (the module's docstring)."""
        currents, span, unexpected = self._currents_between()
        cycle = Cycle(self.ticker.wait())
        if currents:
            cycle.held_current = (np.mean(currents, axis=0), *span)
            cycle.held_reads = np.array(currents)
        if unexpected is not None:
            cycle.notes.append(self._failure("current read", unexpected, cycle))
        if self._settings.current_reads_per_cycle and self.phase != "stop":
            self.read(cycle)  # the hold's last part: read before the write
        return cycle

    def read(self, cycle: Cycle) -> None:
        """Read both actuators into ``cycle`` once (again, nothing); the reading's current
        is the mean of the period's current reads, if any was made."""
        if cycle.read_made:
            return
        cycle.read_made = True
        try:
            before = self._backend.clock.now()
            cycle.measurement = self.last_measurement = self._backend.read()
            middle = 0.5 * (before + self._backend.clock.now()) - self.ticker.origin
            self.timing.read(middle - cycle.time_s)
        except Exception as error:  # noqa: BLE001 - any failure of the device is a fault
            cycle.read_failed = True
            self.reads_failed += 1
            cycle.notes.append(self._failure("read", error, cycle))

    def _currents_between(
        self,
    ) -> tuple[list[np.ndarray], tuple[float, float], Exception | None]:
        """The Present Current reads, one at a random instant in each of equal parts of the
        span from the last goal's write to when a read must begin to end before the
        deadline (twice the time reads take); none in the stop. A read that fails or whose
        part has passed is counted in :attr:`current_reads_missed`. Returns the reads, the
        span (its beginning and end on the clock, s) and an unexpected exception (one other than
        :class:`CommunicationError`), if a read raised one."""
        count = self._settings.current_reads_per_cycle
        deadline = self.ticker.deadline
        if count == 0 or self.phase == "stop" or not self.ticker.ticks:
            return [], (deadline, deadline), None
        clock = self._backend.clock
        begin = max(self._goal_written_at, deadline - self.ticker.period)
        end = max(deadline - CURRENT_READ_MARGIN * self.current_read_s, begin)
        spacing, currents = (end - begin) / count, []
        for k in range(count):
            clock.sleep_until(begin + (k + self._phases.random()) * spacing)
            start = clock.now()
            if start > begin + (k + 1) * spacing:  # its part has passed
                self.current_reads_missed += 1
                continue
            try:  # its replies awaited only until the deadline
                currents.append(self._backend.read_current(deadline - start))
            except CommunicationError:
                self.current_reads_missed += 1
            except Exception as error:  # noqa: BLE001 - any other failure is a fault
                return currents, (begin, end), error
            took = clock.now() - start
            self.current_read_s += CURRENT_READ_SMOOTHING * (took - self.current_read_s)
        return currents, (begin, end), None

    def send(
        self, cycle: Cycle, position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray
    ) -> bool:
        """Write the goal of a reference state at the cycle's time (carried on to the write
        and led by the loop's lag: :meth:`~spm_opt.execution.tracking.Lead.written_goal`);
        only a write that succeeded becomes the commanded state. A write reported failed
        counts as not delivered, though a port can fail a packet that left (see
        :mod:`spm_opt.execution.dynamixel`); the stop's first goal, one period along from
        the last goal known, is then the one that arrived to within q̈ T²."""
        commanded = self.commanded
        if cycle.before is None:
            cycle.before = dataclasses.replace(commanded)
        late = self._backend.clock.now() - self.ticker.origin - cycle.time_s
        goal = self._lead.written_goal(position, velocity, acceleration, late)
        try:
            self._backend.write_goal(goal)
        except Exception as error:  # noqa: BLE001 - any failure of the device is a fault
            cycle.write_failed = True
            self.writes_failed += 1
            cycle.notes.append(self._failure("write", error, cycle))
            return False
        cycle.written_at = self._goal_written_at = self._backend.clock.now()
        self.timing.wrote(cycle.time_s, cycle.written_at - self.ticker.origin - cycle.time_s, late)
        commanded.position, commanded.velocity = position, velocity
        commanded.acceleration, commanded.goal = acceleration, goal
        return True

    def end(self, phase: str, cycle: Cycle, checked: bool) -> None:
        """Count the cycle (failed if its read or its write did) and log it; when
        ``checked``, a run of failures past the retry budget, a write that raised the
        unexpected or a failed log is a fault: raises :class:`Fault` (the cycle logged)."""
        failed = cycle.read_failed or cycle.write_failed
        self.failed_cycles = self.failed_cycles + 1 if failed else 0
        self.previous = (cycle.time_s, not cycle.write_failed)
        reason = ""
        if checked and cycle.unexpected:
            reason = cycle.unexpected
        elif checked and self.failed_cycles > self._settings.communication_retries:
            reason = self._communication_lost(self.failed_cycles, cycle)
            cycle.notes.append(reason)
        self._log(phase, cycle)
        if checked and not reason and self._writer.fault:
            reason = f"log failed: {self._writer.fault}"
        if reason:
            raise Fault(reason, cycle, logged=True)

    def _failure(self, what: str, error: Exception, cycle: Cycle) -> str:
        """The note of a read or write that raised: a :class:`CommunicationError` is a
        failed transaction (counted against the retry budget); anything else is
        unexpected, a fault at once."""
        if isinstance(error, CommunicationError):
            _LOG.info("%s failed: %s", what, error)
            return f"{what} failed: {error}"
        cycle.unexpected = f"the backend's {what} raised {type(error).__name__}: {error}"
        _LOG.debug("%s raised", what, exc_info=True)
        return cycle.unexpected

    # --------------------------------------------------------------- checks
    def check(
        self,
        cycle: Cycle,
        reference: tuple[np.ndarray, np.ndarray, np.ndarray],
        stop_requested: str | None,
    ) -> None:
        """Raise :class:`Fault` on an interrupt (``stop_requested``: why), too many failed
        cycles (this one's read included), a hardware error or a following error (the
        measured position against the reference ``(position, rate, acceleration)`` at the
        cycle's time); the reason joins the notes."""
        reason = self.fault(cycle, reference[0], reference[1], stop_requested)
        if reason:
            if reason not in cycle.notes:
                cycle.notes.append(reason)
            raise Fault(reason, cycle)

    def fault(
        self,
        cycle: Cycle,
        expected: np.ndarray,
        rate: np.ndarray,
        stop_requested: str | None,
    ) -> str:
        """Why the run must stop after this cycle's reading ("" if it need not): see
        :meth:`check`. Records the following error in the cycle."""
        if stop_requested:
            return f"{INTERRUPTED} ({stop_requested})"
        if cycle.unexpected:
            return cycle.unexpected
        failures = self.failed_cycles + 1 if cycle.read_failed else 0
        if failures > self._settings.communication_retries:
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
            speed, self._problem.limits.max_joint_speed, *self._settings.following_error_bounds
        )
        worst = int(np.argmax(error / allowed))
        if error[worst] > allowed[worst]:
            return (
                f"following error of theta{worst + 1}: {error[worst] / DEG:.3f} deg "
                f"(tolerance {allowed[worst] / DEG:.3f} deg at {speed[worst]:.3f} rad/s)"
            )
        return ""

    def _communication_lost(self, failures: int, cycle: Cycle) -> str:
        return (
            f"communication lost: {failures} cycles in a row with a failed read or write "
            f"(retry budget {self._settings.communication_retries}); last: {cycle.status}"
        )

    # ------------------------------------------------------------------ log
    def _log(self, phase: str, cycle: Cycle) -> None:
        """One sample: the pace along the plan (in its phase), the goal the actuators hold
        (the last delivered) and the reading; the same as :attr:`status`."""
        commanded, measurement, pace = self.commanded, cycle.measurement, self.pace
        reference, goal = commanded.position, commanded.goal
        along = None if pace is None else (pace.plan_time_s, pace.feed, pace.target)
        torque = None
        if measurement is None:
            self._writer.append(
                cycle.time_s, phase, along, reference, goal, None, None, cycle.status
            )
        else:
            own = measurement.current_a
            held_mean = None if cycle.held_current is None else cycle.held_current[0]
            current = self._over_hold(cycle, own, held_mean)
            torque = self._torque_map.torque(current)
            sides = [
                self._over_hold(cycle, own_part, held_part)
                for own_part, held_part in zip(*self._sides(cycle.held_reads, own), strict=True)
            ]
            values = (measurement.position_rad, measurement.velocity_rad_s, current, torque, *sides)
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

    def _sides(
        self, held: np.ndarray | None, own: np.ndarray
    ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray | None, np.ndarray | None]]:
        """The torques' positive and negative sides (:mod:`spm_opt.execution.torque_sides`),
        N·m, each (2,): of the cycle's own read (currents ``own`` (2,), A) and of the
        reads while the last goal was held (``held`` (k, 2), A, or None: then None), the own
        read last in their order."""
        reads = own[None, :] if held is None else np.vstack([held, own])
        torques = self._torque_map.torque(reads)
        shares = torque_sides.side_shares(reads, self._current_unit_a)
        own_sides = torque_sides.sides(torques[-1:], shares[-1:])
        if held is None:
            return own_sides, (None, None)
        return own_sides, torque_sides.sides(torques[:-1], shares[:-1])

    @staticmethod
    def _over_hold(cycle: Cycle, own: np.ndarray, held: np.ndarray | None) -> np.ndarray:
        """A value the cycle logs: ``own``, of its own read, or, with reads while the last
        goal was held (``held``, their mean), the mean over that goal's hold: theirs over
        their span and the cycle's own over the rest, up to this cycle's write."""
        if held is None or cycle.held_current is None:
            return own
        _, begin, end = cycle.held_current
        rest = 0.0 if cycle.written_at is None else max(cycle.written_at - end, 0.0)
        return (held * (end - begin) + own * rest) / max(end - begin + rest, 1e-12)

    def _update_status(self, phase: str, cycle: Cycle, torque: np.ndarray | None) -> None:
        """Replace :attr:`status` (one assignment: a reader in another thread sees the old
        status or the new one, whole)."""
        pace, (_, held) = self.pace, self._requests.requested()
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
            measured_rad=None
            if cycle.measurement is None
            else (
                float(cycle.measurement.position_rad[0]),
                float(cycle.measurement.position_rad[1]),
            ),
        )
        if self._status_changed is not None:
            with self._status_changed:
                self._status_changed.notify_all()


def observe_hardware_errors(cycle: Cycle, errors: list[str]) -> None:
    """During the stop and the hold: add the hardware errors ``cycle`` read to ``errors``
    (each once)."""
    if cycle.measurement is None:
        return
    for joint, status_bits in enumerate(cycle.measurement.hardware_error):
        if status_bits:
            entry = f"actuator {joint + 1}: {', '.join(hardware_error_names(status_bits))}"
            if entry not in errors:
                _LOG.warning("hardware error while stopping: %s", entry)
                errors.append(entry)
