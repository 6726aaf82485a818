"""Running a sweep's tasks on a pool of worker processes, started from a fork server and
started again when a worker dies.

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
tasks are in flight when one dies.

A dead worker breaks the pool: the pool is started again and the tasks that were in flight
are run again one at a time, so that the task that kills its worker is told apart from the
innocent ones (a failed row "...died running this task alone", a machine failure) and the
others succeed.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import pickle
import threading
from collections import deque
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.connection import Connection

from spm_opt.base.errors import InputError, require
from spm_opt.studies.sweep.rows import (
    Row,
    TaskFunction,
    describe,
    failed_row,
    run_row,
    task_identity,
)
from spm_opt.studies.sweep.task import MACHINE, Task, failure_kind

_LOG = logging.getLogger(__name__)

_IN_FLIGHT_PER_WORKER = 2
"""Tasks handed to the pool per worker at a time: one running, one waiting in its queue."""


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


def pool_rows(tasks: list[Task], task_function: TaskFunction, workers: int) -> Iterator[Row]:
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
                try:
                    in_flight[pool.executor.submit(run_row, task_function, task)] = task
                except BrokenProcessPool:  # a worker died since the last wait
                    source.appendleft(task)
                    break
            if not in_flight:  # it died with nothing else in flight
                pool.restart()
                continue
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
                    yield failed_row(task_identity(task), describe(error), failure_kind(error))
                elif alone:
                    message = f"{describe(error)} (the worker died running this task alone)"
                    yield failed_row(task_identity(task), message, MACHINE)
                else:
                    suspects.append(task)
    finally:
        pool.close(wait=not in_flight)


def _broke(future: Future[Row]) -> bool:
    return isinstance(future.exception(), BrokenProcessPool)


def check_picklable(task_function: TaskFunction) -> None:
    """Refuse a task function the pool cannot send to its workers (a lambda, a local one)."""
    try:
        pickle.dumps(task_function)
    except (pickle.PicklingError, AttributeError, TypeError) as error:
        raise InputError(
            f"task function {task_function!r} cannot be sent to worker processes ({error}); "
            "use a module-level function"
        ) from None
