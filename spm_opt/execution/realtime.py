"""Keeping a real-time loop free of the garbage collector's pauses.

Python's cyclic collector now and then scans the whole heap (a generation-2 collection).
A process that has imported CasADi, SciPy and pandas and planned holds millions of
objects, and such a scan takes 30–45 ms here: measured with ``gc.callbacks`` during a
500 Hz run through the emulator, two of them stalled the loop for 15–20 cycles, the goal
jumped ahead by the stall and the following-error check stopped the run. Objects that
exist before a loop starts are no garbage of the loop's, so the loop runs with them
frozen (``gc.freeze``): later collections scan only what the loop itself allocates.

The loop's thread also asks the scheduler for a larger share of the processors
(:func:`raised_priority`): on a machine whose cores are all busy, a thread at the default
priority can wait tens of milliseconds for a core, and the goal jumps ahead by the wait.
A loop on the wall clock asks for the real-time policy (``SCHED_FIFO``) as well, where the
system allows it: niceness only weighs a thread's share, and at −10 the loop still lost
its core for milliseconds within a cycle. Measured with ``experiments/executed_cut.py
--backend emulator --problems craniotomy_hardware --repeats 8`` while two busy loops held
both cores of this project's machine (the toppra plan slowed throughout to 0.90, predicted
at 74.9 % of its jerk limit): at niceness −10 alone, its true jerk came to 73.8–117.6 % in
8 runs, 2 past the limit, and 5 of the study's 48 runs stopped on a following error or a
lost line (its first minutes beside a second such study); with the loop and the emulator
at ``SCHED_FIFO`` 10, 75.5–107.1 %, 1 past it, and all 48 completed. Neither keeps every
run inside: under ``SCHED_FIFO``, with every goal carried to its write, the led and unled
plans, predicted at 82–93 %, came to up to 140 % there, beside goals that reached the
actuators up to 10.8 ms late (:data:`~spm_opt.execution.cycle.LATE_GOAL_S`); with each
goal written before its cycle's read, one of 48 runs, beside a goal 12.1 ms late. A loop on
a virtual clock (the simulated robot computing as fast as it can) keeps the ordinary
policy: it would take a core from everything else for as long as it computes.
"""

from __future__ import annotations

import gc
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass


@contextmanager
def frozen_heap() -> Iterator[None]:
    """Collect once, then keep every object that exists now out of the collector's scans
    until the block ends (objects made inside it are collected as usual)."""
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


CONTROL_NICE = -10
"""The niceness a real-time loop's thread asks for (Linux: -20 the most favoured, 0 the
default): its share of a busy core rises about ninefold against threads at 0."""
CONTROL_FIFO_PRIORITY = 10
"""The ``SCHED_FIFO`` priority a loop on the wall clock asks for (1–99): above every thread
of the ordinary policy, below the kernel's own real-time threads (50 and up)."""


@dataclass(frozen=True)
class Priority:
    """The scheduling a block ran with: its niceness and its ``SCHED_FIFO`` priority (None:
    the ordinary policy)."""

    nice: int
    fifo: int | None = None


@contextmanager
def raised_priority(nice: int = CONTROL_NICE, fifo: int | None = None) -> Iterator[Priority]:
    """Run the block with the calling thread's niceness lowered to ``nice`` and, with
    ``fifo`` (1–99), under ``SCHED_FIFO`` at that priority, each where the system allows it
    (Linux sets both per thread; raising either needs root, ``CAP_SYS_NICE`` or an rtprio
    limit), and restore both after. Yields the :class:`Priority` in force."""
    thread = threading.get_native_id()
    try:
        before = os.getpriority(os.PRIO_PROCESS, thread)
    except (AttributeError, OSError):
        yield Priority(0)
        return
    try:
        os.setpriority(os.PRIO_PROCESS, thread, min(nice, before))
    except OSError:  # not permitted: run at the priority the thread has
        pass
    fifo_in_force = _real_time(fifo)
    try:
        yield Priority(os.getpriority(os.PRIO_PROCESS, thread), fifo_in_force)
    finally:
        if fifo_in_force is not None:  # the ordinary policy back (always allowed)
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        try:
            os.setpriority(os.PRIO_PROCESS, thread, before)
        except OSError:  # lowering it back is always allowed; nothing to undo otherwise
            pass


def _real_time(priority: int | None) -> int | None:
    """Put the calling thread under ``SCHED_FIFO`` at ``priority`` if asked and allowed,
    from the ordinary policy only; returns the priority in force (None: not changed)."""
    if priority is None or not hasattr(os, "sched_setscheduler"):
        return None
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            return None  # a policy someone chose: left as it is
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError:  # not permitted: the ordinary policy
        return None
    return priority
