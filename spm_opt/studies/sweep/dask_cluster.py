"""Running a sweep's tasks on a Dask cluster: a local one started and stopped here, or the
one at a scheduler's address, checked to be reachable first.

The scheduler retries a task whose worker died and gives up with ``KilledWorker`` (after
``distributed.scheduler.allowed-failures`` deaths), which becomes its row (a machine
failure).
"""

from __future__ import annotations

import logging
import re
import socket
import uuid
from collections.abc import Iterator
from concurrent.futures import CancelledError
from typing import Any

from spm_opt.base.errors import InputError, SpmOptError, require
from spm_opt.studies.sweep.rows import (
    Row,
    TaskFunction,
    describe,
    failed_row,
    run_row,
    task_identity,
)
from spm_opt.studies.sweep.task import Task, failure_kind

_LOG = logging.getLogger(__name__)

CONNECT_TIMEOUT_S = 5.0
"""How long to try to reach a Dask scheduler before giving up, s."""
_ADDRESS = re.compile(r"tcp://(\[[0-9A-Fa-f:.]+\]|[^\s:/\[\]]+):(\d{1,5})")


def check_scheduler(scheduler: Any) -> None:
    """Refuse a scheduler other than "local" or a reachable ``tcp://HOST:PORT``."""
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
            f"({describe(error)})"
        ) from None


def dask_rows(
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
                f"({describe(error)})"
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
        run_row,
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
                    f"the Dask scheduler cancelled task {task.key} ({describe(error)}); "
                    "the rows so far are kept: run again to resume"
                ) from None
            except Exception as error:  # noqa: BLE001 - KilledWorker, a lost result: a row
                row = failed_row(task_identity(task), describe(error), failure_kind(error))
            future.release()
            yield row
    finally:
        if by_future:
            client.cancel(list(by_future))
