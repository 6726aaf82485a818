"""Running a sweep's tasks: the ones not done yet, in this process, on a process pool or on
a Dask cluster, each finished task's row appended to the results file as it arrives.

    from spm_opt.studies.sweep.runner import run_sweep
    summary = run_sweep(spec.tasks(), Path("runs/friction_payload"), workers=2)

Running the same tasks again resumes: the keys of the results file's complete lines
(:mod:`spm_opt.studies.sweep.results_file`) are done and skipped, unless the key's newest
row failed for the machine's reasons (``failure`` "machine": a worker killed, a lost
connection, a timeout), or failed at all with ``retry_failed``. Each row carries
``worker``, the ``host:pid`` of the process that ran the task
(:mod:`spm_opt.studies.sweep.rows`). A task that raises or whose worker dies is a failed
row and the sweep goes on (:mod:`spm_opt.studies.sweep.pool`,
:mod:`spm_opt.studies.sweep.dask_cluster`). With ``workers=1`` and no scheduler the tasks
run in this process, one after the other (what a debugger wants).
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spm_opt.base.errors import InputError, require
from spm_opt.base.input_limits import excerpt
from spm_opt.studies.sweep.dask_cluster import check_scheduler, dask_rows
from spm_opt.studies.sweep.pool import check_picklable, pool_rows
from spm_opt.studies.sweep.results_file import ResultsFile
from spm_opt.studies.sweep.rows import Row, TaskFunction, run_row
from spm_opt.studies.sweep.task import Task, run_task

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class SweepSummary:
    """What a call of :func:`run_sweep` did.

    Attributes
    ----------
    total : int
        Tasks given.
    skipped : int
        Tasks already in the results file, not run again.
    retried : int
        Tasks run again because their newest row had failed (for the machine's reasons, or
        at all with ``retry_failed``); they count in ``done`` or ``failed`` too.
    done : int
        Tasks run now that planned (status "ok" or with violations).
    failed : int
        Tasks run now whose row has status "failed".
    seconds : float
        Wall time of the call, s (with the start of the pool or cluster).
    """

    total: int
    skipped: int
    retried: int
    done: int
    failed: int
    seconds: float


def run_sweep(
    tasks: Sequence[Task],
    out: str | Path,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    task_function: TaskFunction = run_task,
    retry_failed: bool = False,
) -> SweepSummary:
    """Run every task not yet in ``out/results.jsonl``, or whose newest row there failed
    for the machine's reasons, and append one row per task run.

    Parameters
    ----------
    tasks : sequence of Task
        The sweep's tasks; their keys must differ.
    out : str or Path
        The sweep's directory (created if missing). Rows of other keys already in its
        results file are left alone.
    workers : int
        Worker processes (at least 1): the size of the process pool, or of the local Dask
        cluster with ``scheduler="local"``; 1 without a scheduler runs the tasks in this
        process. Ignored with a scheduler's address (the cluster has its own workers).
    scheduler : str, optional
        None: a local process pool. ``"local"``: a Dask ``LocalCluster`` of ``workers``
        processes of one thread each on 127.0.0.1. ``"tcp://HOST:PORT"``: the Dask
        scheduler there; its workers need the same spm_opt installed (the tasks carry the
        problem files' contents), and are best started with one thread each.
    progress : bool
        Show a progress bar on stderr with the counts done, failed and remaining.
    task_function : callable
        Runs one task and returns its row (default :func:`spm_opt.studies.sweep.task.run_task`);
        it must be importable by the workers (a module-level function).
    retry_failed : bool
        Run again every task whose newest row failed, results (a planning or input error)
        as well as the machine's failures.

    Returns
    -------
    SweepSummary

    Raises
    ------
    InputError
        ``workers`` or ``scheduler`` not allowed, an unreachable scheduler, two tasks with
        one key, ``out`` not a directory, its results file locked by another running sweep
        or holding a line that is not a row (other than a torn last line).
    SpmOptError
        The Dask scheduler cancelled a task (e.g. the connection was lost): the rows so
        far are kept; run again to resume.
    """
    started = time.perf_counter()
    _check_workers(workers)
    if scheduler is not None:
        check_scheduler(scheduler)
    keys = _unique_keys(tasks)
    name = tasks[0].sweep if tasks else "sweep"
    done = failed = 0
    with ResultsFile(Path(out)) as results:
        pending = [task for task in tasks if results.to_run(task.key, retry_failed)]
        skipped = len(tasks) - len(pending)
        retried = sum(task.key in results.finished for task in pending)
        stale = len(results.finished.keys() - keys)
        _LOG.info(
            "%s: %d tasks, %d already in %s%s, %d to run (%d of them failed before) on %s",
            name,
            len(tasks),
            skipped,
            results.path,
            f" (and {stale} stale rows of other tasks)" if stale else "",
            len(pending),
            retried,
            _where(workers, scheduler),
        )
        if pending and scheduler is None and workers > 1:
            check_picklable(task_function)
        bar = require("tqdm", "the sweep's progress bar").tqdm(
            total=len(tasks),
            initial=skipped,
            desc=name,
            unit="task",
            file=sys.stderr,
            disable=not progress or not pending,
            dynamic_ncols=True,
        )
        rows = _rows(pending, task_function, workers, scheduler)
        with bar, closing(rows):
            for row in rows:
                row = results.append(row)
                if row["status"] == "failed":
                    failed += 1
                    _LOG.info("task %s failed: %s", row["key"], row.get("error", ""))
                else:
                    done += 1
                remaining = len(pending) - done - failed
                bar.set_postfix(done=done, failed=failed, remaining=remaining, refresh=False)
                bar.update()
    seconds = time.perf_counter() - started
    summary = SweepSummary(len(tasks), skipped, retried, done, failed, seconds)
    _LOG.info(
        "%s: %d done, %d failed, %d skipped in %.1f s", name, done, failed, skipped, summary.seconds
    )
    return summary


def _check_workers(workers: Any) -> None:
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise InputError(
            f"--workers {excerpt(workers)}: expected a whole number of processes, >= 1"
        )


def _unique_keys(tasks: Sequence[Task]) -> set[str]:
    keys: set[str] = set()
    for task in tasks:
        if task.key in keys:
            raise InputError(f"tasks: key {task.key} appears twice (planner {task.planner})")
        keys.add(task.key)
    return keys


def _where(workers: int, scheduler: str | None) -> str:
    if scheduler is None:
        return "this process" if workers == 1 else f"a pool of {workers} processes"
    if scheduler == "local":
        return f"a local Dask cluster of {workers} processes"
    return f"the Dask cluster at {scheduler}"


def _rows(
    tasks: list[Task], task_function: TaskFunction, workers: int, scheduler: str | None
) -> Iterator[Row]:
    """The tasks' rows as they finish; nothing is started for no tasks."""
    if not tasks:
        return
    if scheduler is not None:
        yield from dask_rows(tasks, task_function, workers, scheduler)
    elif workers == 1:
        yield from (run_row(task_function, task) for task in tasks)
    else:
        yield from pool_rows(tasks, task_function, workers)
