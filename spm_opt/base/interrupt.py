"""Ctrl-C during a CasADi solve stops the program, not just the solve.

CasADi's solvers poll Python for signals between iterations. When SIGINT's handler raises
``KeyboardInterrupt`` there, CasADi catches it, prints a warning and returns the iterate
it had with a failed status (IPOPT's ``NonIpopt_Exception_Thrown``), so the caller would
carry on, retry or even keep the iterate. :func:`solve` notes the signal itself and raises
``KeyboardInterrupt`` once the solver has returned: an interrupted solve is never a result.
CasADi's warning of the interrupt is left out of stderr: the command line says in its own
one line that it was interrupted.
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TextIO

_LOG = logging.getLogger(__name__)
CASADI_INTERRUPT_WARNING = 'WARNING("KeyboardInterruptException")'
"""What the line CasADi writes to ``sys.stderr`` when a solver it runs is interrupted holds."""


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
        if threading.current_thread() is threading.main_thread():
            with _without_interrupt_warning():
                result = solver(**arguments)
        else:
            result = solver(**arguments)
    if interrupted():
        raise KeyboardInterrupt
    return result


@contextmanager
def _without_interrupt_warning() -> Iterator[None]:
    """Within the block (on the main thread only: ``sys.stderr`` is the process's),
    ``sys.stderr`` passes every line on but CasADi's warning of an interrupt."""
    stream = sys.stderr
    filtered = _LinesWithout(stream, CASADI_INTERRUPT_WARNING)
    sys.stderr = filtered
    try:
        yield
    finally:
        sys.stderr = stream
        filtered.close_line()


class _LinesWithout:
    """A text stream that passes on to ``stream`` every whole line that does not hold
    ``text`` (CasADi writes a line in pieces)."""

    def __init__(self, stream: TextIO, text: str) -> None:
        self._stream, self._text, self._line = stream, text, ""

    def write(self, piece: str) -> int:
        *lines, self._line = (self._line + piece).split("\n")
        for line in lines:
            if self._text not in line:
                self._stream.write(line + "\n")
        return len(piece)

    def flush(self) -> None:
        self._stream.flush()

    def close_line(self) -> None:
        """Pass on what was written after the last whole line."""
        if self._line and self._text not in self._line:
            self._stream.write(self._line)
        self._line = ""
