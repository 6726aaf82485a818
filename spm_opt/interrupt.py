"""Ctrl-C during a CasADi solve stops the program, not just the solve.

CasADi's solvers poll Python for signals between iterations. When SIGINT's handler raises
``KeyboardInterrupt`` there, CasADi catches it, prints a warning and returns the iterate
it had with a failed status (IPOPT's ``NonIpopt_Exception_Thrown``), so the caller would
carry on, retry or even keep the iterate. :func:`solve` notes the signal itself and raises
``KeyboardInterrupt`` once the solver has returned: an interrupted solve is never a result.
"""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

_LOG = logging.getLogger(__name__)


@contextmanager
def sigint_noted() -> Iterator[Callable[[], bool]]:
    """Within the block, SIGINT still raises ``KeyboardInterrupt`` (for CasADi to stop on)
    and is also noted; yields a function that tells whether one arrived. Off the main
    thread, where no handler can be set, or where SIGINT is ignored, it yields one that is
    always false."""
    on_main = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGINT) if on_main else signal.SIG_IGN
    if previous == signal.SIG_IGN:
        yield lambda: False
        return
    arrived = threading.Event()

    def note(signum: int, frame: Any) -> None:
        arrived.set()
        if callable(previous):
            previous(signum, frame)
        else:
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, note)
    try:
        yield arrived.is_set
    finally:
        signal.signal(signal.SIGINT, previous)


def solve(solver: Callable[..., Any], **arguments: Any) -> Any:
    """``solver(**arguments)`` (a CasADi Function such as an ``nlpsol``), raising
    ``KeyboardInterrupt`` if SIGINT arrived while it ran."""
    _LOG.info("%s: solving (Ctrl-C stops)", solver.name())
    with sigint_noted() as interrupted:
        result = solver(**arguments)
    if interrupted():
        raise KeyboardInterrupt
    return result
