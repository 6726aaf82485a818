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
"""

from __future__ import annotations

import gc
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager


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


@contextmanager
def raised_priority(nice: int = CONTROL_NICE) -> Iterator[int]:
    """Run the block with the calling thread's niceness lowered to ``nice``, where the
    system allows it (Linux sets niceness per thread; raising priority needs root or
    ``CAP_SYS_NICE``), and restore it after. Yields the niceness in force."""
    thread = threading.get_native_id()
    try:
        before = os.getpriority(os.PRIO_PROCESS, thread)
    except (AttributeError, OSError):
        yield 0
        return
    try:
        os.setpriority(os.PRIO_PROCESS, thread, min(nice, before))
    except OSError:  # not permitted: run at the priority the thread has
        pass
    try:
        yield os.getpriority(os.PRIO_PROCESS, thread)
    finally:
        try:
            os.setpriority(os.PRIO_PROCESS, thread, before)
        except OSError:  # lowering it back is always allowed; nothing to undo otherwise
            pass
