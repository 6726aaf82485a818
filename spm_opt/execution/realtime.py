"""Keeping a real-time loop free of the garbage collector's pauses.

Python's cyclic collector now and then scans the whole heap (a generation-2 collection).
A process that has imported CasADi, SciPy and pandas and planned holds millions of
objects, and such a scan takes 30–45 ms here: measured with ``gc.callbacks`` during a
500 Hz run through the emulator, two of them stalled the loop for 15–20 cycles, the goal
jumped ahead by the stall and the following-error check stopped the run. Objects that
exist before a loop starts are no garbage of the loop's, so the loop runs with them
frozen (``gc.freeze``): later collections scan only what the loop itself allocates.
"""

from __future__ import annotations

import gc
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
