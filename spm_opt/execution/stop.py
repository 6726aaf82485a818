"""The safe stop: a jerk-limited ruckig stop from the last goal the actuators received,
then a hold there until rest is proven, and the report of where it ended."""

from __future__ import annotations

import logging

import numpy as np

from spm_opt.execution.backend import CLOCK_EPSILON_S, Measurement
from spm_opt.execution.cycle import ControlLoop, Cycle, Fault, observe_hardware_errors
from spm_opt.execution.moves import Segment, jerk_limited_move
from spm_opt.execution.rest import hold_until_rest
from spm_opt.execution.results import StopReport
from spm_opt.execution.settings import ExecutionSettings
from spm_opt.model.params import DEG
from spm_opt.problem.problem import Problem

_LOG = logging.getLogger(__name__)


def safe_stop(
    loop: ControlLoop, fault: Fault, problem: Problem, settings: ExecutionSettings
) -> StopReport:
    """Stop from the last goal delivered, in the cycle that saw ``fault`` (unless that one
    is already logged; a goal that cycle wrote before its reading showed the fault is
    replaced: the stop starts from the goal before it), hold there and report how it
    ended."""
    _LOG.info("safe stop: %s", fault)
    loop.phase = "stop"
    seen = fault.cycle.time_s if fault.cycle is not None else loop.ticker.now()
    before = loop.last_measurement
    reads, writes = loop.reads_failed, loop.writes_failed
    errors: list[str] = []
    first = None if fault.logged else fault.cycle
    origin = loop.commanded if first is None or first.before is None else first.before
    segment = jerk_limited_move("stop", origin, settings.joint_limits(problem), target=None)
    delivered = _stream(loop, segment, first, errors, seen + segment.duration + settings.hold_s)
    at_rest, rest, confirmed = _hold(loop, problem, settings, errors)
    travel = _travel(before, loop.last_measurement)
    return StopReport(
        fault_seen_s=seen,
        stop_delivered=delivered,
        at_rest=at_rest,
        rest=rest,
        duration_s=None if confirmed is None else confirmed - seen,
        travel_rad=travel,
        travel_deg=None if travel is None else [t / DEG for t in travel],
        failed_reads=loop.reads_failed - reads,
        failed_writes=loop.writes_failed - writes,
        hardware_errors=errors,
    )


def _stream(
    loop: ControlLoop, segment: Segment, first: Cycle | None, errors: list[str], give_up: float
) -> bool:
    """Stream the stop to its end; gives up at ``give_up`` (s, the loop's clock). True if
    its last goal was delivered.

    The stop's clock runs with the loop's while its goals get through; a failed write
    pauses it (the goal after an outage is one period further along the profile than
    the last one delivered), so the goals the actuators receive stay one jerk-limited
    stream.
    """
    elapsed, cycle = 0.0, first
    while True:
        cycle = cycle or loop.begin()
        previous_s, delivered = loop.previous
        step = cycle.time_s - previous_s if delivered else loop.ticker.period
        t = min(elapsed + step, segment.duration)
        if segment.duration - t < CLOCK_EPSILON_S:
            t = segment.duration
        if loop.send(cycle, *segment.at(t)):
            elapsed = t
        loop.read(cycle)  # the cycle that saw the fault has read already
        observe_hardware_errors(cycle, errors)
        loop.end("stop", cycle, checked=False)
        if elapsed >= segment.duration:
            return True
        if cycle.time_s >= give_up:
            _LOG.warning("stop given up at %.3f s of its %.3f s", elapsed, segment.duration)
            return False
        cycle = None


def _hold(
    loop: ControlLoop, problem: Problem, settings: ExecutionSettings, errors: list[str]
) -> tuple[bool, str, float | None]:
    """Hold the last goal delivered until rest is confirmed or ``hold_s`` passes.

    Returns (at rest, "confirmed" or why not, the time rest was confirmed or None).
    Reads, hardware errors and signals are still watched: they are recorded, and a
    failed read or a motion restarts the rest window.
    """
    hold_s = settings.hold_s
    confirmed, window = hold_until_rest(
        loop,
        "hold",
        loop.commanded.position,
        hold_s,
        settings,
        problem.robot.actuator,
        lambda cycle: observe_hardware_errors(cycle, errors),
        checked=False,
    )
    if confirmed is not None:
        return True, "confirmed", confirmed
    why = f"not confirmed within the {hold_s:g} s hold: {window.why()}"
    _LOG.info("rest %s", why)
    return False, why, None


def _travel(before: Measurement | None, after: Measurement | None) -> list[float] | None:
    """How far each joint moved between two readings, rad (None without both)."""
    if before is None or after is None:
        return None
    return [float(d) for d in np.abs(after.position_rad - before.position_rad)]
