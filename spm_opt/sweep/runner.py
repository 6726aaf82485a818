"""Running a sweep's tasks: in this process, on a process pool or on a Dask cluster.

    from spm_opt.sweep.runner import run_sweep
    summary = run_sweep(spec.tasks(), Path("runs/friction_payload"), workers=2)

Every finished task is one JSON line of ``DIR/results.jsonl``, appended in the order the
tasks finish with one ``os.write`` of the whole line on an ``O_APPEND`` descriptor and
``os.fsync`` (a fraction of a millisecond a row): a crash, even ``kill -9``, leaves whole
rows and at most a torn last line. Running the same tasks again resumes: the keys of the
file's complete lines are done and skipped, unless the key's newest row failed for the
machine's reasons (``failure`` "machine": a worker killed, a lost connection, a timeout),
or failed at all with ``retry_failed``; a torn last line is cut off before anything is
appended. A task run again appends its new row: the newest row of a key is the task's
(:func:`spm_opt.sweep.results.load_sweep` keeps it alone). The runner adds ``worker``
(``host:pid`` of the process that ran the task) and ``finished_at`` (ISO 8601 UTC, the
runner's clock when the row arrived) to each row, and writes NaN and infinities as
``null``, so the file is standard JSON lines.

A task that raises anyway (a bug) or whose worker dies is a row with status "failed", its
error, its ``failure`` kind (:func:`spm_opt.sweep.task.failure_kind`) and, when it raised,
its traceback; the sweep goes on. On the process pool, a dead worker breaks the pool: the
pool is started again and the tasks that were in flight are run again one at a time, so
that the task that kills its worker is told apart from the innocent ones (a failed row
"...died running this task alone", a machine failure) and the others succeed. On Dask,
the scheduler retries a task whose worker died and gives up with ``KilledWorker`` (after
``distributed.scheduler.allowed-failures`` deaths), which becomes its row (a machine
failure too).

The pool's workers are started from a fork server that imported ``spm_opt`` once (about
1.3 s for the first pool, 0.05 s for a restart; "spawn" takes 2.7 s a pool on two cores,
every worker importing on its own; "fork" would copy the runner's threads). A worker keeps
its caches (compiled CasADi functions, the planners' solvers) from task to task, and ends
with the runner, even on ``kill -9``. Each worker gets its share of the CPUs for the
threads of its libraries (:data:`THREAD_VARIABLES`, unless the environment sets them): the
compiled batch functions' OpenMP loops and the BLAS under IPOPT's linear solver would
otherwise each start a thread per CPU in every worker and spin against each other
(``ocp-min-time`` on the paper's flap, 16 tasks on 2 workers and 2 CPUs: 237 against 285
tasks a minute, 324 against 432 after the first wave; ``benchmarks/sweep.py``). The pool
is given two tasks per worker at a time, so that a worker never waits for the next and few
tasks are in flight when one dies. With ``workers=1`` and no scheduler the tasks run in
this process, one after the other (what a debugger wants). One runner at a time writes a
directory: the results file is locked.
"""

from __future__ import annotations

import fcntl
import json
import logging
import math
import multiprocessing
import os
import pickle
import re
import socket
import sys
import threading
import time
import traceback
import uuid
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, CancelledError, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import closing
from dataclasses import dataclass
from datetime import UTC, datetime
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np

from spm_opt.errors import InputError, SpmOptError, require
from spm_opt.input_limits import excerpt
from spm_opt.sweep.results import RESULTS_FILE
from spm_opt.sweep.task import MACHINE, RESULT, Task, failure_kind, run_task

_LOG = logging.getLogger(__name__)

TaskFunction = Callable[[Task], dict[str, Any]]
Row = dict[str, Any]

CONNECT_TIMEOUT_S = 5.0
"""How long to try to reach a Dask scheduler before giving up, s."""
_IN_FLIGHT_PER_WORKER = 2
"""Tasks handed to the pool per worker at a time: one running, one waiting in its queue."""
_ADDRESS = re.compile(r"tcp://(\[[0-9A-Fa-f:.]+\]|[^\s:/\[\]]+):(\d{1,5})")


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
        Runs one task and returns its row (default :func:`spm_opt.sweep.task.run_task`);
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
        _check_scheduler(scheduler)
    keys = _unique_keys(tasks)
    name = tasks[0].sweep if tasks else "sweep"
    done = failed = 0
    with _ResultsFile(Path(out)) as results:
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
            _check_picklable(task_function)
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


def _check_scheduler(scheduler: Any) -> None:
    if scheduler == "local":
        return
    match = _ADDRESS.fullmatch(scheduler) if isinstance(scheduler, str) else None
    if match is None or not 1 <= int(match.group(2)) <= 65535:
        raise InputError(
            f"--scheduler {scheduler!r}: expected 'local' or a Dask scheduler's address "
            "tcp://HOST:PORT"
        )
    # before the results file or the progress bar exist: an unreachable address leaves
    # nothing behind
    host, port = match.group(1).strip("[]"), int(match.group(2))
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as error:
        raise InputError(
            f"--scheduler {scheduler}: cannot connect within {CONNECT_TIMEOUT_S:g} s "
            f"({_describe(error)})"
        ) from None


def _check_picklable(task_function: TaskFunction) -> None:
    try:
        pickle.dumps(task_function)
    except (pickle.PicklingError, AttributeError, TypeError) as error:
        raise InputError(
            f"task function {task_function!r} cannot be sent to worker processes ({error}); "
            "use a module-level function"
        ) from None


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


# The results file


class _ResultsFile:
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

    def __enter__(self) -> _ResultsFile:
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
            row = {**_failed(row, f"the row is not JSON ({error})", RESULT), **_runner_fields(row)}
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


# Rows: what a task returns, or its failure


def _call(task_function: TaskFunction, task: Task) -> Row:
    """Run one task in a worker: its row, or a failed row if it raised, with the worker."""
    try:
        result = task_function(task)
        if not isinstance(result, dict) or not isinstance(result.get("status"), str):
            raise TypeError(f"the task function returned {_shown(result)}, not a row")
        row = {**_identity(task), **{k: v for k, v in result.items() if k != "key"}}
        if row["status"] == "failed":
            row.setdefault("failure", RESULT)
    except Exception as error:  # noqa: BLE001 - a task's bug is its row, not the sweep's end
        row = _failed(_identity(task), _describe(error), failure_kind(error))
        row["traceback"] = "".join(traceback.format_exception(error))
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return row


def _identity(task: Task) -> Row:
    return {
        "key": task.key,
        "sweep": task.sweep,
        "planner": task.planner,
        "parameters": task.parameters,
    }


def _failed(row: Row, error: str, failure: str) -> Row:
    identity = {k: row[k] for k in ("key", "sweep", "planner", "parameters") if k in row}
    return {**identity, "status": "failed", "error": error, "failure": failure}


def _shown(result: object) -> str:
    if isinstance(result, dict):
        return f"a dict without a text 'status' ({len(result)} keys)"
    return f"a {type(result).__name__}"


def _describe(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0]}" if text else type(error).__name__


def _rows(
    tasks: list[Task], task_function: TaskFunction, workers: int, scheduler: str | None
) -> Iterator[Row]:
    """The tasks' rows as they finish; nothing is started for no tasks."""
    if not tasks:
        return
    if scheduler is not None:
        yield from _dask_rows(tasks, task_function, workers, scheduler)
    elif workers == 1:
        yield from (_call(task_function, task) for task in tasks)
    else:
        yield from _pool_rows(tasks, task_function, workers)


# The process pool


THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")
"""The environment variables a pool worker sets to its share of the CPUs (the CPUs this
process may use over the workers, at least 1) before its libraries start their threads;
a value the runner's environment already has is kept."""


def threads_per_worker(workers: int) -> int:
    """Each pool worker's share of the CPUs this process may use (at least 1)."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, (cpus or 1) // workers)


class _Pool:
    """A process pool started from a fork server that imported spm_opt (or by "spawn"
    where there is none), restarted after a worker died. Its workers end with the runner,
    even on ``kill -9``, which a pool's workers do not notice by themselves (they would
    wait for work forever): each watches the end of a pipe that only the runner writes."""

    def __init__(self, workers: int) -> None:
        require("threadpoolctl", "the sweep's process pool")  # its workers' initializer's
        if "forkserver" in multiprocessing.get_all_start_methods():
            self._context = multiprocessing.get_context("forkserver")
            self._context.set_forkserver_preload(["__main__", "spm_opt"])  # until it runs
        else:
            self._context = multiprocessing.get_context("spawn")
        self._workers = workers
        self._lifeline, self._held = self._context.Pipe(duplex=False)
        self.executor = self._start()

    def _start(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(
            self._workers,
            mp_context=self._context,
            initializer=_start_worker,
            initargs=(self._lifeline, threads_per_worker(self._workers)),
        )

    def restart(self) -> None:
        self.executor.shutdown()
        self.executor = self._start()

    def close(self, wait: bool) -> None:
        """Shut down, waiting for the tasks in flight or ending the workers at once."""
        self.executor.shutdown(wait=wait, cancel_futures=True)
        self._held.close()
        self._lifeline.close()


def _start_worker(lifeline: Connection, threads: int) -> None:
    """A pool worker's initializer: its libraries' threads (:data:`THREAD_VARIABLES`) set
    to ``threads`` where the environment leaves them open, and the process ended when the
    runner's end of the pipe closes (the runner ended)."""
    if not any(variable in os.environ for variable in THREAD_VARIABLES):
        import threadpoolctl  # optional: the sweep extra's

        threadpoolctl.threadpool_limits(threads)  # NumPy's and SciPy's BLAS, loaded already
    for variable in THREAD_VARIABLES:  # the libraries loaded later read these
        os.environ.setdefault(variable, str(threads))

    def watch() -> None:
        try:
            lifeline.recv_bytes()
        except (EOFError, OSError):
            pass
        os._exit(1)

    threading.Thread(target=watch, name="end-with-runner", daemon=True).start()


def _pool_rows(tasks: list[Task], task_function: TaskFunction, workers: int) -> Iterator[Row]:
    """Rows in the order the tasks finish on a pool of ``workers`` processes, started again
    (with the tasks that were in flight run one at a time) whenever a worker dies."""
    queue, suspects = deque(tasks), deque[Task]()
    in_flight: dict[Future[Row], Task] = {}
    pool = _Pool(workers)
    try:
        while queue or suspects or in_flight:
            alone = bool(suspects)
            source, limit = (suspects, 1) if alone else (queue, _IN_FLIGHT_PER_WORKER * workers)
            while source and len(in_flight) < limit:
                task = source.popleft()
                in_flight[pool.executor.submit(_call, task_function, task)] = task
            finished, _ = wait(in_flight, return_when=FIRST_COMPLETED)
            if any(_broke(future) for future in finished):
                finished = wait(in_flight).done  # the others in flight failed with it
                pool.restart()
                _LOG.warning(
                    "a worker process died; pool restarted; %s",
                    "its task, run alone, is failed"
                    if alone
                    else f"{sum(map(_broke, finished))} task(s) in flight run again one at a time",
                )
            for future in [f for f in in_flight if f in finished]:  # in submission order
                task = in_flight.pop(future)
                error = future.exception()
                if error is None:
                    yield future.result()
                elif not isinstance(error, Exception):
                    raise error  # Ctrl-C reached the worker too: the sweep stops
                elif not isinstance(error, BrokenProcessPool):
                    yield _failed(_identity(task), _describe(error), failure_kind(error))
                elif alone:
                    message = f"{_describe(error)} (the worker died running this task alone)"
                    yield _failed(_identity(task), message, MACHINE)
                else:
                    suspects.append(task)
    finally:
        pool.close(wait=not in_flight)


def _broke(future: Future[Row]) -> bool:
    return isinstance(future.exception(), BrokenProcessPool)


# Dask


def _dask_rows(
    tasks: list[Task], task_function: TaskFunction, workers: int, scheduler: str
) -> Iterator[Row]:
    """Rows in the order the tasks finish on a Dask cluster (a local one, started and
    stopped here, or the one at the scheduler's address)."""
    distributed = require("distributed", f"--scheduler {scheduler}")
    cluster = None
    if scheduler == "local":
        cluster = distributed.LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},  # its HTTP server, not 8787
        )
        address = cluster.scheduler_address
    else:
        address = scheduler
        if workers != 1:
            _LOG.info(
                "--workers %d ignored: the cluster at %s has its own workers", workers, address
            )
    try:
        try:
            client = distributed.Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError) as error:
            raise InputError(
                f"--scheduler {scheduler}: cannot connect within {CONNECT_TIMEOUT_S:g} s "
                f"({_describe(error)})"
            ) from None
        with client:
            yield from _client_rows(client, tasks, task_function)
    finally:
        if cluster is not None:
            cluster.close()


def _client_rows(client: Any, tasks: list[Task], task_function: TaskFunction) -> Iterator[Row]:
    import distributed

    run = uuid.uuid4().hex[:8]
    futures = client.map(
        _call,
        [task_function] * len(tasks),
        tasks,
        key=[f"spm-sweep-{task.key}-{run}" for task in tasks],
        pure=False,
    )
    by_future = dict(zip(futures, tasks, strict=True))
    try:
        for future in distributed.as_completed(futures, loop=client.loop):
            task = by_future.pop(future)
            try:
                row = future.result()
            except CancelledError as error:
                raise SpmOptError(
                    f"the Dask scheduler cancelled task {task.key} ({_describe(error)}); "
                    "the rows so far are kept: run again to resume"
                ) from None
            except Exception as error:  # noqa: BLE001 - KilledWorker, a lost result: a row
                row = _failed(_identity(task), _describe(error), failure_kind(error))
            future.release()
            yield row
    finally:
        if by_future:
            client.cancel(list(by_future))
