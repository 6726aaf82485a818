"""Stand-in task functions for the runner's tests, importable by worker processes (the
process pool's and a Dask cluster's) and by a runner started in a subprocess:

    python -c "import sweep_helpers; sweep_helpers.main()" OUT COUNT WORKERS
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

import threadpoolctl

from spm_opt.base.errors import InputError, PlanningError
from spm_opt.studies.sweep.pool import THREAD_VARIABLES
from spm_opt.studies.sweep.runner import run_sweep
from spm_opt.studies.sweep.task import ProblemFiles, Task

NOWHERE = ProblemFiles("/nowhere.toml", "", "robot.toml", "")
"""The stand-in tasks' problem: none (their functions read no file)."""


def grid_tasks(count: int, sweep: str = "stand-in", **extra: Any) -> list[Task]:
    """``count`` tasks with x = 0, 1, ..., and the ``extra`` parameters."""
    return [
        Task(
            key=f"{sweep[:4]}{x:012x}"[-16:],
            sweep=sweep,
            problem=NOWHERE,
            planner="square",
            code="stand-in",
            parameters={"x": x, **extra},
            overrides={"x": x},
        )
        for x in range(count)
    ]


def square(task: Task) -> dict[str, Any]:
    """Sleeps ``parameters["sleep"]`` s (default 0.2), then a row computed from x: its
    square, NaN for odd x and infinity for x = 2; status "1 violation(s)" for x = 1."""
    started = time.perf_counter()
    time.sleep(task.parameters.get("sleep", 0.2))
    x = task.parameters["x"]
    return {
        "key": task.key,
        "sweep": task.sweep,
        "planner": task.planner,
        "parameters": task.parameters,
        "status": "1 violation(s)" if x == 1 else "ok",
        "error": "",
        "solve_time_s": time.perf_counter() - started,
        "wall_time_s": time.perf_counter() - started,
        "square": float(x * x),
        "odd": float("nan") if x % 2 else float(x),
        "big": float("inf") if x == 2 else 1.0,
    }


def thread_settings(task: Task) -> dict[str, Any]:
    """``square``, with the worker's thread variables (:data:`THREAD_VARIABLES`) and the
    threads of its BLAS libraries loaded so far."""
    blas = sorted({pool["num_threads"] for pool in threadpoolctl.threadpool_info()})
    variables = {name: os.environ.get(name) for name in THREAD_VARIABLES}
    return {**square(task), **variables, "blas_threads": blas}


def fails_on_three(task: Task) -> dict[str, Any]:
    """``square``, but raises for x = 3 (a bug in a task function)."""
    if task.parameters["x"] == 3:
        raise ZeroDivisionError("x = 3 is not allowed")
    return square(task)


def fails_by_kind(task: Task) -> dict[str, Any]:
    """``square``, but x = 1 times out (the machine's failure), x = 2 cannot be planned and
    x = 3 is refused as input (the problem's failures, results)."""
    x = task.parameters["x"]
    if x == 1:
        raise TimeoutError("no answer from the license server in 30 s")
    if x == 2:
        raise PlanningError("square: infeasible")
    if x == 3:
        raise InputError("x = 3: not allowed")
    return square(task)


def kills_on_three(task: Task) -> dict[str, Any]:
    """``square``, but the worker process is killed (SIGKILL) running x = 3."""
    if task.parameters["x"] == 3:
        time.sleep(0.1)
        os.kill(os.getpid(), signal.SIGKILL)
    return square(task)


def returns_text(task: Task) -> str:
    """Not a row: a task function's bug."""
    return f"x = {task.parameters['x']}"


def returns_a_set(task: Task) -> dict[str, Any]:
    """A row with a value that JSON cannot hold: a task function's bug."""
    return {**square(task), "square": {task.parameters["x"]}}


def main() -> None:
    """Run ``square`` over COUNT tasks into OUT with WORKERS processes (argv)."""
    out, count, workers = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
    run_sweep(grid_tasks(count), out, workers=workers, progress=False, task_function=square)
