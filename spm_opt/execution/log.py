"""The execution log: a CSV written while the robot moves, and its JSON header.

Samples are appended as they are read and reach the file in whole lines, one ``write``
call at least every ``flush_interval_s`` (0.1 s), so that a crash (even ``kill -9``) leaves
a valid CSV of every sample up to the last flush. The header beside it (``run.json`` for
``run.csv``) holds the plan, the problem, the backend and the settings; it is written when
the run starts and replaced, whole, with the outcome and the loop statistics when it ends.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from spm_opt.errors import InputError
from spm_opt.files import json_default, write_atomically

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
delivered); measured values are empty in a cycle whose read failed."""


def header_path(log_path: Path) -> Path:
    """The JSON header beside a CSV log."""
    return log_path.with_suffix(".json")


class LogWriter:
    """Appends samples to a CSV log; flushes whole lines at least every ``flush_interval_s``.

    The file is opened with O_APPEND and written with ``os.write`` of complete lines only,
    never through a buffer that could split a line.
    """

    def __init__(self, path: Path, header: dict[str, Any], flush_interval_s: float = 0.1) -> None:
        self.path = Path(path)
        self.header = dict(header)
        self.flush_interval_s = flush_interval_s
        self._pending: list[str] = []
        self._last_flush = time.monotonic()
        self.samples = 0
        write_atomically(
            {
                self.path: ",".join(COLUMNS) + "\n",
                header_path(self.path): json.dumps(self.header, indent=2, default=json_default)
                + "\n",
            }
        )
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)

    def append(
        self,
        time_s: float,
        phase: str,
        along: tuple[float, float, float] | None,
        reference: np.ndarray,
        goal: np.ndarray,
        measured: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None,
        hardware_error: tuple[int, int] | None,
        status: str,
    ) -> None:
        """One sample: ``along`` is (plan time, feed, feed target) or None, ``reference``
        and ``goal`` positions (rad), ``measured`` (position, velocity, current, torque) or
        None."""
        values = [f"{time_s:.9f}", phase]
        values += ["", "", ""] if along is None else [f"{v:.12g}" for v in along]
        values += [f"{v:.9g}" for v in (*reference, *goal)]
        if measured is None:
            values += [""] * 8
        else:
            values += [f"{v:.9g}" for part in measured for v in part]
        values += [str(e) for e in hardware_error] if hardware_error else ["", ""]
        values.append(status.replace(",", ";").replace("\n", " "))
        self._pending.append(",".join(values) + "\n")
        self.samples += 1
        if time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Write every pending line in one call."""
        if self._pending:
            data = "".join(self._pending).encode()
            self._pending.clear()
            while data:
                data = data[os.write(self._fd, data) :]
        self._last_flush = time.monotonic()

    def close(self, outcome: dict[str, Any]) -> None:
        """Flush, sync to disk and rewrite the header with the outcome."""
        self.flush()
        os.fsync(self._fd)
        os.close(self._fd)
        self.header.update(outcome)
        write_atomically(
            {header_path(self.path): json.dumps(self.header, indent=2, default=json_default) + "\n"}
        )


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
