"""The execution log: a CSV written while the robot moves, and its JSON header.

The control thread never touches the disk. :meth:`LogWriter.append` formats a sample's line
and queues it in memory; a writer thread of its own writes the queued lines at least every
``flush_interval_s`` (0.1 s), whole lines only, so that a crash (even ``kill -9``) leaves a
valid CSV of every sample up to the last write. A write that fails (a full disk, EIO, a
read-only remount) or that stalls for ``stall_s`` (a network share that hangs) is the
writer's :attr:`~LogWriter.fault`, which the executor turns into a safe stop; the stop and
its rest proof go on whatever the disk does, their samples kept in memory (up to
:data:`MAX_PENDING_BYTES`) and written if the disk comes back. A write that stops part way
through a line is cut back to the last whole line.

The header beside the CSV (``run.json`` for ``run.csv``) holds the plan, the problem, the
backend and the settings; it is written when the run starts and replaced, whole, with the
outcome, the loop statistics and what the log kept (``log``) when it ends. Room for that
replacement is set aside when the run starts (a hidden ``.run.json.reserve`` beside it,
removed at the end), so that a disk the run filled still takes the outcome.
"""

from __future__ import annotations

import collections
import contextlib
import errno
import json
import os
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from spm_opt.base.errors import InputError
from spm_opt.base.files import json_default, write_atomically
from spm_opt.base.input_limits import (
    LOG_KIND,
    MAX_LOG_ROWS,
    check_log_header,
    first_line,
    log_rows,
)
from spm_opt.execution.results import LogReport

COLUMNS = (
    "time_s",
    "phase",
    "plan_time_s",
    "feed",
    "feed_target",
    "reference_theta1_rad",
    "reference_theta2_rad",
    "goal_theta1_rad",
    "goal_theta2_rad",
    "position_theta1_rad",
    "position_theta2_rad",
    "velocity_theta1_rad_s",
    "velocity_theta2_rad_s",
    "current_theta1_a",
    "current_theta2_a",
    "torque_theta1_nm",
    "torque_theta2_nm",
    "torque_positive_theta1_nm",
    "torque_positive_theta2_nm",
    "torque_negative_theta1_nm",
    "torque_negative_theta2_nm",
    "hardware_error_1",
    "hardware_error_2",
    "status",
)
"""Columns of the CSV log. ``time_s``: when the cycle began (to the ns), the time its goal
was sampled at; ``plan_time_s``, ``feed``, ``feed_target``: in the plan phase, how far along
the plan (s of its own time) the goal was sampled, at what pace (1: as planned, 0: held)
and the pace it was heading for (empty in other phases); the references: where the
joints are to be at the cycle's time (the plan at ``plan_time_s`` in the plan phase, the
approach's or the stop's profile, the position held) and the goals: what the actuators
hold after the cycle, the reference led by the position loop's lag (see
:mod:`spm_opt.execution.tracking`; a failed write leaves the last reference and goal
delivered); ``torque_positive_*`` and ``torque_negative_*``: the Present Current reads'
torques behind ``torque_*`` in two sides, each read on the side its neighbours' sign gives
(:mod:`spm_opt.execution.torque_sides`); measured values are empty in a cycle
whose read failed."""

LINE_BYTES = 384
"""Bytes a sample's line may take, for the room a log needs (:func:`bytes_needed`): a line
whose every number is negative with an exponent is 351 bytes with an "ok" status; the
lines of toppra's run of ``craniotomy_hardware.toml`` on the simulated robot average 214
bytes, at most 253."""

MAX_PENDING_BYTES = 64_000_000
"""Lines the disk has not taken are kept in memory up to this many bytes (about 200,000
samples, over half an hour at 100 Hz); later ones are counted as lost."""

RESERVE_BYTES = 65_536
"""Room set aside for the header's last version, at least (four times the first one's
size when that is more)."""

Write = Callable[[int, bytes], int]
"""``os.write``'s shape: (file descriptor, data) → bytes written."""


def header_path(log_path: Path) -> Path:
    """The JSON header beside a CSV log."""
    return log_path.with_suffix(".json")


def bytes_needed(samples: float, header: dict[str, Any]) -> int:
    """Disk space a log of ``samples`` lines with ``header`` takes at most, bytes: the
    lines, the header twice (its temporary copy when replaced) and the reserve."""
    header_bytes = len(_header_text(header))
    return int(samples * LINE_BYTES) + 2 * header_bytes + max(RESERVE_BYTES, 4 * header_bytes)


def _header_text(header: dict[str, Any]) -> str:
    return json.dumps(header, indent=2, default=json_default) + "\n"


class LogWriter:
    """Queues samples from the control thread; a thread of its own writes them.

    Parameters
    ----------
    path : Path
        The CSV log; its header goes beside it (:func:`header_path`).
    header : dict
        What the header holds when the run starts.
    flush_interval_s : float, s
        Longest time a queued line waits before the writer tries to write it.
    stall_s : float, s
        A write that has not returned after this long is a :attr:`fault`.
    write : callable
        The system call that writes (``os.write``; a test's failing or blocking disk).

    The CSV's first line and the header are written here, before the writer starts: an
    OSError then means nothing was logged.
    """

    def __init__(
        self,
        path: Path,
        header: dict[str, Any],
        flush_interval_s: float = 0.1,
        stall_s: float = 1.0,
        write: Write = os.write,
    ) -> None:
        self.path = Path(path)
        self.header = dict(header)
        self.flush_interval_s, self.stall_s = flush_interval_s, stall_s
        self._write = write
        self.samples = 0
        """Samples appended (queued), whether or not the disk took them."""
        text = _header_text(self.header)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._reserve = self.path.with_name(f".{header_path(self.path).name}.reserve")
        self._set_aside(max(RESERVE_BYTES, 4 * len(text)))
        try:
            write_atomically({self.path: ",".join(COLUMNS) + "\n", header_path(self.path): text})
        except OSError:
            self._reserve.unlink(missing_ok=True)
            raise
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)
        self._first_bytes = os.fstat(self._fd).st_size  # the columns' line
        self._queue: collections.deque[bytes] = collections.deque()
        self._queued_bytes = 0  # the control thread's count
        self._written_bytes = 0  # the writer's count (of whole lines, in order)
        self._chunks: collections.deque[bytes] = collections.deque()  # the writer's own
        self._written_lines = 0
        self._fault: str | None = None
        self._busy_since: float | None = None  # when the write under way began
        self._closing = threading.Event()
        self._wake = threading.Event()
        self._final: dict[str, Any] | None = None
        self._report: LogReport | None = None
        self._thread = threading.Thread(target=self._run, name="log-writer", daemon=True)
        self._thread.start()

    # -------------------------------------------------------------- control thread
    def append(
        self,
        time_s: float,
        phase: str,
        along: tuple[float, float, float] | None,
        reference: np.ndarray,
        goal: np.ndarray,
        measured: tuple[np.ndarray, ...] | None,
        hardware_error: tuple[int, int] | None,
        status: str,
    ) -> None:
        """Queue one sample; never blocks, never raises an OSError. ``along`` is (plan
        time, feed, feed target) or None, ``reference`` and ``goal`` positions (rad),
        ``measured`` (position, velocity, current, torque, its positive and its negative
        side) or None."""
        values = [f"{time_s:.9f}", phase]
        values += ["", "", ""] if along is None else [f"{v:.12g}" for v in along]
        values += [f"{v:.9g}" for v in (*reference, *goal)]
        if measured is None:
            values += [""] * 12
        else:
            values += [f"{v:.9g}" for part in measured for v in part]
        values += [str(e) for e in hardware_error] if hardware_error else ["", ""]
        values.append(status.replace(",", ";").replace("\n", " "))
        line = (",".join(values) + "\n").encode()
        self.samples += 1
        if self._queued_bytes - self._written_bytes + len(line) > MAX_PENDING_BYTES:
            return  # kept from the disk's comeback: lost
        self._queued_bytes += len(line)
        self._queue.append(line)

    @property
    def fault(self) -> str | None:
        """Why the log is failing (a write that raised, or one that stalls), or None."""
        if self._fault is not None:
            return self._fault
        since = self._busy_since
        if since is not None and time.monotonic() - since > self.stall_s:
            return f"a write to {self.path.name} has not returned for {self.stall_s:g} s"
        return None

    def close(self, outcome: dict[str, Any]) -> LogReport:
        """Write what is queued, sync, and replace the header with ``outcome`` and what the
        log kept (its ``log`` entry), all in the writer thread; waits while it makes
        progress, and at most ``stall_s`` for a write that does not return."""
        self._final = dict(outcome)
        self._closing.set()
        self._wake.set()
        while self._thread.is_alive():
            self._thread.join(self.flush_interval_s)
            since = self._busy_since
            if since is not None and time.monotonic() - since > self.stall_s:
                break
        return self._report or self._describe(header_written=False)

    # ---------------------------------------------------------------- the writer
    def _run(self) -> None:
        """The writer thread: write what is queued every flush interval, until closed;
        then the last lines, the sync and the header."""
        while not self._closing.is_set():
            self._wake.wait(self.flush_interval_s)
            self._wake.clear()
            self._write_queued()
        self._write_queued()
        self._sync_and_close()
        self._report = self._write_header()

    @contextlib.contextmanager
    def _busy(self) -> Iterator[None]:
        """Within the block the writer waits on the disk: :attr:`fault` times it."""
        self._busy_since = time.monotonic()
        try:
            yield
        finally:
            self._busy_since = None

    def _write_queued(self) -> None:
        """Take the queue's lines as one chunk and write the chunks in order, whole lines
        only; a failure is the :attr:`fault` (the first one stays), and the chunk it met
        and those after it wait for the next try (each is joined once: a long backlog
        costs the control thread nothing)."""
        queue, lines = self._queue, []
        while queue:
            lines.append(queue.popleft())
        if lines:
            self._chunks.append(b"".join(lines))
        while self._chunks:
            chunk, done = self._chunks[0], 0
            with self._busy():
                try:
                    while done < len(chunk):
                        done += self._write(self._fd, chunk[done:])
                except OSError as error:
                    self._fail(f"cannot write {self.path.name}", error)
                    done = self._cut_to_whole_lines(chunk, done)
            self._written_lines += chunk.count(b"\n", 0, done)
            self._written_bytes += done
            if done < len(chunk):
                self._chunks[0] = chunk[done:]
                return
            self._chunks.popleft()

    def _cut_to_whole_lines(self, chunk: bytes, done: int) -> int:
        """After a write that stopped ``done`` bytes into ``chunk``: cut the file back to
        the last whole line; the bytes of ``chunk`` that stay written."""
        whole = chunk.rfind(b"\n", 0, done) + 1
        if whole < done:
            try:
                os.ftruncate(self._fd, self._first_bytes + self._written_bytes + whole)
            except OSError as error:
                self._fail(f"cannot cut {self.path.name} back to its last whole line", error)
                return done
        return whole

    def _fail(self, what: str, error: OSError) -> None:
        """Record a failure: the first one is the :attr:`fault`, later ones its notes."""
        message = f"{what} ({_reason(error)})"
        if self._fault is None:
            self._fault = message
        elif message not in self._fault:
            self._fault = f"{self._fault}; {message}"

    def _sync_and_close(self) -> None:
        """Flush the CSV to the disk and close it."""
        try:
            with self._busy():
                os.fsync(self._fd)
        except OSError as error:
            self._fail(f"cannot sync {self.path.name}", error)
        finally:
            os.close(self._fd)

    def _write_header(self) -> LogReport:
        """Replace the header with the outcome and what the log kept, using the room set
        aside when the disk is full; remove that room."""
        report = self._describe(header_written=True)
        self.header.update(self._final or {})
        self.header["log"] = report.record()
        text = _header_text(self.header)
        try:
            with self._busy():
                try:
                    write_atomically({header_path(self.path): text})
                except OSError as error:
                    if error.errno != errno.ENOSPC or not self._reserve.exists():
                        raise
                    self._reserve.unlink()
                    write_atomically({header_path(self.path): text})
        except OSError as error:
            self._fail(f"cannot update {header_path(self.path).name}", error)
            return self._describe(header_written=False)
        finally:
            self._reserve.unlink(missing_ok=True)
        return report

    def _set_aside(self, size: int) -> None:
        """Make the reserve file of ``size`` bytes (zeros, its blocks allocated)."""
        fd = os.open(self._reserve, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            os.posix_fallocate(fd, 0, size)
        except OSError:
            self._reserve.unlink(missing_ok=True)
            raise
        finally:
            os.close(fd)

    def _describe(self, header_written: bool) -> LogReport:
        """What the log kept so far."""
        return LogReport(
            samples=self.samples,
            samples_written=self._written_lines,
            fault=self.fault,
            header_written=header_written,
        )


def _reason(error: OSError) -> str:
    """An OSError's reason, without its file name: "No space left on device"."""
    return error.strerror or str(error)


MISSING_NAMED = 3
"""Missing columns a log's error names before it says the file is no execution log."""


def read_log(path: str | Path) -> tuple[pd.DataFrame, dict[str, Any]]:
    """A CSV log as a DataFrame (one row per sample, SI) and its header."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"log {path}: no such file")
    table = pd.read_csv(path)
    missing = [c for c in COLUMNS if c not in table.columns]
    if len(missing) > MISSING_NAMED:
        raise InputError(
            f"log {path}: {len(missing)} of the execution log's {len(COLUMNS)} columns are "
            f"missing ({', '.join(missing[:MISSING_NAMED])}, ...); is it a log of "
            "spm-opt execute?"
        )
    if missing:
        raise InputError(f"log {path}: missing columns {', '.join(missing)}")
    sidecar = header_path(path)
    header = json.loads(sidecar.read_text()) if sidecar.is_file() else {}
    return table, header


def read_execution_log(path: str | Path) -> tuple[pd.DataFrame, dict[str, Any]]:
    """:func:`read_log`, every way of failing an
    :class:`InputError`: the log at most :data:`MAX_LOG_BYTES` and :data:`MAX_LOG_ROWS`
    rows (counted before pandas parses them), its header beside it JSON of at most
    :data:`MAX_SIDECAR_BYTES`."""
    path = Path(path)
    rows = log_rows(path)
    if rows > MAX_LOG_ROWS:
        raise InputError(
            f"{path}: {rows:,} rows; expected {LOG_KIND} of at most {MAX_LOG_ROWS:,} rows "
            "(log a shorter run: minutes identify a robot)"
        )
    check_log_header(header_path(path))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pd.errors.DtypeWarning)
            return read_log(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise InputError(f"log {path}: not a CSV log ({first_line(error)})") from None
