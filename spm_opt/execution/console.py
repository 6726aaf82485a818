"""The operator's console during a run: a live status line, and keys that steer the feed.

The live view rewrites one line of a terminal a few times a second from the executor's
:attr:`~spm_opt.execution.executor.Executor.status`: time, progress along the contour (mm
and %), feed, following error, torques and what the run is doing. The keys (a terminal in
cbreak mode, read by a thread): space holds and resumes, + and − change the feed override
in 10 % steps, q ends the run in the safe stop. Neither touches the control loop: both run
in their own threads and call the executor's thread-safe controls.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import termios
import threading
import tty
from collections.abc import Iterator
from typing import TextIO

import numpy as np

from spm_opt.execution.executor import Executor
from spm_opt.execution.feed import FEED_STEP
from spm_opt.execution.results import RunStatus
from spm_opt.model import kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

_LOG = logging.getLogger(__name__)

REFRESH_S = 0.25
"""How often the live view rewrites its line, s."""

KEYS_HELP = "keys: space hold/resume, + and - feed ±10 %, q stop safely"

_CLEAR_LINE = "\r\x1b[K"


class ContourProgress:
    """How far along the contour the plan's cut is at each plan time: the contour's arc
    length at the nearest point to the cut, never decreasing, m."""

    def __init__(self, problem: Problem, trajectory: Trajectory, samples: int = 2000) -> None:
        contour = problem.contour
        self.length_m = contour.length
        self._tau = np.linspace(0.0, trajectory.duration, samples)
        directions = kinematics.forward_kinematics(
            trajectory.position(self._tau + trajectory.start_time), 1.0
        )
        progress = contour.progress(contour.nearest(directions))
        self._progress = np.clip(np.maximum.accumulate(progress), 0.0, self.length_m)

    def at(self, plan_time_s: float) -> float:
        """Progress at plan time τ (s), m."""
        return float(np.interp(plan_time_s, self._tau, self._progress))


def status_line(status: RunStatus, progress: ContourProgress) -> str:
    """The live view's line for one status."""
    done = progress.at(status.plan_time_s)
    error = (
        "error    -  "
        if status.following_error_rad is None
        else f"error {status.following_error_rad / DEG:5.2f}°"
    )
    torque = (
        "torque    -      -   "
        if status.torque_nm is None
        else "torque {:+.2f} {:+.2f} N·m".format(*status.torque_nm)
    )
    feed = f"feed {status.feed:4.0%}"
    if status.feed_target != status.feed:
        feed += f"→{status.feed_target:.0%}"
    return (
        f"{status.time_s:7.1f} s  {done / MM:6.1f} of {progress.length_m / MM:.1f} mm "
        f"({done / progress.length_m:4.0%})  {feed:<14} {error}  {torque}  {_doing(status)}"
    )


def _doing(status: RunStatus) -> str:
    if status.phase != "plan":
        return {
            "approach": "approaching",
            "ready": "settling at the start",
            "settle": "settling",
            "stop": "stopping",
        }.get(status.phase, "holding after the stop")
    if status.status != "ok":
        return status.status
    if status.held:
        return "held" if status.feed == 0.0 else "holding"
    return "running"


class LiveView:
    """Rewrites one status line on ``stream`` every :data:`REFRESH_S` while in its block;
    the package's log records to the same stream start on a cleared line."""

    def __init__(self, executor: Executor, progress: ContourProgress, stream: TextIO) -> None:
        self._executor, self._progress, self._stream = executor, progress, stream
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="live view", daemon=True)
        self._filter = _ClearLineFirst(stream)
        self._handlers = [
            h for h in logging.getLogger("spm_opt").handlers if getattr(h, "stream", None) is stream
        ]

    def __enter__(self) -> LiveView:
        for handler in self._handlers:
            handler.addFilter(self._filter)
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._done.set()
        self._thread.join()
        self._draw()
        self._stream.write("\n")
        self._stream.flush()
        for handler in self._handlers:
            handler.removeFilter(self._filter)

    def _run(self) -> None:
        while not self._done.wait(REFRESH_S):
            self._draw()

    def _draw(self) -> None:
        status = self._executor.status
        if status is not None:
            self._stream.write(_CLEAR_LINE + status_line(status, self._progress))
            self._stream.flush()


class _ClearLineFirst(logging.Filter):
    """Lets a log record reach the terminal on a line of its own while a live view runs."""

    def __init__(self, stream: TextIO) -> None:
        super().__init__()
        self._stream = stream

    def filter(self, record: logging.LogRecord) -> bool:
        self._stream.write(_CLEAR_LINE)
        return True


class KeyReader:
    """Reads keys from the terminal ``fd`` in cbreak mode while in its block and steers
    ``executor``: space hold/resume, + (or =) and − (or _) the feed, q the safe stop."""

    def __init__(self, executor: Executor, fd: int) -> None:
        self._executor, self._fd = executor, fd
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="keys", daemon=True)
        self._saved: list | None = None

    def __enter__(self) -> KeyReader:
        self._saved = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd, termios.TCSANOW)  # TCSAFLUSH would drop keys typed already
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._done.set()
        self._thread.join()
        termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)

    def press(self, key: str) -> None:
        """What one key does."""
        executor = self._executor
        if key == " ":
            _LOG.info("key: %s", "hold" if executor.toggle_hold() else "resume")
        elif key in ("+", "="):
            _LOG.info("key: feed %.0f %%", 100 * executor.step_feed(FEED_STEP))
        elif key in ("-", "_"):
            _LOG.info("key: feed %.0f %%", 100 * executor.step_feed(-FEED_STEP))
        elif key in ("q", "Q"):
            executor.stop("operator pressed q")

    def _run(self) -> None:
        while not self._done.is_set():
            ready, _, _ = select.select([self._fd], [], [], 0.05)
            if not ready:
                continue
            data = os.read(self._fd, 32)
            if not data:  # the terminal closed
                return
            for key in data.decode(errors="ignore"):
                self.press(key)


@contextlib.contextmanager
def console(
    executor: Executor,
    problem: Problem,
    trajectory: Trajectory,
    stderr: TextIO,
    keys_fd: int | None,
) -> Iterator[None]:
    """The live view on ``stderr`` if it is a terminal, and the keys from ``keys_fd`` (a
    terminal, or None for no keys), for the block's run."""
    with contextlib.ExitStack() as stack:
        if keys_fd is not None:  # the keys are read before they are offered
            stack.enter_context(KeyReader(executor, keys_fd))
            stderr.write(KEYS_HELP + "\n")
        if stderr.isatty():
            stack.enter_context(LiveView(executor, ContourProgress(problem, trajectory), stderr))
        yield
