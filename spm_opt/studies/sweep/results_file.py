"""The results file a sweep appends to, ``DIR/results.jsonl``: locked while the sweep runs,
its torn last line cut off, one synced JSON line a finished task, and which keys are done.

Every finished task is one JSON line, appended in the order the tasks finish with one
``os.write`` of the whole line on an ``O_APPEND`` descriptor and ``os.fsync`` (a fraction
of a millisecond a row): a crash, even ``kill -9``, leaves whole rows and at most a torn
last line, which is cut off before anything is appended. A task run again appends its new
row: the newest row of a key is the task's
(:func:`spm_opt.studies.sweep.results.load_sweep` keeps it alone). Each row gets
``finished_at`` (ISO 8601 UTC, the runner's clock when the row arrived), and NaN and
infinities are written as ``null``, so the file is standard JSON lines. One runner at a
time writes a directory: the file is locked.
"""

from __future__ import annotations

import fcntl
import json
import logging
import math
import os
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.studies.sweep.rows import Row, failed_row
from spm_opt.studies.sweep.task import MACHINE, RESULT

_LOG = logging.getLogger(__name__)

RESULTS_FILE = "results.jsonl"
"""The file, in a sweep's directory, that the runner appends one row per task to."""


class ResultsFile:
    """``out/results.jsonl``, locked while the sweep runs (the lock goes with the process),
    its torn last line cut off; :attr:`finished` maps the key of each of its rows to the
    ``failure`` of the key's newest row (None if it did not fail)."""

    def __init__(self, out: Path) -> None:
        if out.exists() and not out.is_dir():
            raise InputError(f"--out {out}: expected a directory, not a file")
        out.mkdir(parents=True, exist_ok=True)
        self.path = out / RESULTS_FILE
        self._fd = os.open(self.path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            self._lock()
            self.finished = self._finished()
        except BaseException:
            os.close(self._fd)
            raise

    def __enter__(self) -> ResultsFile:
        return self

    def __exit__(self, *exception: object) -> None:
        os.close(self._fd)

    def to_run(self, key: str, retry_failed: bool) -> bool:
        """Whether the task ``key`` runs: no row yet, or its newest failed for the
        machine's reasons (for any reason with ``retry_failed``)."""
        if key not in self.finished:
            return True
        failure = self.finished[key]
        return failure is not None and (retry_failed or failure == MACHINE)

    def append(self, row: Row) -> Row:
        """Write the row as one JSON line and sync it to disk; the row as written (a
        failed row if it cannot be written as JSON)."""
        row = {**row, "finished_at": datetime.now(UTC).isoformat()}
        try:
            text = json.dumps(_plain(row), allow_nan=False)
        except (TypeError, ValueError) as error:
            row = {
                **failed_row(row, f"the row is not JSON ({error})", RESULT),
                **_runner_fields(row),
            }
            text = json.dumps(_plain(row), allow_nan=False)
        data = memoryview((text + "\n").encode())
        while data:
            data = data[os.write(self._fd, data) :]
        os.fsync(self._fd)
        return row

    def _lock(self) -> None:
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(
                f"--out {self.path.parent}: {self.path.name} is being written by another "
                "sweep; wait for it or choose another directory"
            ) from None

    def _finished(self) -> dict[str, str | None]:
        data = b""
        while chunk := os.pread(self._fd, 1 << 20, len(data)):
            data += chunk
        end = data.rfind(b"\n") + 1
        if end < len(data):
            _LOG.warning("%s: torn last line (%d bytes) removed", self.path, len(data) - end)
            os.ftruncate(self._fd, end)
            os.fsync(self._fd)
        finished: dict[str, str | None] = {}
        for number, line in enumerate(data[:end].splitlines(), start=1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except (json.JSONDecodeError, UnicodeDecodeError) as error:
                raise InputError(f"{self.path}, line {number}: not valid JSON ({error})") from None
            if not isinstance(row, dict) or not isinstance(row.get("key"), str):
                raise InputError(
                    f"{self.path}, line {number}: expected a JSON object with a text 'key'"
                )
            finished[row["key"]] = _failure(row)
        return finished


def _failure(row: Row) -> str | None:
    """A row's ``failure``: None if it did not fail; a result if it does not say."""
    if row.get("status") != "failed":
        return None
    return MACHINE if row.get("failure") == MACHINE else RESULT


def _runner_fields(row: Row) -> Row:
    return {k: row[k] for k in ("worker", "finished_at") if k in row}


def _plain(value: Any) -> Any:
    """JSON-able: numpy scalars and arrays as Python ones, NaN and infinities as None."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value
