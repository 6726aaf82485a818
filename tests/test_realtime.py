"""The control loop's thread asks for a larger share of the processors, and gives it back."""

from __future__ import annotations

import os
import threading

from spm_opt.execution.realtime import CONTROL_NICE, raised_priority


def niceness() -> int:
    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())


def test_the_thread_runs_at_the_loops_priority_where_allowed_and_returns_to_its_own():
    before = niceness()
    with raised_priority() as inside:
        assert inside == niceness()
        # root (CI) may raise it; a user without CAP_SYS_NICE keeps the priority they have
        assert inside in (min(CONTROL_NICE, before), before)
        if os.geteuid() == 0:
            assert inside == min(CONTROL_NICE, before)
    assert niceness() == before
