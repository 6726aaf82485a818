"""A task's row as a worker makes it: the task function's result with the task's identity
and the worker's ``host:pid``, or a failed row (its error, ``failure`` kind and traceback)
when the task raised.

A task that raises anyway (a bug) is a row with status "failed", its error, its
``failure`` kind (:func:`spm_opt.studies.sweep.task.failure_kind`) and its traceback; the
sweep goes on.
"""

from __future__ import annotations

import os
import socket
import traceback
from collections.abc import Callable
from typing import Any

from spm_opt.studies.sweep.task import RESULT, Task, failure_kind

TaskFunction = Callable[[Task], dict[str, Any]]
Row = dict[str, Any]


def run_row(task_function: TaskFunction, task: Task) -> Row:
    """Run one task in a worker: its row, or a failed row if it raised, with the worker."""
    try:
        result = task_function(task)
        if not isinstance(result, dict) or not isinstance(result.get("status"), str):
            raise TypeError(f"the task function returned {_shown(result)}, not a row")
        row = {**task_identity(task), **{k: v for k, v in result.items() if k != "key"}}
        if row["status"] == "failed":
            row.setdefault("failure", RESULT)
    except Exception as error:  # noqa: BLE001 - a task's bug is its row, not the sweep's end
        row = failed_row(task_identity(task), describe(error), failure_kind(error))
        row["traceback"] = "".join(traceback.format_exception(error))
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return row


def task_identity(task: Task) -> Row:
    """The fields naming a task in its row: key, sweep, planner and parameters."""
    return {
        "key": task.key,
        "sweep": task.sweep,
        "planner": task.planner,
        "parameters": task.parameters,
    }


def failed_row(row: Row, error: str, failure: str) -> Row:
    """A failed row: ``row``'s identity fields, status "failed", ``error`` and ``failure``
    (:data:`~spm_opt.studies.sweep.task.MACHINE` or :data:`~spm_opt.studies.sweep.task.RESULT`)."""
    identity = {k: row[k] for k in ("key", "sweep", "planner", "parameters") if k in row}
    return {**identity, "status": "failed", "error": error, "failure": failure}


def _shown(result: object) -> str:
    if isinstance(result, dict):
        return f"a dict without a text 'status' ({len(result)} keys)"
    return f"a {type(result).__name__}"


def describe(error: BaseException) -> str:
    """``error`` in one line: its type and the first line of its message."""
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0]}" if text else type(error).__name__
