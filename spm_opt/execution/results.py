"""What a run reports: the loop's timing, how a stop went, the run as it stands for a live
view, and how it ended (SI; times on the log's clock)."""

from __future__ import annotations

import signal
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spm_opt.base.errors import StopAsked


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


@dataclass(frozen=True)
class StopReport:
    """How a safe stop went (SI; times on the log's clock, its ``time_s``).

    Attributes
    ----------
    fault_seen_s : float, s
        When the fault was seen: the start of the cycle that saw it.
    stop_delivered : bool
        Every goal of the stop reached the actuators.
    at_rest : bool
        Rest confirmed over the rest window (see :class:`ExecutionSettings`).
    rest : str
        "confirmed", or "not confirmed within the … s hold: " and why.
    duration_s : float or None, s
        From the fault seen to rest confirmed (None when it was not).
    travel_rad, travel_deg : list of float, or None
        How far each joint moved after the fault was seen, as measured: from the last
        reading at or before it to the last reading of the hold (None without both).
    failed_reads, failed_writes : int
        Transactions that failed during the stop and the hold.
    hardware_errors : list of str
        Hardware errors the actuators reported during the stop and the hold.
    """

    fault_seen_s: float
    stop_delivered: bool
    at_rest: bool
    rest: str
    duration_s: float | None
    travel_rad: list[float] | None
    travel_deg: list[float] | None
    failed_reads: int
    failed_writes: int
    hardware_errors: list[str]


@dataclass(frozen=True)
class RunStatus:
    """The run as it stands after a control cycle, for a live view (SI).

    Attributes
    ----------
    time_s : float, s
        The log's time (since the loop's start).
    phase : str
        "approach", "ready" (the hold at the plan's start), "plan", "settle", "stop" or
        "hold" (after a stop).
    plan_time_s, plan_duration_s : float, s
        How far along the plan the goal is (τ), and the plan's length.
    feed, feed_target : float
        The pace (1: as planned) and the pace it is heading for.
    held : bool
        The operator holds the feed.
    following_error_rad : float or None, rad
        The larger joint's distance from its goal (None in a cycle not checked).
    torque_nm : tuple of float, or None, N·m
        The actuators' torques from their current (None after a failed read).
    status : str
        The log's status of the cycle.
    measured_rad : tuple of float, or None, rad
        The joint angles the cycle read, as the log records them (None after a failed
        read).
    """

    time_s: float
    phase: str
    plan_time_s: float
    plan_duration_s: float
    feed: float
    feed_target: float
    held: bool
    following_error_rad: float | None
    torque_nm: tuple[float, float] | None
    status: str
    measured_rad: tuple[float, float] | None = None


@dataclass(frozen=True)
class LogReport:
    """What the execution log kept.

    Attributes
    ----------
    samples : int
        Samples the run logged.
    samples_written : int
        Of those, the lines the CSV holds (whole lines, in order from the first).
    fault : str or None
        Why the log failed (a write that raised or stalled), or None.
    header_written : bool
        The header was replaced with the run's outcome.
    """

    samples: int
    samples_written: int
    fault: str | None
    header_written: bool

    @property
    def samples_lost(self) -> int:
        """Samples the CSV does not hold."""
        return self.samples - self.samples_written

    def record(self) -> dict[str, Any]:
        """The header's ``log`` entry."""
        return {
            "samples": self.samples,
            "samples_written": self.samples_written,
            "samples_lost": self.samples_lost,
            "fault": self.fault,
        }

    def summary(self) -> str:
        """What the CSV and the header hold, in one phrase."""
        header = "records" if self.header_written else "lacks"
        return (
            f"the log holds {self.samples_written} of {self.samples} samples (whole lines); "
            f"its header {header} the outcome"
        )


@dataclass
class ExecutionResult:
    """How a run ended. ``completed`` is False when it ended in a safe stop; ``reason``
    says why, in one line (also when rest was not proven after a completed plan);
    ``at_rest``: rest was proven at the end; ``stop`` says how the stop went; ``signals``
    lists every SIGINT and SIGTERM received, with the phase it arrived in; ``feed_events``
    every hold, resume and override, with its time (s, the log's clock) and plan time, as
    the header has them; ``log`` what the log kept (None for a run that logged nothing)."""

    completed: bool
    reason: str
    log_path: Path
    samples: int
    statistics: LoopStatistics
    at_rest: bool
    backend: dict[str, Any] = field(default_factory=dict)
    stop: StopReport | None = None
    signals: list[str] = field(default_factory=list)
    feed_events: list[dict[str, Any]] = field(default_factory=list)
    log: LogReport | None = None

    @property
    def succeeded(self) -> bool:
        """The plan ran to its end and rest was proven after it."""
        return self.completed and self.at_rest

    def raise_if_signalled(self) -> None:
        """Raise :class:`~spm_opt.base.errors.StopAsked` if a SIGINT or SIGTERM reached
        this run. The executor answers a signal with the safe stop and returns; a script
        making runs one after another calls this after each, so that the signal ends the
        script rather than the run alone and the next run never starts."""
        if self.signals:
            first = self.signals[0]
            number = signal.Signals[first.split()[0]]
            raise StopAsked(
                f"{first}: the run ended in its safe stop ({self.reason}); no further run was made",
                number,
            )
