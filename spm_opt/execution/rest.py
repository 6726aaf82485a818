"""Proof of rest: after a stop, at a plan's start and end and in a feed hold, the robot
counts as at rest only over a window of readings, never on one."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np

from spm_opt.execution.backend import CLOCK_EPSILON_S, Measurement
from spm_opt.execution.cycle import ControlLoop, Cycle
from spm_opt.execution.feed import Pace
from spm_opt.execution.settings import ExecutionSettings
from spm_opt.model.actuator import Actuator


class RestWindow:
    """Proof of rest: consecutive samples covering ``window_s``, every one slower than
    ``speed`` (rad/s), over which each joint's position spans fewer than ``pulses``; given
    a ``target`` (rad, as the actuators read), every one also fewer than ``pulses`` from
    it."""

    def __init__(
        self, settings: ExecutionSettings, actuator: Actuator, target: np.ndarray | None = None
    ) -> None:
        self._speed = settings.rest_speed_rad_s
        self._window = settings.rest_window_s
        self._pulses = settings.rest_position_pulses
        self._actuator = actuator
        self._target = None if target is None else actuator.pulses(target)
        self._samples: deque[tuple[float, np.ndarray]] = deque()
        self._why = "no reading"

    def add(self, time_s: float, measurement: Measurement | None) -> bool:
        """One sample at ``time_s`` (s); True once rest is confirmed."""
        if measurement is None:
            return self._restart("a read failed")
        speed = np.abs(measurement.velocity_rad_s)
        if np.any(speed >= self._speed):
            j = int(np.argmax(speed))
            return self._restart(f"theta{j + 1} at {speed[j]:.4f} rad/s")
        pulses = self._actuator.pulses(measurement.position_rad)
        if self._target is not None:
            off = np.abs(pulses - self._target)
            if np.any(off >= self._pulses):
                j = int(np.argmax(off))
                return self._restart(f"theta{j + 1} {off[j]} pulses from its goal")
        self._samples.append((time_s, pulses))
        while (span := self._span()).max() >= self._pulses:
            j = int(np.argmax(span))
            self._why = f"theta{j + 1} moved {span[j]} pulses in {self._covered():.3f} s"
            self._samples.popleft()
        return self._covered() >= self._window - CLOCK_EPSILON_S

    def why(self) -> str:
        """Why rest is not confirmed (yet), in a few words."""
        return f"{self._why}; at rest for the last {self._covered():.3f} s of {self._window:g} s"

    def _restart(self, why: str) -> bool:
        self._samples.clear()
        self._why = why
        return False

    def _span(self) -> np.ndarray:
        pulses = np.array([p for _, p in self._samples])
        return pulses.max(axis=0) - pulses.min(axis=0)

    def _covered(self) -> float:
        return self._samples[-1][0] - self._samples[0][0] if self._samples else 0.0


class FeedHoldWatch:
    """Watches a feed hold: when the feed reached 0, when rest was confirmed, and how long
    it has lasted."""

    def __init__(self, settings: ExecutionSettings, actuator: Actuator) -> None:
        self._settings, self._actuator = settings, actuator
        self._since: float | None = None
        self._rest: RestWindow | None = None

    def watch(self, time_s: float, measurement: Measurement | None, pace: Pace) -> list[str]:
        """The hold's events in the cycle that began at ``time_s`` (s) and read
        ``measurement``: "held" (the feed reached 0 on the path), "at rest" (rest
        confirmed, as after a stop)."""
        if pace.feed > 0.0 or pace.target > 0.0:
            self._since, self._rest = None, None
            return []
        events = []
        if self._since is None:
            self._since = time_s
            self._rest = RestWindow(self._settings, self._actuator)
            events.append("held")
        if self._rest is not None and self._rest.add(time_s, measurement):
            self._rest = None
            events.append("at rest")
        return events

    def too_long(self, time_s: float) -> bool:
        """The hold has lasted longer than ``max_hold_s``."""
        return self._since is not None and time_s - self._since > self._settings.max_hold_s


def hold_until_rest(
    loop: ControlLoop,
    phase: str,
    target: np.ndarray,
    limit_s: float,
    settings: ExecutionSettings,
    actuator: Actuator,
    inspect: Callable[[Cycle], None],
    checked: bool,
    on_target: bool = False,
) -> tuple[float | None, RestWindow]:
    """Hold ``target`` (rad), each cycle's reading given to ``inspect`` (which raises
    :class:`~spm_opt.execution.cycle.Fault` on a fault; ``checked``: a run of failed
    cycles is one too), until rest is confirmed (``on_target``: at rest on ``target``) or
    ``limit_s`` (s) passes; returns the time rest was confirmed (None if not) and the
    window."""
    loop.phase = phase
    window = RestWindow(settings, actuator, target if on_target else None)
    begin = None
    while True:
        cycle = loop.begin()
        begin = cycle.time_s if begin is None else begin
        loop.send(cycle, target, np.zeros(2), np.zeros(2))
        loop.read(cycle)
        inspect(cycle)
        loop.end(phase, cycle, checked=checked)
        if window.add(cycle.time_s, cycle.measurement):
            return cycle.time_s, window
        if cycle.time_s - begin >= limit_s - CLOCK_EPSILON_S:
            return None, window
