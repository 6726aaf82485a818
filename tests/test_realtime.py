"""The control loop's thread asks for a larger share of the processors (and a loop on the
wall clock for the real-time policy), and gives them back."""

from __future__ import annotations

import os
import threading

from spm_opt.execution.realtime import CONTROL_FIFO_PRIORITY, CONTROL_NICE, raised_priority


def niceness() -> int:
    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())


def test_the_thread_runs_at_the_loops_priority_where_allowed_and_returns_to_its_own():
    before = niceness()
    with raised_priority() as inside:
        assert inside.nice == niceness() and inside.fifo is None
        assert os.sched_getscheduler(0) == os.SCHED_OTHER
        # root (CI) may raise it; a user without CAP_SYS_NICE keeps the priority they have
        assert inside.nice in (min(CONTROL_NICE, before), before)
        if os.geteuid() == 0:
            assert inside.nice == min(CONTROL_NICE, before)
    assert niceness() == before


def test_a_wall_clock_loop_runs_under_the_real_time_policy_where_allowed_and_gives_it_back():
    before = niceness()
    assert os.sched_getscheduler(0) == os.SCHED_OTHER
    with raised_priority(fifo=CONTROL_FIFO_PRIORITY) as inside:
        if inside.fifo is not None:
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
            assert os.sched_getparam(0).sched_priority == CONTROL_FIFO_PRIORITY
        else:  # not allowed: the ordinary policy, as asked of a thread without the right
            assert os.sched_getscheduler(0) == os.SCHED_OTHER
        if os.geteuid() == 0:
            assert inside.fifo == CONTROL_FIFO_PRIORITY
    assert os.sched_getscheduler(0) == os.SCHED_OTHER and niceness() == before
